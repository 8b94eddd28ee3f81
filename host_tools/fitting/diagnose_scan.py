"""The candidate scan of the closed loop (host_tools.fitting.diagnose, steps 3-4 of its module doc): the
cross-validation engine (:class:`_Scanner`: leave-one-group-out refits of the base terms plus a
candidate, in Gram form, for the real target and the surrogates at once; folds and held-out SSE
from host_tools.fitting.cv), the 1-s binning of the score (:class:`_Binner`), the design of the current
model (polynomial terms + accepted generators, per mode bank for regress_first), the rate
estimator alternatives, the structure/effect kinds, and :func:`scan_candidates`: every candidate scored, the
max-T threshold from noise-model surrogates, the selection rule and the refinement of the winner.
Gains are fractions of the held-out residual variance of 1-s means; taus in seconds."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace

import numpy as np

from firmware_ref.formats import AUX_MAX_TERMS
from firmware_ref.terms import K_AUX
from host_tools.fitting import effects
from host_tools.golden import runlog as rl
from host_tools.golden.compensate import fit_config_from_logs, prepare
from host_tools.fitting.cv import fold_ids, heldout_sse
from host_tools.fitting.diagnose_confirm import fmt_value
from host_tools.fitting.fit import fit_logs
from host_tools.fitting.diagnose_noise import (MAX_LINES, artifact_entry, combined_noise, artifact_of, characterize,
                                       combiner_lines, noise_model, spectral_lines, surrogates)
from host_tools.golden.regressors import AuxConfig, generator_values, regressor_matrix


G_MIN = 0.02                 # minimum CV gain (fraction of held-out residual variance)
N_SURROGATES = 39            # surrogate residuals for the null of the scan's best gain
NULL_QUANTILE = 0.95
NULL_SD_FLOOR = 0.005        # max-T: smallest upper-tail scale of a candidate's null gains
MAX_ITER = 3
TRIES_PER_STEP = 2           # a phase tries at most this many steps per step it may keep (max_iter): a step the
                             # held-out runs do not confirm is reverted and uses a try, not one of the max_iter
CV_BLOCKS = 16               # single training run: contiguous blocks ...
CV_FOLDS = 4                 # ... dealt round-robin into folds
PERIOD_GRID_MIN_S = 120.0    # ... plus a grid of periods from this, ratio 2^(1/4), ...
PERIOD_GRID_RATIO = 2 ** 0.25
PERIOD_EXCLUDE_RATIO = 2 ** 0.5   # a reverted periodic step excludes the periods within this ratio (None: the family)
PERIOD_GRID_MAX_FRACTION = 0.5   # ... up to half the training run: two cycles, the fewest that tell a line from a drift
RATE_ALTERNATIVES_S = (16.0, 64.0)   # rate_estimator candidates: lsq windows [s] ...
RATE_IIR_TAUS_S = (8.0, 32.0, 128.0, 512.0)   # ... and iir time constants 2^shift / fs [s]
TOP_RANKING = 12
SCORE_TAU_S = 1.0            # the CV scores bin means of this many seconds (the report's shortest tau)
TIE_TOLERANCE = 0.05         # gains within 5 % (relative) of the best are a tie: prefer the proxy


# ---------------------------------------------------------------------------------------------
# cross-validation engine
# ---------------------------------------------------------------------------------------------

class _Scanner:
    """Leave-one-group-out cross-validation of a base design plus candidate columns, for many
    targets at once (the real target and the surrogates), in Gram form.

    The valid rows of every group are stacked (group after group).  The base design X is replaced
    by an orthonormal basis Q of its span (left singular vectors of the column-scaled stacked
    design, numerical rank kept) and the targets by their residual Yr = Y - Q Q^T Y on all groups, so per-group sums of
    small quantities suffice: A_g = Q_g^T Q_g, B_g = Q_g^T Yr_g, S_g = sum Yr_g^2.  Fold f trains
    on all groups but f (A_tr = I - A_f, B_tr = -B_f since Q^T Yr = 0) and is scored on group f:
    held-out SSE = S_f - 2 b.B_f + b.A_f b for the fold's coefficient change b.  A candidate C adds
    D_g = Q_g^T C_g, E_g = C_g^T C_g, F_g = C_g^T Yr_g and its coefficients a to the solve.  This
    is algebraically the refit of the base terms plus the candidate in every fold."""

    def __init__(self, X_logs, Y_logs, groups):
        self.groups = groups
        X = np.concatenate([X_logs[j][idx] for j, idx in groups])
        Y = np.concatenate([Y_logs[j][idx] for j, idx in groups])
        sizes = [len(idx) for _, idx in groups]
        self.bounds = np.concatenate([[0], np.cumsum(sizes)])
        norms = np.sqrt(np.einsum("ij,ij->j", X, X))
        norms[norms == 0] = 1.0
        U, sv, _ = np.linalg.svd(X / norms, full_matrices=False)
        keep = sv > (sv.max() if len(sv) else 0.0) * 1e-10
        self.Q = np.ascontiguousarray(U[:, keep])
        self.Yr = np.ascontiguousarray(Y - self.Q @ (self.Q.T @ Y))
        p = self.Q.shape[1]
        self.p = p
        self.A, self.B, self.S = [], [], []
        for a, b in self._slices():
            Qg, Yg = self.Q[a:b], self.Yr[a:b]
            self.A.append(np.einsum("ij,ik->jk", Qg, Qg))
            self.B.append(np.einsum("ij,ik->jk", Qg, Yg))
            self.S.append(np.einsum("ij,ij->j", Yg, Yg))
        self.e0 = np.empty((len(groups), Y.shape[1]))
        eye = np.eye(p)
        self._base = []
        for f in range(len(groups)):
            b = _solve_sym(eye - self.A[f], -self.B[f])
            self._base.append(b)
            self.e0[f] = heldout_sse(b, self.S[f], self.B[f], self.A[f])

    def _slices(self):
        return [(int(self.bounds[g]), int(self.bounds[g + 1])) for g in range(len(self.groups))]

    def stack(self, C_logs) -> np.ndarray:
        """The valid rows of per-log columns (n_log, m) in the stacked group order."""
        return np.concatenate([C_logs[j][idx] for j, idx in self.groups])

    def score(self, C_logs):
        """(folds, targets) held-out SSE with the candidate columns C_logs (one (n, m) array per
        log) added; the base SSE where the candidate is not identifiable in a fold."""
        C = self.stack(C_logs)
        D, E, F = [], [], []
        for a, b in self._slices():
            Cg = C[a:b]
            D.append(np.einsum("ij,ik->jk", self.Q[a:b], Cg))
            E.append(np.einsum("ij,ik->jk", Cg, Cg))
            F.append(np.einsum("ij,ik->jk", Cg, self.Yr[a:b]))
        Dt, Et, Ft = sum(D), sum(E), sum(F)
        p = self.p
        out = self.e0.copy()
        eye = np.eye(p)
        for f in range(len(self.groups)):
            Atr = eye - self.A[f]
            Dtr, Etr = Dt - D[f], Et - E[f]
            # identifiability: the candidate's part outside the base span on the training rows
            schur = Etr - Dtr.T @ _solve_sym(Atr, Dtr)
            if np.any(np.diag(schur) <= 1e-9 * np.maximum(np.diag(Etr), 1e-300)):
                continue
            M = np.block([[Atr, Dtr], [Dtr.T, Etr]])
            rhs = np.vstack([-self.B[f], Ft - F[f]])
            try:
                sol = np.linalg.solve(M, rhs)
            except np.linalg.LinAlgError:
                continue
            # held-out sums of the fold in the joint basis [Q, C]: (A D; D^T E), (B; F), S
            out[f] = heldout_sse(sol, self.S[f], np.vstack([self.B[f], F[f]]),
                                 np.block([[self.A[f], D[f]], [D[f].T, E[f]]]))
        return out


def _solve_sym(A, B):
    try:
        return np.linalg.solve(A, B)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(A, B, rcond=None)[0]


class _Binner:
    """Averages of the valid samples of one log over consecutive bins of SCORE_TAU_S seconds
    (``round(SCORE_TAU_S * fs)`` samples, counted within each gap-free segment; a bin with fewer
    than half its samples valid is dropped).  At fs <= 1 Hz a bin is one valid sample."""

    def __init__(self, log, valid, fs):
        valid = np.asarray(valid, bool)
        size = max(1, int(round(SCORE_TAU_S * fs)))
        idx = np.flatnonzero(valid)
        if size == 1:
            self.idx, self.inverse, self.count, self.n = idx, None, None, len(idx)
            return
        start = np.zeros(len(valid), np.int64)
        start[np.asarray(log.segments, np.int64)] = np.asarray(log.segments, np.int64)
        start = np.maximum.accumulate(start)
        seg = np.searchsorted(np.asarray(log.segments), np.arange(len(valid)), side="right") - 1
        key = seg[idx] * (len(valid) + 1) + (idx - start[idx]) // size
        keys, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
        keep = count >= (size + 1) // 2
        remap = np.full(len(keys), -1, np.int64)
        remap[keep] = np.arange(int(keep.sum()))
        inv = remap[inverse]
        sel = inv >= 0
        self.idx, self.inverse, self.count, self.n = idx[sel], inv[sel], count[keep], int(keep.sum())

    def mean(self, A) -> np.ndarray:
        """(bins, ...) bin means of the rows of A (n rows, 1-D or 2-D)."""
        A = np.asarray(A, np.float64)
        rows = A[self.idx]
        if self.inverse is None:
            return rows
        if rows.ndim == 1:
            return np.bincount(self.inverse, rows, self.n) / self.count
        return np.column_stack([np.bincount(self.inverse, rows[:, j], self.n) for j in range(rows.shape[1])]) \
            / self.count[:, None]


def cv_groups(valid_masks, cv_blocks=CV_BLOCKS, cv_folds=CV_FOLDS) -> list:
    """The CV groups as (log index, row indices of valid samples): one group per log when there
    are >= 2 logs; else ``cv_blocks`` contiguous time blocks of the single log dealt round-robin
    into ``cv_folds`` groups (block b -> group b % cv_folds)."""
    if len(valid_masks) >= 2:
        return [(j, np.flatnonzero(v)) for j, v in enumerate(valid_masks)]
    v = valid_masks[0]
    fold = fold_ids(len(v), cv_blocks, cv_folds)
    groups = [(0, np.flatnonzero(v & (fold == k))) for k in range(cv_folds)]
    if any(len(idx) == 0 for _, idx in groups):
        raise ValueError("a CV fold holds no valid sample: the run is too short for the blocks")
    return groups


# ---------------------------------------------------------------------------------------------
# the current model: design, explicit weights, rate alternatives
# ---------------------------------------------------------------------------------------------

@dataclass
class Accepted:
    family: str
    params: dict
    terms: list = field(default_factory=list)      # generator terms (weight 1 placeholders)
    rate: dict | None = None                       # rate_estimator winner: {"estimator", "n"}


def poly_terms(model) -> tuple:
    return tuple(k for k in model.terms if k != K_AUX)


def _banked(pr, A):
    """A regress_first model has one coefficient bank per mode: the columns of A (n, m) become
    (n, 2m), A on mode-1 samples then A on mode-2 samples (zero elsewhere); other orders: A."""
    A = np.asarray(A, np.float64)
    if getattr(pr, "order", None) != "regress_first":
        return A
    A = A.reshape(len(A), -1)
    return np.column_stack([A * (pr.mode == 1)[:, None], A * (pr.mode == 2)[:, None]])


def fit_mask(pr):
    """The samples a fit uses: the combined valid samples, or the per-mode used samples of regress_first."""
    return pr.used if getattr(pr, "order", None) == "regress_first" else pr.valid


def design_matrix(pr, poly, gen_cols):
    X = regressor_matrix(pr.u, pr.v)[:, list(poly)]
    return _banked(pr, np.column_stack([X] + list(gen_cols)) if gen_cols else X)


FIT_BLOCK = "fit_block"   # a gen_terms entry: the k7 sum of the starting model (hdrg fit's), one column


def fit_block(model) -> list:
    """The starting model's k7 as gen_terms: [] when it has no k7 generators, else one entry
    ``{"gen": FIT_BLOCK, "terms": [...]}`` whose column is that k7 sum (its terms at their weights):
    the loop refits it as ONE column beside its own generators, so `hdrg fit`'s lag block and
    power-on term keep their shape (and a regress_first lag block its sign twins)."""
    if K_AUX not in model.terms or not model.config.aux.terms:
        return []
    return [{"gen": FIT_BLOCK, "terms": [dict(t) for t in model.config.aux.terms]}]


def gen_column(log, term, fs) -> np.ndarray:
    """One gen_terms column of ``log``: a generator term's values, or a FIT_BLOCK's weighted sum."""
    if term.get("gen") == FIT_BLOCK:
        return sum(t["weight"] * generator_values(log, t, fs) for t in term["terms"])
    return generator_values(log, term, fs)


def chip_terms(gen_terms) -> list:
    """The chip's k7 terms of ``gen_terms`` (a FIT_BLOCK expanded to its terms)."""
    return [t for g in gen_terms for t in (g["terms"] if g.get("gen") == FIT_BLOCK else [g])]


def _same_term(a, b) -> bool:
    strip = lambda t: json.dumps({k: v for k, v in t.items() if k != "weight"}, sort_keys=True, default=str)   # noqa: E731
    return strip(a) == strip(b)


def explicit_weights(train, cfg, poly, gen_terms) -> list:
    """Refit poly terms + every generator as its own column (a FIT_BLOCK as one column; training
    valid samples, lstsq); return the chip's k7 terms with weights c_j / sum |c_j| (|z| <= 1; a
    FIT_BLOCK's terms at its coefficient times their weights)."""
    fs = cfg.rate.fs
    Xs, ys = [], []
    for log in train:
        pr = prepare(log, replace(cfg, aux=AuxConfig()))
        cols = [gen_column(log, t, fs) for t in gen_terms]
        X = design_matrix(pr, poly, cols)
        Xs.append(X[fit_mask(pr)])
        ys.append(pr.y[fit_mask(pr)])
    X = np.concatenate(Xs)
    y = np.concatenate(ys)
    norms = np.sqrt(np.einsum("ij,ij->j", X, X))
    norms[norms == 0] = 1.0
    c = np.linalg.lstsq(X / norms, y, rcond=None)[0] / norms
    m = len(poly) + len(gen_terms)
    banks = [c[b * m + len(poly):(b + 1) * m] for b in range(len(c) // m)]
    cg = max(banks, key=lambda b: float(np.sum(np.abs(b))))   # regress_first: the larger bank's ratios
    flat = []
    for t, cj in zip(gen_terms, cg):
        if t.get("gen") == FIT_BLOCK:
            flat += [{**u, "weight": float(cj * u["weight"])} for u in t["terms"]]
        else:
            flat.append({**t, "weight": float(cj)})
    total = float(sum(abs(t["weight"]) for t in flat))
    if not total > 0:
        raise ValueError("the accepted generators have zero weight in the explicit refit")
    return [{**t, "weight": t["weight"] / total} for t in flat]


def refit_with(train, cfg, poly, gen_terms):
    """The model of ``poly`` terms plus the generators ``gen_terms`` (none: the poly terms alone)
    fitted on ``train`` as the loop keeps it: generator weights from :func:`explicit_weights`
    baked into ``AuxConfig('sum')`` as k7.  Returns (model, config)."""
    if gen_terms:
        cfg = replace(cfg, aux=AuxConfig.from_terms(explicit_weights(train, cfg, poly, gen_terms), cfg.rate.fs))
        return fit_logs(train, cfg, tuple(poly) + (K_AUX,), drop_unidentifiable=True)[0], cfg
    return fit_logs(train, cfg, tuple(poly), drop_unidentifiable=True)[0], cfg


def _rate_alternatives(train, cfg) -> list:
    """The rate_estimator candidates {estimator, n, shift}: lsq over RATE_ALTERNATIVES_S seconds
    and iir with time constants 2^shift / fs in RATE_IIR_TAUS_S (nominal fs), a warm-up shorter
    than half the shortest segment, different from the current estimator."""
    from host_tools.golden.rate import MAX_SHIFT, warmup_length
    fs = cfg.rate.fs
    shortest = min(int(np.min(np.diff(np.append(log.segments, len(log))))) for log in train)
    cur = (cfg.rate.estimator, cfg.rate.n if cfg.rate.estimator == "lsq" else 0,
           cfg.rate.shift if cfg.rate.estimator == "iir" else 0)
    out = []
    for sec in RATE_ALTERNATIVES_S:
        out.append({"estimator": "lsq", "n": max(2, int(round(sec * fs))), "shift": cfg.rate.shift})
    shifts = sorted({min(MAX_SHIFT, max(0, int(round(math.log2(t * fs))))) for t in RATE_IIR_TAUS_S})
    out += [{"estimator": "iir", "n": cfg.rate.n, "shift": sh} for sh in shifts]
    keep = []
    for alt in out:
        key = (alt["estimator"], alt["n"] if alt["estimator"] == "lsq" else 0,
               alt["shift"] if alt["estimator"] == "iir" else 0)
        if key != cur and warmup_length(alt["estimator"], alt["n"], alt["shift"]) <= shortest // 2:
            keep.append(alt)
    return keep


def loop_config(train, opts, rate=None, aux=None):
    o = dict(opts)
    if rate is not None:
        o["rate_estimator"], o["n"] = rate["estimator"], rate["n"]
        o["shift"] = rate.get("shift", o["shift"])
    return fit_config_from_logs(train, aux=aux, **o)


def _gain(e1, e0):
    """Per column of Y: 1 - sum_f e1 / sum_f e0."""
    return 1.0 - e1.sum(axis=0) / np.maximum(e0.sum(axis=0), 1e-300)
STRUCTURAL = ("rate_estimator", "reversal_order", "reversal_settle", "exchange_settling", "board_temp",
              "thermal_lag", "proxy_high_order")  # the model's structure
PHASES = ("structure", "effect")
# reported as structure but scanned with the effects: in the structure phase u^4 / u^5 came first on tofupilot x
# (cool->heat) and left the effect phase no iteration for the accelerometer term (held-out 17.0 -> 13.9 deg/h at
# 100 s instead of -> 10.1); a higher power of the proxy is not a dynamic that could masquerade as an effect
SCANNED_WITH_EFFECTS = ("proxy_high_order",)
STRUCT_TAU_FRACTION = 0.25   # structure phase: lags (block, second thermometer) <= this x the longest run
DRIFT_MARGIN = 1.7           # structure phase: a drift (diagnose.COMPETE_FAMILIES) wins only leaving <= 1/this of
                             # the best structural candidate's residual (chosen on calibration seed 1, docs/LOOP.md)


def kind_of(family, params) -> str:
    """'structure' for a step that changes the model's own structure (rate estimator, order /
    combiner, settling window, the exchange settling of per-mode banks (a transient after each
    exchange that follows the mode sign like the rate: the readout still settling), a lag of the
    proxy: one lag or the lag-state polynomial block, a higher power of the proxy (u^4, u^5: the
    order of the model's own polynomial; a clean foreign device's bias has a tanh of its
    temperature, which no cubic holds), the second thermometer and its lag), 'effect' for an
    added effect regressor (module doc, step 3).
    A single lag of the proxy is the same physics as the block (a lagged thermal node of the
    device): on clean foreign devices their own nodes were reported as a thermal_lag "effect"."""
    return "structure" if family in STRUCTURAL else "effect"


def phase_of(family, params) -> str:
    """The phase whose scan offers a candidate: its :func:`kind_of`, except SCANNED_WITH_EFFECTS."""
    return "effect" if family in SCANNED_WITH_EFFECTS else kind_of(family, params)


def step_key(family, params) -> str:
    """The name under which a reverted step is not offered again: the family; the lag block apart;
    with PERIOD_EXCLUDE_RATIO a periodic step by its period (:func:`_excluded`)."""
    if family == "periodic" and PERIOD_EXCLUDE_RATIO:
        return f"periodic@{float(params['period_s'])!r}"
    return "thermal_lag_block" if family == "thermal_lag" and "order" in params else family


def _excluded(c, excluded) -> bool:
    """Candidate ``c`` is not offered again: its step key was reverted, or (PERIOD_EXCLUDE_RATIO) it
    is a period within that ratio of a reverted period: another line may still be tried."""
    if step_key(c.family, c.params) in excluded:
        return True
    if c.family != "periodic" or not PERIOD_EXCLUDE_RATIO:
        return False
    p = float(c.params["period_s"])
    return any(max(p / q, q / p) <= PERIOD_EXCLUDE_RATIO
               for q in (float(k.split("@", 1)[1]) for k in excluded if k.startswith("periodic@")))


def scan_candidates(train, cfg, model, poly, gen_terms, rng, n_sur, g_min, cv_blocks, cv_folds, families, rate_alt,
          excluded=frozenset(), phase=None, also=frozenset(), reserved=0):
    """Score every candidate (module doc, steps 3-4) against the current base; returns a dict with
    the ranking, the null, the decision and the (refined) winner.  ``phase``: offer only that
    phase's candidates (None: all), and the families in ``also`` besides; ``reserved``: k7 terms
    kept free for a term the final model adds."""
    fs = cfg.rate.fs
    preps = [prepare(log, replace(cfg, aux=AuxConfig())) for log in train]
    gen_cols = [[gen_column(log, t, fs) for t in gen_terms] for log in train]
    X_logs = [design_matrix(pr, poly, gc) for pr, gc in zip(preps, gen_cols)]
    valid = [fit_mask(pr) for pr in preps]
    # base fit on all training data: residual per log
    Xv = np.concatenate([X[v] for X, v in zip(X_logs, valid)])
    yv = np.concatenate([pr.y[v] for pr, v in zip(preps, valid)])
    norms = np.sqrt(np.einsum("ij,ij->j", Xv, Xv))
    norms[norms == 0] = 1.0
    coef = np.linalg.lstsq(Xv / norms, yv, rcond=None)[0] / norms
    fitted = [X @ coef for X in X_logs]
    resid = [np.where(v, pr.y - f, 0.0) for pr, f, v in zip(preps, fitted, valid)]
    charac = [characterize(log, r, v, fs, pr.v) for log, r, v, pr in zip(train, resid, valid, preps)]
    gapfree = all(len(log.segments) == 1 for log in train)
    clines = combiner_lines(train, cfg)
    artifacts = []
    for c in charac:
        for ln in c["lines"]:
            why = artifact_of(ln["period_s"], clines)
            if why:
                artifacts.append(artifact_entry(ln, clines, why))
    periods = _pooled_periods([[ln for ln in c["lines"] if not artifact_of(ln["period_s"], clines)]
                               for c in charac]) if gapfree else []
    Y_logs = []
    sur_resids = []
    noise_models = []
    for log, X, pr, f, r, v in zip(train, X_logs, preps, fitted, resid, valid):
        Xs = X[v] / norms
        Qv = np.linalg.qr(Xs)[0]

        def project(W, Qv=Qv, v=v):
            out = np.zeros_like(W)
            out[v] = Qv @ (Qv.T @ W[v])
            return out

        nm = noise_model(r, log.t_s, v, fs, reversal=combined_noise(cfg))
        noise_models.append(nm)
        sur, sur_resid = surrogates(nm, log, cfg, n_sur, rng, project)
        Y_logs.append(np.column_stack([pr.y, f[:, None] + sur]))
        sur_resids.append(sur_resid)
    binners = [_Binner(log, v, fs) for log, v in zip(train, valid)]
    groups = cv_groups([np.ones(b.n, bool) for b in binners], cv_blocks, cv_folds)
    scanner = _Scanner([b.mean(X) for b, X in zip(binners, X_logs)], [b.mean(Y) for b, Y in zip(binners, Y_logs)],
                       groups)
    e0 = scanner.e0
    nfold = len(groups)
    majority = nfold // 2 + 1
    cands = effects.library(train, cfg, periods=periods, families=families)
    for c in cands:
        if c.family == "periodic":
            c.extra["line"] = True
    dur = effects._duration_s(train)     # the longest training run [s]
    if (families is None or "periodic" in families) and phase != "structure":      # a period grid too: a line may hide under slow residual
        grid = PERIOD_GRID_MIN_S * PERIOD_GRID_RATIO ** np.arange(64)
        cands += [effects.periodic(float(p)) for p in grid[grid <= PERIOD_GRID_MAX_FRACTION * dur]
                  if not artifact_of(float(p), clines) and all(abs(p / q - 1.0) > 0.05 for q in periods)]
    # drop candidates equal to an accepted generator
    have = chip_terms(gen_terms)
    cands = [c for c in cands if not any(_same_term(t, h) for t in c.terms for h in have)
             and not _excluded(c, excluded)
             and (phase is None or phase_of(c.family, c.params) == phase or c.family in also)]
    # the model goes to the firmware: its k7 sum holds at most AUX_MAX_TERMS terms, so a candidate
    # that would not fit beside the accepted ones is not offered (the report says how many)
    room = AUX_MAX_TERMS - reserved - len(have)
    n_full = sum(len(c.terms) > room for c in cands)
    cands = [c for c in cands if len(c.terms) <= room]

    def tau_cap(c):
        # a structural lag longer than a quarter of the run is a ramp (aging), not the device's dynamics
        if kind_of(c.family, c.params) == "structure":
            return min(STRUCT_TAU_FRACTION * dur, c.extra.get("max_tau_s", dur))
        return c.extra.get("max_tau_s", dur)     # an aging decay may run longer than the run

    cands = [c for c in cands if c.params.get("tau_s", 0.0) <= tau_cap(c)]
    rows = []
    nsur = Y_logs[0].shape[1] - 1

    def evaluate(c):
        e1 = scanner.score([b.mean(_cand_columns(c, log, pr, fs)) for b, log, pr in zip(binners, train, preps)])
        g = _gain(e1, e0)
        return {"family": c.family, "label": c.label, "params": dict(c.params), "terms": list(c.terms),
                "gain": float(g[0]), "folds_improved": int(np.sum(e1[:, 0] < e0[:, 0])), "folds": nfold,
                "_cand": c, "_null": g[1:]}

    rows = [evaluate(c) for c in cands]
    if gapfree and any(r["family"] == "periodic" for r in rows) and nsur:
        # the periodic candidates are chosen from the residual's own spectrum: repeat that choice
        # on every surrogate (its lines, scored on it; 0 when it has none), so the null of the
        # periodic family counts the selection
        pnull = np.zeros(nsur)
        for j in range(nsur):
            sl = [[ln for ln in spectral_lines(sr[:, j], v, fs) if not artifact_of(ln["period_s"], clines)]
                  for sr, v in zip(sur_resids, valid)]
            for period in _pooled_periods(sl):
                pnull[j] = max(pnull[j], evaluate(effects.periodic(period))["_null"][j])
        for r in rows:
            if r["family"] == "periodic" and r["_cand"].extra.get("line"):
                r["_null"] = pnull
    if rate_alt and "rate_estimator" not in excluded and phase != "effect":
        for alt in _rate_alternatives(train, cfg):
            try:
                acfg = _config_like(train, cfg, alt)
            except ValueError:
                continue
            apreps = [prepare(log, replace(acfg, aux=AuxConfig())) for log in train]
            AX = [design_matrix(pr, poly, gc) for pr, gc in zip(apreps, gen_cols)]
            # a longer warm-up changes the valid set: both bases are scored on the common samples
            cb = [_Binner(log, v & fit_mask(a), fs) for log, v, a in zip(train, valid, apreps)]
            cgroups = cv_groups([np.ones(b.n, bool) for b in cb], cv_blocks, cv_folds)
            Yc = [b.mean(Y) for b, Y in zip(cb, Y_logs)]
            g_base = _Scanner([b.mean(X) for b, X in zip(cb, X_logs)], Yc, cgroups).e0
            g_alt = _Scanner([b.mean(X) for b, X in zip(cb, AX)], Yc, cgroups).e0
            g = _gain(g_alt, g_base)
            if alt["estimator"] == "lsq":
                params = {"estimator": "lsq", "n": alt["n"], "window_s": alt["n"] / acfg.rate.fs}
            else:
                params = {"estimator": "iir", "shift": alt["shift"], "tau_s": 2.0 ** alt["shift"] / acfg.rate.fs}
            inner = ", ".join(f"{k}={fmt_value(v)}" for k, v in params.items() if k != "estimator")
            rows.append({"family": "rate_estimator", "label": f"rate_estimator({alt['estimator']}, {inner})",
                         "params": params, "terms": [], "gain": float(g[0]),
                         "folds_improved": int(np.sum(g_alt[:, 0] < g_base[:, 0])), "folds": nfold,
                         "_cand": None, "_null": g[1:]})
    out = {"characterization": charac, "artifacts": artifacts, "combiner_lines": clines,
           "noise_models": noise_models, "accept": False, "reason": None, "winner": None, "ranking": [],
           "best": None, "threshold": None, "null_max": [],
           "not_offered": (f"{n_full} candidates not offered: the firmware's k7 sum holds at most {AUX_MAX_TERMS} "
                           f"terms and {len(have)} are taken" + (f", {reserved} kept free for the power-on term" if reserved else "")
                           if n_full else None)}
    if not rows:
        out["reason"] = "no candidates" + (f" ({out['not_offered']})" if n_full else "")
        return out
    # rule (b): the largest gain of the whole scan on each surrogate; its 95 % level
    # (max-T: every candidate's gain standardized by its own null (median, 84th percentile - median),
    # so a candidate that fits noise easily (a wandering channel) does not raise the bar for the others)
    nulls = np.array([r["_null"] for r in rows]).reshape(len(rows), nsur)
    if nsur:     # robust location / upper-tail scale: a wild negative tail must not inflate the bar
        mu = np.median(nulls, axis=1)
        sd = np.maximum(np.quantile(nulls, 0.8413, axis=1) - mu, NULL_SD_FLOOR)
        # the families offered beside a phase (``also``) are not in its max-T: the phase's own bar
        # stays what it was without them
        own = np.array([r["family"] not in also for r in rows]) if phase is not None else np.ones(len(rows), bool)
        own = own if own.any() else np.ones(len(rows), bool)
        null_max = ((nulls[own] - mu[own, None]) / sd[own, None]).max(axis=0)
        t_level = float(np.quantile(null_max, NULL_QUANTILE))
    else:
        mu, sd, null_max, t_level = np.zeros(len(rows)), np.ones(len(rows)), np.zeros(0), -np.inf
    for r, m, d in zip(rows, mu, sd):
        r["t"] = float((r["gain"] - m) / d)
        r["null95"] = float(m + t_level * d) if nsur else g_min     # the gain this candidate needs
        r["significant"] = bool(r["gain"] >= max(g_min, r["null95"]) and r["folds_improved"] >= majority)
    threshold = t_level
    rows.sort(key=lambda r: -r["gain"])
    keys = ("label", "family", "gain", "null95", "t", "significant", "folds_improved", "folds")
    out.update(ranking=[{k: r[k] for k in keys} for r in rows[:TOP_RANKING]], threshold=threshold,
               null_max=[float(x) for x in null_max])
    passing = [r for r in rows if r["significant"]]
    others = [r["gain"] for r in rows if r["family"] not in also]
    if also and others and phase is not None:
        # an effect family offered beside the structure (a drift in time, which a long lag of the
        # proxy mimics) is taken first only when it leaves 1/DRIFT_MARGIN of the residual variance
        # the best structural candidate leaves, or less
        left = 1.0 - max(others)
        kept = [r for r in passing if r["family"] not in also or left >= DRIFT_MARGIN * (1.0 - r["gain"])]
        if passing and not kept:
            out["reason"] = (f"{passing[0]['label']} (CV gain {passing[0]['gain']:.4f}) does not leave 1/{DRIFT_MARGIN:g} "
                             f"of the best structural candidate's residual: the effect phase takes it")
            out["best"] = {k: passing[0][k] for k in keys}
            return out
        passing = kept
    if any(r["family"] != "rate_estimator" for r in passing):
        # a longer rate warm-up hides the start of every run (turn-on): effects first
        passing = [r for r in passing if r["family"] != "rate_estimator"]
    best = _preferred(passing if passing else rows)
    out["best"] = {k: best[k] for k in keys}
    out["threshold"] = max(g_min, best["null95"])
    out["t_level"] = t_level
    if not passing:
        if best["gain"] < g_min:
            out["reason"] = f"best CV gain {best['gain']:.4f} ({best['label']}) < g_min {g_min}"
        elif best["gain"] < best["null95"]:
            out["reason"] = (f"best CV gain {best['gain']:.4f} ({best['label']}) < {best['null95']:.4f}, the gain "
                             f"it needs: the {NULL_QUANTILE:.0%} level of the scan's largest standardized gain "
                             f"(max-T {t_level:.2f}) on {nsur} noise-model surrogates")
        else:
            out["reason"] = (f"inconsistent: {best['label']} improves {best['folds_improved']} of {nfold} folds "
                             f"(need {majority})")
        return out
    # refine the winner's continuous parameter
    coarse = best
    cand = best["_cand"]
    if cand is not None and cand.scan:
        for ratios in (_ratios(cand.scan, 1), _ratios(cand.scan, 2)):
            trial = [best] + [evaluate(c) for c in effects.refine(cand, ratios, max_value=tau_cap(cand))]
            best = max(trial, key=lambda r: r["gain"])
            cand = best["_cand"]
    best = {k: v for k, v in best.items() if not k.startswith("_")}
    best.update(significant=True, coarse=coarse["label"], coarse_gain=coarse["gain"])
    out.update(accept=True, winner=best)
    return out


def _cand_columns(c, log, pr, fs):
    """A candidate's design columns on one log: banked by mode for a regress_first model unless the
    candidate has one coefficient for both banks (``extra['shared']``: exchange_settling)."""
    cols = c.columns(log, fs)
    return cols if c.extra.get("shared") else _banked(pr, cols)


def _tier(family) -> int:
    """0: a regressor from the proxy, the mode and the sample counter only; 1: it needs another
    logged channel (board_temp, aux, aux_*)."""
    return 1 if family in ("board_temp", "aux") or family.startswith("aux_") else 0


def _tied(gain, top) -> bool:
    """A CV gain within TIE_TOLERANCE (relative) of the best one ``top``: the scan cannot tell them apart."""
    return gain >= top - TIE_TOLERANCE * abs(top)


def _preferred(rows) -> dict:
    """The winner of a ranking (sorted by gain): among the rows within TIE_TOLERANCE (relative) of
    the best gain, the best one of the lowest :func:`_tier` (Occam: when another channel explains
    no more than the proxy itself, within the noise of the gains, the proxy's lag is the
    simpler model and needs no extra input in the firmware)."""
    top = rows[0]["gain"]
    close = [r for r in rows if _tied(r["gain"], top)]
    tier = min(_tier(r["family"]) for r in close)
    return max((r for r in close if _tier(r["family"]) == tier), key=lambda r: r["gain"])


def rivals(ranking, winner) -> list:
    """Labels of the candidates of OTHER families that the training runs cannot tell from the
    accepted ``winner`` (a scan's ``winner``; ``ranking``: its ``ranking`` rows): significant, CV
    gain within TIE_TOLERANCE (relative) of the winner's coarse gain; the best of each family.
    E.g. a lag of the proxy and a lagged second thermometer when the sensor node is itself a lag
    of the resonator: the step holds on held-out, which of the two the device has does not."""
    top = winner.get("coarse_gain", winner["gain"])
    out = {}
    for r in ranking:
        if r["family"] != winner["family"] and r["significant"] and r["family"] not in out and _tied(r["gain"], top):
            out[r["family"]] = r["label"]
    return list(out.values())


def _pooled_periods(lines_per_log) -> list:
    """Periods [s] of the strongest lines over all logs (strongest first), lines within 2 % merged,
    at most MAX_LINES."""
    periods = []
    for ln in sorted((ln for lines in lines_per_log for ln in lines), key=lambda ln: -ln["ratio"]):
        if all(abs(ln["period_s"] / p - 1.0) > 0.02 for p in periods):
            periods.append(ln["period_s"])
    return periods[:MAX_LINES]


def _ratios(scan, level):
    if scan == "period_s":
        return (0.96, 0.98, 1.02, 1.04) if level == 1 else (0.99, 1.01)
    return (2 ** -0.5, 2 ** -0.25, 2 ** 0.25, 2 ** 0.5) if level == 1 else (2 ** -0.125, 2 ** 0.125)


def _config_like(train, cfg, alt):
    """cfg with another rate estimator (span from the training data)."""
    from host_tools.golden.rate import RateConfig
    keep = [np.asarray(log.mode) != rl.MODE_EXCHANGE for log in train]
    ps = [log[cfg.proxy.column] for log in train]
    rate = RateConfig.from_data(ps, cfg.rate.fs, alt["estimator"], alt["n"], alt.get("shift", cfg.rate.shift),
                                restarts=[log.segments for log in train], masks=keep)
    return replace(cfg, rate=rate)
