"""Close the loop on measured data: find the residual of a bias model, trace it to an effect the
model lacks, add that effect through the auxiliary term k7, and report the error before and after:
``hdrg diagnose RUN... [--holdout RUN...] --out DIR [--json report.json]``.

Procedure (:func:`diagnose`)
----------------------------
1. **Fit** the starting model on the training runs exactly as ``hdrg fit`` does with its defaults
   (:func:`base_options` / :func:`base_model`: the options not given are None, so
   host_tools.compensate's DEFAULT_RATE / DEFAULT_ORDER / DEFAULT_COMBINER / DEFAULT_TERMS apply:
   one place); ``--proxy``, ``--rate-estimator``, ``--terms``, ``--order``, ``--combiner`` as in
   ``hdrg fit``.  A regress_first model (two coefficient banks by mode) is scanned with the banked
   design: every column once per mode, on the per-mode used samples, target c = s * rate, raw
   noise surrogates (no combiner in the target).
2. **Residual** = the model's target (FTR output or mode-reversal combined output) minus the
   model, on the valid samples; characterized per run (:func:`characterize`): Allan deviation
   against the white-noise line extrapolated from the shortest tau (taus where it is > 2x that line
   hold structure above white noise), spectrum lines (:func:`spectral_lines`: Hann-windowed
   periodogram of the mean-free residual, invalid samples interpolated, over a local median
   continuum; gap-free logs only), and the binned means / correlation of the residual against
   time, proxy rate, mode and every logged channel.
3. **Trace**: every candidate of host_tools.effects (physically motivated regressor families,
   computed causally from the log, parameters scanned on coarse grids) is scored by
   cross-validation: groups are the training runs (leave one run out) or, with a single training
   run, ``cv_blocks`` contiguous time blocks dealt round-robin into ``cv_folds`` folds (each fold
   holds out contiguous blocks spread over the run, so no fold extrapolates the polynomial in u);
   never random samples.  In each fold the base terms (the polynomial terms plus the generators
   already added, each its own column) AND the candidate are refitted on the training part and
   scored on the held-out part (:class:`_Scanner`).  The score is on SCORE_TAU_S = 1-s means of
   the valid samples (the samples themselves at <= 1 Hz; at 50 Hz the white noise of single
   samples would swamp any slow effect): ``gain = 1 - SSE_heldout(with candidate) /
   SSE_heldout(base)``, summed over folds.  A candidate may also be another rate estimator (lsq
   over 16 or 64 s, iir with 2^shift / fs = 8, 32, 128 or 512 s; family ``rate_estimator``): it
   replaces the v terms instead of adding a column, and is scored on the samples valid under
   both estimators (a longer warm-up must not win by hiding the start of a run); effects are
   preferred to it when both pass (its warm-up would hide a turn-on).
4. **Selection rule** (:data:`RULE`): the best candidate is accepted only when

   a. its CV gain >= ``g_min`` (default 0.02: it explains at least 2 % of the held-out residual
      variance of 1-s means), and
   b. its CV gain >= the gain it needs under max-T: every candidate is rescored on
      ``n_surrogates`` (39) surrogate noise series per training run (:func:`noise_model`: white +
      flicker fitted to the residual's Allan variance at taus <= NOISE_TAU_MAX_S, where effects
      are not; :func:`surrogates`: Gaussian, no wrap-around, through the model's combiner for
      mode-reversal logs, absolute level, never rescaled to the residual); each candidate's gain
      is standardized by its own null (median, 84th percentile - median); the 95 % level of the
      scan's LARGEST standardized null gain over the surrogates, mapped back through each
      candidate's own null, is the gain that candidate needs (``null95``).  So the threshold
      counts every candidate and scan point, and a candidate that fits noise easily (a wandering
      aux channel) does not raise the bar for the others; and
   c. it is consistent: it lowers the held-out error in a strict majority of the folds (all folds
      with 2 runs).

   Ties: among the candidates within 5 % (relative) of the best gain, one computed from the proxy,
   the mode and the sample counter alone is preferred to one that needs another logged channel
   (board_temp, aux_*) (:func:`_preferred`).  The winner's continuous parameter (tau or period)
   is then refined on finer grids (ratios 2^(+-1/4, +-1/2), then 2^(+-1/8); periods +-2, 4 %,
   then +-1 %) by the same CV gain.  Periodic candidates: at the periods of significant lines of
   the training residual (power / continuum > ln(bins / 0.01)) and on a period grid (120 s ..
   a third of the run, ratio 2^(1/4)); never at a **combiner line** (:func:`combiner_lines`: the
   reversal cycle, its harmonics and their sidebands with the chamber cycle), which is reported
   in ``artifacts`` with the combiner as the cause and the structural fix.
5. **Add the effect**: the polynomial terms plus every accepted generator as its own column are
   refitted by a small explicit least-squares solve on the training runs; the generator weights
   are normalized by the sum of their magnitudes (so |z| <= 1 everywhere, host_tools.regressors)
   and baked into ``AuxConfig('sum', ...)``; the fitter then fits the 17 coefficients with k7.
   (A rate_estimator winner changes the model's rate estimator instead.)  **Confirm** it on the
   held-out runs (:data:`CONFIRM_RULE`): if the held-out error does not drop, the step is
   reported ``confirmed: false`` and reverted, its family is not offered again.  Iterate while a
   candidate passes the rule, at most ``max_iter`` (3) times per phase.  **Structure first**
   (:data:`PHASES`): phase 1 offers only the structural candidates (:func:`kind_of`: the rate
   estimator, the lag-state block of the proxy, board_temp = the second thermometer, lags <=
   STRUCT_TAU_FRACTION of the run), then for mode-reversal logs the order/combiner
   (:func:`_order_step`: regress_first with each other combiner, whole-model CV), confirmed the
   same way; phase 2 offers the effect families on the residual of the structured base.  Steps
   carry ``kind`` 'structure' / 'effect'; the verdict is "effect found" only for a kept effect
   step.  The confirmation (:data:`CONFIRM_RULE`) also counts the mean offset: per held-out run,
   the quadratic mean over its legs (gap-free segments) of their rms with the mean may rise by at
   most CONFIRM_TOL_RMS (:func:`offsets_hold`).
6. **Report**: per iteration the effect, its parameters, the evidence (CV gain, threshold, folds,
   ranking; PNG: residual vs the candidate, Allan deviation and spectrum before/after) and the
   error before and after (:func:`error_stats`: stability 1 sigma and variation p-p of 1-s and
   100-s averages, host_tools.metrics) on the held-out runs (the training runs when none are
   given; several runs: the mean over runs), next to the noise floor (white noise: the Allan
   deviation at 1 s, and that / 10 for 100 s).  DIR/diagnose.json (also ``--json``),
   DIR/diagnose.md, DIR/model.json (the final model, usable by ``hdrg compensate``) and
   DIR/*.png.

Limits: with a single training run, slow candidates (aging, long lags) cannot be told from the
run's own slow noise as well as across runs; a turn-on transient or anything else that only a
part of a run holds needs two runs to be identified.  Tau-scans of filters/decays assume the
nominal sample rate.
"""
from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass, field, replace

import numpy as np

from firmware_ref.terms import K_AUX, TERM_NAMES
from host_tools import effects, metrics
from host_tools import runlog as rl
from host_tools.atomic import atomic_open, atomic_path
from host_tools.compensate import compensate, fit_config_from_logs, prepare, residual
from host_tools.fit import fit_default, fit_logs
from host_tools.model import BiasModel, jsonable
from host_tools.regressors import AuxConfig, generator_values, regressor_matrix

G_MIN = 0.02                 # minimum CV gain (fraction of held-out residual variance)
N_SURROGATES = 39            # surrogate residuals for the null of the scan's best gain
NULL_QUANTILE = 0.95
NULL_SD_FLOOR = 0.005        # max-T: smallest upper-tail scale of a candidate's null gains
MAX_ITER = 3
CV_BLOCKS = 16               # single training run: contiguous blocks ...
CV_FOLDS = 4                 # ... dealt round-robin into folds
BAND_RATIO = 2 ** 0.25       # spectrum continuum: median over 1/4-octave bands
LINE_ALPHA = 0.01            # spectrum lines: false-alarm level over all bins (Bonferroni)
MAX_LINES = 3                # periodic candidates: at most this many lines ...
PERIOD_GRID_MIN_S = 120.0    # ... plus a grid of periods from this, ratio 2^(1/4), up to a third of the run
PERIOD_GRID_RATIO = 2 ** 0.25
RATE_ALTERNATIVES_S = (16.0, 64.0)   # rate_estimator candidates: lsq windows [s] ...
RATE_IIR_TAUS_S = (8.0, 32.0, 128.0, 512.0)   # ... and iir time constants 2^shift / fs [s]
REPORT_TAUS = (1.0, 100.0)
TOP_RANKING = 12
CONFIRM_MIN_DROP = 0.05      # a confirmed step lowers the held-out error by >= 5 % ...
CONFIRM_TOL_1S = 0.01        # ... and raises the held-out 1-s std by at most 1 %
CONFIRM_TOL_RMS = 0.05      # ... and raises no held-out run's leg rms (mean offsets included) by more than 5 %
RMS_MIN_SAMPLES = 10         # a leg (gap-free segment) needs this many valid samples to count
CONFIRM_RULE = ("a step is confirmed iff, on the held-out runs, the std of 100-s averages (1-s where "
                "100 s is undefined) drops by >= 5 %, the std of 1-s averages rises by at most 1 % and, per "
                "held-out run, the leg rms (quadratic mean over its gap-free segments of each segment's rms, "
                "mean offset included) rises by at most 5 %; an unconfirmed step is reverted and its family "
                "not offered again")
SCORE_TAU_S = 1.0            # the CV scores bin means of this many seconds (the report's shortest tau)
TIE_TOLERANCE = 0.05         # gains within 5 % (relative) of the best are a tie: prefer the proxy

RULE = ("accept the best candidate iff (a) its cross-validated gain (1 - held-out SSE of 1-s means "
        "with it / without it, the base terms refitted with it in every fold; folds: runs, or "
        "contiguous blocks of one run) >= g_min, (b) that gain >= the gain it needs under max-T: "
        "the 95 % level of the scan's largest standardized gain on surrogate noise (white + flicker "
        "fitted to the residual's Allan variance at short taus, through the combiner), mapped back "
        "through the candidate's own null, and (c) it lowers the held-out error in a strict "
        "majority of the folds; ties within 5 % prefer a regressor of the proxy alone; then refine "
        "its parameter; stop when no candidate passes or after max_iter iterations")


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
            self.e0[f] = self.S[f] - 2.0 * np.einsum("ij,ij->j", b, self.B[f]) + \
                np.einsum("ij,ij->j", b, self.A[f] @ b)

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
            b, c = sol[:p], sol[p:]
            Ab = self.A[f] @ b + D[f] @ c
            Ec = D[f].T @ b + E[f] @ c
            out[f] = (self.S[f] - 2.0 * (np.einsum("ij,ij->j", b, self.B[f]) + np.einsum("ij,ij->j", c, F[f]))
                      + np.einsum("ij,ij->j", b, Ab) + np.einsum("ij,ij->j", c, Ec))
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
    n = len(v)
    if cv_folds < 2 or cv_blocks < cv_folds:
        raise ValueError(f"a single training run needs cv_folds >= 2 and cv_blocks >= cv_folds "
                         f"(got {cv_blocks} blocks, {cv_folds} folds)")
    block = (np.arange(n) * cv_blocks) // max(n, 1)
    groups = [(0, np.flatnonzero(v & (block % cv_folds == k))) for k in range(cv_folds)]
    if any(len(idx) == 0 for _, idx in groups):
        raise ValueError("a CV fold holds no valid sample: the run is too short for the blocks")
    return groups


# ---------------------------------------------------------------------------------------------
# spectrum: continuum, lines, surrogates
# ---------------------------------------------------------------------------------------------

def _filled(resid, valid):
    """The mean-free residual on the valid rows, linearly interpolated (in row index) across the
    invalid ones (mode exchanges, warm-up; held at the ends): a gap-free series for spectra.
    Zero-filling instead would modulate the residual by the exchange pattern (spurious lines)."""
    valid = np.asarray(valid, bool)
    r = np.asarray(resid, np.float64)
    if not valid.any():
        return np.zeros(len(r))
    rv = r[valid] - r[valid].mean()
    idx = np.flatnonzero(valid)
    return np.interp(np.arange(len(r)), idx, rv)


MIN_BAND_BINS = 5            # continuum bands with fewer bins: mean instead of median


def continuum(power) -> np.ndarray:
    """Smooth noise continuum of a periodogram ``power`` (bins 0..K, bin 0 ignored): per
    1/4-octave band of bins, the median / ln 2 (the mean of an exponential ordinate; the median
    ignores the few bins a line occupies) in bands of >= MIN_BAND_BINS bins, the plain mean in the
    narrower bands at the lowest frequencies; interpolated in log-log between band centres.  The
    lowest bins thus keep their own power: a slow residual counts as noise there, since one run
    cannot tell a slow effect from slow noise (conservative)."""
    K = len(power) - 1
    if K < 1:
        return np.zeros_like(power)
    edges = [1]
    while edges[-1] <= K:
        edges.append(max(edges[-1] + 1, int(math.ceil(edges[-1] * BAND_RATIO))))
    centres, levels = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = power[a:min(b, K + 1)]
        if len(seg) == 0:
            continue
        lev = float(np.mean(seg)) if len(seg) < MIN_BAND_BINS else float(np.median(seg)) / math.log(2.0)
        centres.append(math.sqrt(a * (a + len(seg) - 1)))
        levels.append(max(lev, 1e-300))
    k = np.arange(K + 1, dtype=np.float64)
    k[0] = 1.0
    out = np.exp(np.interp(np.log(k), np.log(centres), np.log(levels)))
    out[0] = 0.0
    return out


def local_continuum(power, exact_upto=256) -> np.ndarray:
    """Continuum of a periodogram for the line test: at bin k the median / ln 2 of the bins k'
    with 2 <= |k' - k| <= max(6, ceil(k / 4)), 1 <= k' <= K (the bin and its direct neighbours,
    where a line leaks, excluded); above ``exact_upto`` the band :func:`continuum` (a line is a
    negligible part of a band there)."""
    K = len(power) - 1
    out = continuum(power)
    kmax = min(K, exact_upto)
    if kmax < 1:
        return out
    ks = np.arange(1, kmax + 1)
    hs = np.maximum(6, np.ceil(ks / 4.0).astype(np.int64))
    H = int(hs.max())
    pad = H + 2
    padded = np.concatenate([np.full(pad, np.nan), np.asarray(power, np.float64), np.full(pad, np.nan)])
    padded[pad] = np.nan                     # bin 0 never enters
    offs = np.concatenate([np.arange(-H, -1), np.arange(2, H + 1)])
    win = padded[pad + ks[:, None] + offs[None, :]]
    win[np.abs(offs)[None, :] > hs[:, None]] = np.nan
    count = np.sum(~np.isnan(win), axis=1)
    srt = np.sort(win, axis=1)                    # NaN sort last
    med = 0.5 * (np.take_along_axis(srt, (count // 2)[:, None], 1)[:, 0]
                 + np.take_along_axis(srt, np.maximum((count - 1) // 2, 0)[:, None], 1)[:, 0])
    ok = count >= 3
    out[ks[ok]] = np.maximum(med[ok] / math.log(2.0), 1e-300)
    return out


def spectral_lines(resid, valid, fs, max_lines=MAX_LINES, alpha=LINE_ALPHA) -> list:
    """Significant lines of a residual: periodogram (Hann window) of the mean-free residual
    (invalid samples interpolated, :func:`_filled`)
    over its :func:`local_continuum`; a bin is a line when power / continuum > ln(K / alpha) (K
    bins: about alpha false alarms per spectrum) and a local maximum, with a period between 4
    samples and a third of the record.  Returns up to ``max_lines`` dicts {period_s, ratio,
    amp_dph} (strongest first; amp: the sinusoid amplitude estimate)."""
    valid = np.asarray(valid, bool)
    r = _filled(np.asarray(resid, np.float64), valid)
    n = len(r)
    if n < 16 or not valid.any():
        return []
    X = np.fft.rfft(r * np.hanning(n))
    power = np.abs(X) ** 2
    cont = local_continuum(power)
    K = len(power) - 1
    thr = math.log(K / alpha)
    ratio = np.where(cont > 0, power / np.where(cont > 0, cont, 1.0), 0.0)
    k = np.arange(len(power))
    ok = (k >= 3) & (k <= n / 4.0)
    cand = [i for i in np.flatnonzero(ok & (ratio > thr))
            if ratio[i] >= ratio[i - 1] and ratio[i] >= ratio[min(i + 1, K)]]
    cand.sort(key=lambda i: -ratio[i])
    frac = float(valid.mean())
    return [{"period_s": float(n / (i * fs)), "ratio": float(ratio[i]),
             "amp_dph": float(4.0 * np.abs(X[i]) / (n * max(frac, 1e-12)))} for i in cand[:max_lines]]


SURROGATE_OVERSAMPLE = 4     # surrogates are cut from a series this many times longer (no wrap-around)
NOISE_TAU_MAX_S = 64.0       # the noise model is fitted to the Allan variance at taus <= this [s]


def noise_model(resid, t_s, valid, fs, reversal=False) -> dict:
    """The noise of a residual, fitted where slow effects are not: the overlapping Allan variance
    of the valid gap-free stretches (host_tools.metrics.allan, allantools; a mode-reversal log's
    stretches are single dwells) at taus <= NOISE_TAU_MAX_S is fitted (non-negative least squares,
    relative errors) by ``AVAR(tau) = A / tau + B + C tau + D tau^2``: white noise (A = sigma^2 /
    fs, sigma the per-sample std), flicker / bias instability (B = 2 ln2 h_-1), rate random walk
    (C = 2 pi^2 h_-2 / 3) and a drift (D, deterministic: dropped).  So the noise is what the
    short-tau statistics say, extrapolated to long taus by its white and flicker laws; a slow
    effect in the residual (power at long taus only) does not enter it.  The random-walk and
    drift terms are fitted but NOT kept: at taus <= 64 s a rate random walk cannot be told from
    the start of a slow effect (on the foreign devices with an undeclared effect the fitted C was
    50x the true random walk), so keeping it would let the noise swallow the effect.  A real
    random walk does not repeat from run to run or block to block: the cross-validation and the
    held-out confirmation are what stand against it.

    For a mode-reversal residual (``reversal``) the combined output within a window is half the
    raw output plus a deterministic part of the other window, so the raw noise is twice the
    fitted one: the returned coefficients are for the RAW per-sample output (the surrogates pass
    it through the combiner, :func:`surrogates`).  Returns {white_dph (sigma), flicker_dph
    (sqrt B: the flat Allan level), rw_dph_per_sqrt_s (0, see above), slow_dropped (the tau /
    tau^2 terms were non-zero), taus_s, fs, raw_scale} or None when fewer than 3 taus are available."""
    from scipy.optimize import nnls
    a = metrics.allan(resid, t_s, valid, fs)
    taus = np.asarray(a["tau_s"], np.float64)
    adev = np.asarray(a["adev_dph"], np.float64)
    keep = (taus <= NOISE_TAU_MAX_S) & (adev > 0)
    if keep.sum() < 3:
        return None
    taus, avar = taus[keep], adev[keep] ** 2
    cols = [1.0 / taus, np.ones_like(taus)] + ([taus, taus ** 2] if keep.sum() >= 5 else [])
    M = np.column_stack(cols) / avar[:, None]
    coef = nnls(M, np.ones(len(taus)))[0]
    scale = 2.0 if reversal else 1.0
    A, B = coef[:2] * scale ** 2
    C = 0.0      # the tau and tau^2 terms absorb slow structure (effects): not noise
    return {"white_dph": float(math.sqrt(A * fs)), "flicker_dph": float(math.sqrt(B)),
            "rw_dph_per_sqrt_s": float(math.sqrt(3.0 * C)), "slow_dropped": bool(len(coef) > 2 and np.any(coef[2:] > 0)),
            "taus_s": taus.tolist(), "fs": float(fs), "raw_scale": scale,
            "_psd": (2.0 * A, B / (2.0 * math.log(2.0)), 3.0 * C / (2.0 * math.pi ** 2))}


def _noise_series(nm, n, count, rng) -> np.ndarray:
    """``count`` Gaussian series (n, count) with the one-sided PSD ``h0 + h1 / f + h2 / f^2`` of
    the noise model ``nm`` (:func:`noise_model`), each a random window of a SURROGATE_OVERSAMPLE x
    longer series (no wrap-around: it drifts and wanders like a real record)."""
    h0, h1, h2 = nm["_psd"]
    fs = nm["fs"]
    L = SURROGATE_OVERSAMPLE * n
    f = np.arange(L // 2 + 1) * (fs / L)
    f[0] = 1.0
    amp = np.sqrt((h0 + h1 / f + h2 / f ** 2) * L * fs / 2.0)
    amp[0] = 0.0
    out = np.zeros((n, count))
    for c in range(count):
        spec = amp * (rng.standard_normal(len(amp)) + 1j * rng.standard_normal(len(amp))) / math.sqrt(2.0)
        x = np.fft.irfft(spec, L)
        start = int(rng.integers(0, L - n + 1))
        out[:, c] = x[start:start + n]
    return out


def _combined(cfg) -> bool:
    """The model's target is a combiner output (mode reversal, order combine_first); regress_first
    regresses the per-sample signed output (the noise is raw)."""
    return cfg.reversal is not None and cfg.reversal.order != "regress_first"


def surrogates(nm, log, cfg, count, rng, project=None):
    """``(noise, residual)``: ``count`` surrogate noise series (n, count) of a training log from
    its noise model ``nm`` (:func:`noise_model`; absolute level, not rescaled to the residual)
    and their residuals after the base fit (``noise - project(noise)``).  On a mode-reversal log
    the raw noise goes through the model's combiner (host_tools.reversal, the same kernel), so the
    surrogate carries what the combiner does to noise (window means, trend extrapolation)."""
    n = len(log)
    if count == 0 or nm is None:
        z = np.zeros((n, count))
        return z, z
    w = _noise_series(nm, n, count, rng)
    if _combined(cfg):
        from host_tools.reversal import combine_values
        mode = np.asarray(log.mode, np.int64)
        ok = np.ones(n, np.bool_)
        for c in range(count):
            w[:, c] = combine_values(mode, w[:, c], ok, log.segments, cfg.reversal, cfg.rate.fs)[0]
    rs = w - project(w) if project is not None else w
    return w, rs


ARTIFACT_HARMONICS = 4       # combiner artifacts: lines at m f_rev + k f_chamber, m = 1..4 ...
ARTIFACT_SIDEBANDS = 3       # ... |k| <= 3


def combiner_lines(train, cfg) -> dict | None:
    """Where the mode-reversal combiner puts spectral lines: the reversal cycle f_rev (median time
    between the starts of mode-1 windows), its harmonics m f_rev (m <= ARTIFACT_HARMONICS) and
    their sidebands with the chamber cycle m f_rev + k f_ch (|k| <= ARTIFACT_SIDEBANDS; f_ch: the
    strongest bin of the Hann periodogram of the mean-free proxy).  A residual the combiner leaves
    (a mode-sign term times a slowly varying envelope) is a square wave at f_rev modulated by the
    chamber cycle: exactly these lines.  None for FTR logs or without two reversal cycles."""
    if cfg.reversal is None:
        return None
    fs = cfg.rate.fs
    starts, fch = [], []
    for log in train:
        mode = np.asarray(log.mode)
        st = np.flatnonzero((mode[1:] == 1) & (mode[:-1] != 1)) + 1
        if len(st) >= 3:
            starts.append(np.diff(log.t_s[st]))
        _, prx = log.proxy(cfg.proxy.kind)
        prx = np.asarray(prx, np.float64) - np.mean(prx)
        P = np.abs(np.fft.rfft(prx * np.hanning(len(prx)))) ** 2
        if len(P) > 2:
            fch.append((1 + int(np.argmax(P[1:]))) * fs / len(prx))
    if not starts:
        return None
    t_rev = float(np.median(np.concatenate(starts)))
    f_ch = float(np.median(fch)) if fch else 0.0
    dur = max(float(log.t_s[-1] - log.t_s[0]) for log in train)
    tol = min(1.5 / dur, f_ch / 3.0) if f_ch > 0 else 1.5 / dur
    return {"reversal_period_s": t_rev, "chamber_period_s": 1.0 / f_ch if f_ch > 0 else None,
            "tolerance_hz": tol, "combiner": cfg.reversal.combiner}


def artifact_of(period_s, cl) -> str | None:
    """'m f_rev + k f_ch' when a line at ``period_s`` is a combiner line of :func:`combiner_lines`
    ``cl``, else None."""
    if cl is None:
        return None
    f, f_rev = 1.0 / period_s, 1.0 / cl["reversal_period_s"]
    f_ch = 1.0 / cl["chamber_period_s"] if cl["chamber_period_s"] else 0.0
    for m in range(1, ARTIFACT_HARMONICS + 1):
        for k in range(-ARTIFACT_SIDEBANDS, ARTIFACT_SIDEBANDS + 1) if f_ch else (0,):
            if abs(f - (m * f_rev + k * f_ch)) <= cl["tolerance_hz"]:
                return f"{m} f_rev {'+' if k >= 0 else '-'} {abs(k)} f_chamber"
    return None


def _artifact_entry(line, cl, why) -> dict:
    fix = ("another combiner (--combiner pair or trend), or regress-then-reverse (the bias model applied "
           "per mode before the combiner: order regress_first, combiner none)")
    return {"period_s": line["period_s"], "amp_dph": line["amp_dph"], "ratio": line["ratio"], "at": why,
            "cause": f"the mode-reversal combiner ({cl['combiner']}): a line at the reversal cycle "
                     f"({cl['reversal_period_s']:g} s), its harmonics or their sidebands with the chamber cycle "
                     f"({_fmt(cl['chamber_period_s'])} s); not a periodic bias of the sensor",
            "structural_fix": fix}


# ---------------------------------------------------------------------------------------------
# residual characterization
# ---------------------------------------------------------------------------------------------

def _binned(x, r, bins=10):
    """Binned means of r by quantile bins of x (unique values when x has few): list of
    {"x": centre, "mean_dph", "n"}."""
    vals = np.unique(x)
    if len(vals) <= bins:
        return [{"x": float(v), "mean_dph": float(r[x == v].mean()), "n": int(np.sum(x == v))} for v in vals]
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    out = []
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            out.append({"x": float(x[sel].mean()), "mean_dph": float(r[sel].mean()), "n": int(sel.sum())})
    return out


def _allan_bridged(resid, t_s, valid, fs=None) -> dict:
    """metrics.allan of the residual with its invalid samples (mode exchanges, warm-up) bridged by
    linear interpolation (:func:`_filled`), so a mode-reversal log reaches long taus (its valid
    stretches are at most one dwell long); time gaps still break the stretches."""
    return metrics.allan(_filled(resid, valid), t_s, np.ones(len(resid), bool), fs)


def characterize(log, resid, valid, fs, v=None) -> dict:
    """The residual of one run against its own noise floor (see the module doc): ``allan``
    (:func:`_allan_bridged`: tau_s, adev_dph, white_dph = the white-noise line through the
    shortest tau, structure_taus_s = the taus where adev > 2 x white_dph), ``lines`` (:func:`spectral_lines`),
    ``dependence`` {channel: {corr, range_dph, bins}} over time_s, proxy_rate (v), mode and every
    logged channel but t_s/rate_dph, ``rms_dph``."""
    valid = np.asarray(valid, bool)
    out = {"source": log.source, "n_valid": int(valid.sum()),
           "rms_dph": float(np.std(resid[valid])) if valid.any() else None}
    a = _allan_bridged(resid, log.t_s, valid, fs)
    taus = np.asarray(a["tau_s"], np.float64)
    adev = np.asarray(a["adev_dph"], np.float64)
    white = adev[0] * np.sqrt(taus[0] / taus) if len(taus) else np.zeros(0)
    out["allan"] = {"tau_s": taus.tolist(), "adev_dph": adev.tolist(), "white_dph": white.tolist(),
                    "structure_taus_s": taus[adev > 2.0 * white].tolist(),
                    "adev_1s_dph": a["adev_1s_dph"], "bias_instability_dph": a["bias_instability_dph"]}
    out["lines"] = spectral_lines(resid, valid, fs) if len(log.segments) == 1 else []
    dep = {}
    if valid.sum() >= 20:
        r = resid[valid]
        chans = {"time_s": log.t_s}
        if v is not None:
            chans["proxy_rate"] = v
        chans["mode"] = log.mode
        for name in log.columns:
            if name not in ("t_s", "rate_dph", "mode"):
                chans[name] = log[name]
        for name, x in chans.items():
            x = np.asarray(x, np.float64)[valid]
            sd = float(np.std(x))
            corr = float(np.corrcoef(x, r)[0, 1]) if sd > 0 and np.std(r) > 0 else 0.0
            bins = _binned(x, r)
            means = [b["mean_dph"] for b in bins]
            dep[name] = {"corr": corr, "range_dph": float(max(means) - min(means)) if means else 0.0, "bins": bins}
    out["dependence"] = dep
    return out


# ---------------------------------------------------------------------------------------------
# error statistics
# ---------------------------------------------------------------------------------------------

STAT_KEYS = ("std_dph", "pp_dph", "std100_dph", "pp100_dph", "rms_dph")


def leg_rms(y, valid, segments) -> list:
    """rms [deg/h] of the valid samples of ``y`` per gap-free segment (a held-out leg), the MEAN
    OFFSET INCLUDED (a static record's compensated output should be 0 after the fit's k0); None
    for a segment with fewer than RMS_MIN_SAMPLES valid samples."""
    y = np.asarray(y, np.float64)
    ok = np.asarray(valid, bool) & np.isfinite(y)
    bounds = list(np.asarray(segments, np.int64)) + [len(y)]
    out = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        v = y[a:b][ok[a:b]]
        out.append(float(np.sqrt(np.mean(v ** 2))) if len(v) >= RMS_MIN_SAMPLES else None)
    return out


def _stats_one(y, t, valid) -> dict:
    """STAT_KEYS of one output: std / pp of 1-s and 100-s averages, rms with the mean [deg/h]."""
    m = metrics.bias_metrics(y, t, valid, taus=REPORT_TAUS)
    r1, r100 = metrics.at_tau(m, 1.0), metrics.at_tau(m, 100.0)
    ok = np.asarray(valid, bool) & np.isfinite(y)
    return {"std_dph": r1["stability_dph"], "pp_dph": r1["variation_dph"],
            "std100_dph": r100["stability_dph"], "pp100_dph": r100["variation_dph"],
            "rms_dph": float(np.sqrt(np.mean(np.asarray(y)[ok] ** 2))) if ok.any() else None}


def _mean_stats(rows) -> dict:
    out = {}
    for key in STAT_KEYS:
        vals = [r[key] for r in rows if r[key] is not None]
        out[key] = float(np.mean(vals)) if vals else None
    return out


def error_stats(logs, model: BiasModel, other: BiasModel | None = None) -> dict:
    """The error of ``model`` on ``logs``: the compensated output (host_tools.compensate) judged
    by host_tools.metrics: ``std_dph``/``pp_dph`` (1 sigma / peak-to-peak of 1-s averages) and
    ``std100_dph``/``pp100_dph`` (100-s averages), deg/h, mean over the logs (None where no log
    supports that tau); ``runs`` holds the per-run values.  With ``other``, only the samples
    valid under both models count (a longer rate warm-up must not win by hiding samples)."""
    rows = []
    for log in logs:
        out = compensate(log, model)
        valid = np.asarray(out["valid"]) == 1
        if other is not None:
            valid &= np.asarray(compensate(log, other)["valid"]) == 1
        rows.append({"run": log.source, **_stats_one(out.rate_dph, log.t_s, valid),
                     "rms_legs_dph": leg_rms(out.rate_dph, valid, log.segments)})
    return {**_mean_stats(rows), "runs": rows}


def _residuals(logs, model):
    res = []
    for log in logs:
        pr = prepare(log, model)
        res.append((pr, residual(pr, model)[0]))
    return res


def noise_floor(logs, model) -> dict:
    """White-noise floor of the model's residual on ``logs`` (mean over logs): the Allan deviation
    at 1 s (the 1-s std of white noise) and that / 10 (its 100-s std); None if 1 s is not an
    Allan tau."""
    vals = []
    for log, (pr, r) in zip(logs, _residuals(logs, model)):
        a = metrics.allan(r, log.t_s, pr.valid)
        if a["adev_1s_dph"] is not None:
            vals.append(a["adev_1s_dph"])
    if not vals:
        return {"std_dph": None, "std100_dph": None, "method": "no 1-s Allan tau"}
    w = float(np.mean(vals))
    return {"std_dph": w, "std100_dph": w / 10.0,
            "method": "white noise: Allan deviation of the residual at 1 s; / sqrt(100) at 100 s"}


# ---------------------------------------------------------------------------------------------
# the diagnosis
# ---------------------------------------------------------------------------------------------

@dataclass
class _Accepted:
    family: str
    params: dict
    terms: list = field(default_factory=list)      # generator terms (weight 1 placeholders)
    rate: dict | None = None                       # rate_estimator winner: {"estimator", "n"}


def _poly_terms(model) -> tuple:
    return tuple(k for k in model.terms if k != K_AUX)


def _banked(pr, A):
    """A regress_first model has one coefficient bank per mode: the columns of A (n, m) become
    (n, 2m), A on mode-1 samples then A on mode-2 samples (zero elsewhere); other orders: A."""
    A = np.asarray(A, np.float64)
    if getattr(pr, "order", None) != "regress_first":
        return A
    A = A.reshape(len(A), -1)
    return np.column_stack([A * (pr.mode == 1)[:, None], A * (pr.mode == 2)[:, None]])


def _fit_mask(pr):
    """The samples a fit uses: the combined valid samples, or the per-mode used samples of regress_first."""
    return pr.used if getattr(pr, "order", None) == "regress_first" else pr.valid


def _design(pr, poly, gen_cols):
    X = regressor_matrix(pr.u, pr.v)[:, list(poly)]
    return _banked(pr, np.column_stack([X] + list(gen_cols)) if gen_cols else X)


def _explicit_weights(train, cfg, poly, gen_terms) -> list:
    """Refit poly terms + every generator as its own column (training valid samples, lstsq);
    return the generator terms with weights c_j / sum |c_j| (|z| <= 1)."""
    fs = cfg.rate.fs
    Xs, ys = [], []
    for log in train:
        pr = prepare(log, replace(cfg, aux=AuxConfig()))
        cols = [generator_values(log, t, fs) for t in gen_terms]
        X = _design(pr, poly, cols)
        Xs.append(X[_fit_mask(pr)])
        ys.append(pr.y[_fit_mask(pr)])
    X = np.concatenate(Xs)
    y = np.concatenate(ys)
    norms = np.sqrt(np.einsum("ij,ij->j", X, X))
    norms[norms == 0] = 1.0
    c = np.linalg.lstsq(X / norms, y, rcond=None)[0] / norms
    m = len(poly) + len(gen_terms)
    banks = [c[b * m + len(poly):(b + 1) * m] for b in range(len(c) // m)]
    cg = max(banks, key=lambda b: float(np.sum(np.abs(b))))   # regress_first: the larger bank's ratios
    total = float(np.sum(np.abs(cg)))
    if not total > 0:
        raise ValueError("the accepted generators have zero weight in the explicit refit")
    return [{**t, "weight": float(cj / total)} for t, cj in zip(gen_terms, cg)]


def _rate_alternatives(train, cfg) -> list:
    """The rate_estimator candidates {estimator, n, shift}: lsq over RATE_ALTERNATIVES_S seconds
    and iir with time constants 2^shift / fs in RATE_IIR_TAUS_S (nominal fs), a warm-up shorter
    than half the shortest segment, different from the current estimator."""
    from host_tools.rate import MAX_SHIFT, warmup_length
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


def _config(train, opts, rate=None, aux=None):
    o = dict(opts)
    if rate is not None:
        o["rate_estimator"], o["n"] = rate["estimator"], rate["n"]
        o["shift"] = rate.get("shift", o["shift"])
    return fit_config_from_logs(train, aux=aux, **o)


def _gain(e1, e0):
    """Per column of Y: 1 - sum_f e1 / sum_f e0."""
    return 1.0 - e1.sum(axis=0) / np.maximum(e0.sum(axis=0), 1e-300)


def _score(stats):
    """(primary, 1-s) error of error_stats: the std of 100-s averages where defined, else of 1-s."""
    return (stats["std100_dph"] if stats["std100_dph"] is not None else stats["std_dph"]), stats["std_dph"]


def confirmed_on_holdout(before, after) -> bool:
    """CONFIRM_RULE: the held-out std of 100-s averages (1-s where 100 s is undefined) drops by at
    least CONFIRM_MIN_DROP, the held-out std of 1-s averages does not rise by more than
    CONFIRM_TOL_1S (relative) and no held-out run or leg has its rms, mean offset included, raised
    by more than CONFIRM_TOL_RMS (:func:`offsets_hold`)."""
    p0, s0 = _score(before)
    p1, s1 = _score(after)
    if p0 is None or p1 is None:
        return False
    return bool(p1 <= p0 * (1.0 - CONFIRM_MIN_DROP)
                and (s0 is None or s1 is None or s1 <= s0 * (1.0 + CONFIRM_TOL_1S))
                and offsets_hold(before, after))


def _leg_rms(run) -> float | None:
    """Quadratic mean over a run's legs of their rms (mean offsets included), each leg weighted
    equally (a short leg moved by tens of deg/h counts as much as a long one)."""
    legs = [x for x in (run.get("rms_legs_dph") or []) if x is not None]
    return float(np.sqrt(np.mean(np.square(legs)))) if legs else run.get("rms_dph")


def offsets_hold(before, after) -> bool:
    """The mean-offset part of CONFIRM_RULE: per held-out run (``runs`` of error_stats, same order)
    the leg rms (:func:`_leg_rms`: each gap-free segment's rms with its mean offset, quadratic mean
    over the segments; one segment: the run's rms) rises by at most CONFIRM_TOL_RMS: a step that
    moves a held-out leg by tens of deg/h while the std drops is not an improvement.  (Each leg
    on its own is not required to improve: on a blocks split a step that halves the run's rms
    may still move one quiet block by a few deg/h.)  True when no run carries the rms."""
    for b, a in zip(before.get("runs", []), after.get("runs", [])):
        r0, r1 = _leg_rms(b), _leg_rms(a)
        if r0 is not None and r1 is not None and r1 > r0 * (1.0 + CONFIRM_TOL_RMS):
            return False
    return True


def base_options(*, proxy=None, rate_estimator=None, rate_n=None, rate_shift=None, combiner=None, order=None,
                 settle_s=None, proxy_range=None, rate_range=None, reversal=False) -> dict:
    """The keyword arguments of host_tools.compensate.fit_config_from_logs for the loop's starting
    model: every option the user did not give is None there, so the starting model is the product
    default of ``hdrg fit`` (compensate.DEFAULT_RATE / DEFAULT_ORDER / DEFAULT_COMBINER, the one
    place those are defined)."""
    return dict(proxy_kind=proxy, rate_estimator=rate_estimator, n=rate_n, shift=rate_shift,
                proxy_range=proxy_range, rate_range=rate_range,
                reversal={"combiner": combiner, "settle_s": settle_s, "order": order} if reversal else None)


def base_model(train, opts, terms=None):
    """(model, config): the loop's starting model, fitted like ``hdrg fit`` (host_tools.fit.fit_logs;
    ``terms`` None -> compensate.DEFAULT_TERMS; terms the data cannot identify are dropped).  With no
    rate option given, mode-reversal runs get the rate estimator `hdrg fit` chooses by default
    (host_tools.fit.fit_default: compensate.DEFAULT_RATE_SELECTION_MR), so the loop starts from
    exactly the model `hdrg fit` writes."""
    if all(opts.get(k) is None for k in ("rate_estimator", "n", "shift")):
        kw = {k: v for k, v in opts.items() if k not in ("rate_estimator", "n", "shift")}
        model = fit_default(train, terms, drop_unidentifiable=True, **kw)[0]
        return model, model.config
    cfg = _config(train, opts)
    return fit_logs(train, cfg, terms, drop_unidentifiable=True)[0], cfg


def diagnose(train_logs, holdout_logs=(), *, proxy=None, rate_estimator=None, rate_n=None, rate_shift=None,
             terms=None, combiner=None, order=None, settle_s=None, proxy_range=None, rate_range=None,
             max_iter=MAX_ITER, n_surrogates=N_SURROGATES, g_min=G_MIN, cv_blocks=CV_BLOCKS,
             cv_folds=CV_FOLDS, seed=0, families=None, rate_alternatives=True, out_dir=None,
             plots=True, progress=None, phases=None) -> tuple:
    """Run the closed loop (module doc) on RunLogs.  Returns ``(report, model)``: the report dict
    (the JSON of the module doc) and the final BiasModel (the last step confirmed on the held-out
    runs; without held-out runs the last accepted one).  With ``out_dir`` the files are written
    there (:func:`write_report`).  ``progress``: a callable(str) told what is being done.
    ``phases``: the phases to run (default both, structure first; ``("effect",)`` searches the
    effects on the starting model as it is, e.g. to test one effect family)."""
    say = progress or (lambda msg: None)
    train = list(train_logs)
    hold = list(holdout_logs)
    if not train:
        raise ValueError("no training runs")
    rev = any(log.reversal for log in train)
    opts = base_options(proxy=proxy, rate_estimator=rate_estimator, rate_n=rate_n, rate_shift=rate_shift,
                        combiner=combiner, order=order, settle_s=settle_s, proxy_range=proxy_range,
                        rate_range=rate_range, reversal=rev)
    say(f"fitting the base model on {len(train)} training run(s)")
    model, cfg = base_model(train, opts, terms)
    poly = _poly_terms(model)
    evals = hold if hold else train
    rng = np.random.default_rng(seed)
    accepted: list[_Accepted] = []
    gen_terms: list = []
    rate_choice = None
    iterations = []
    stopped = None
    excluded: set = set()
    first_stats = error_stats(evals, model)
    report = {"train": [log.source for log in train], "holdout": [log.source for log in hold],
              "evaluated_on": "holdout" if hold else "train", "rule": RULE,
              "confirm_rule": CONFIRM_RULE if hold else "no held-out runs: steps are not confirmed",
              "settings": {"g_min": g_min, "n_surrogates": n_surrogates, "null_quantile": NULL_QUANTILE,
                           "cv": "runs" if len(train) >= 2 else f"{cv_blocks} blocks round-robin in {cv_folds} folds",
                           "max_iter": max_iter, "seed": seed, "terms": [int(k) for k in poly]},
              "baseline": {"holdout" if hold else "train": first_stats,
                           "train": error_stats(train, model) if hold else first_stats},
              "noise_floor": noise_floor(evals, model)}
    characterization = None
    artifacts = None
    it = 0
    stops = {}
    # structure first (module doc): the model's own structure (rate estimator, lag-state block of
    # the proxy, second thermometer, order/combiner), then the effects on the structured base
    phases = PHASES if phases is None else tuple(phases)
    unknown = set(phases) - set(PHASES)
    if unknown:
        raise ValueError(f"unknown diagnose phases {sorted(unknown)}: choose from {PHASES}")
    for phase in [p for p in PHASES if p in phases]:
        stopped = None
        for _ in range(max_iter):
            it += 1
            say(f"iteration {it} ({phase}): scoring the {phase} candidates (CV, {n_surrogates} noise-model surrogates)")
            scan = _scan(train, cfg, model, poly, gen_terms, rng, n_surrogates, g_min, cv_blocks, cv_folds,
                         families, rate_alternatives and rate_choice is None, frozenset(excluded), phase=phase)
            if characterization is None:
                characterization = {"train": scan["characterization"],
                                    "holdout": [characterize(log, r, pr.valid, cfg.rate.fs, pr.v)
                                                for log, (pr, r) in zip(hold, _residuals(hold, model))],
                                    "noise_models": [jsonable(nm, skip_private=True) if nm else None
                                                     for nm in scan["noise_models"]]}
                artifacts = {"lines": scan["artifacts"], "combiner_lines": scan["combiner_lines"]}
            if not scan["accept"]:
                stopped = {k: scan[k] for k in ("best", "threshold", "ranking", "reason", "null_max")}
                stopped["phase"] = phase
                break
            best = scan["winner"]
            say(f"iteration {it}: {best['label']} passes (CV gain {best['gain']:.3f} >= {scan['threshold']:.3f}); "
                f"refitting and checking it on the {'held-out' if hold else 'training'} runs")
            before_model, before_cfg, before_gen, before_rate = model, cfg, gen_terms, rate_choice
            before = error_stats(evals, model)
            if best["family"] == "rate_estimator":
                bp = best["params"]
                rate_choice = {"estimator": bp["estimator"], "n": bp.get("n", cfg.rate.n), "shift": bp.get("shift", cfg.rate.shift)}
                acc = _Accepted("rate_estimator", dict(best["params"]), [], rate_choice)
            else:
                acc = _Accepted(best["family"], dict(best["params"]), [dict(t) for t in best["terms"]])
                gen_terms = gen_terms + acc.terms
            cfg = _config(train, opts, rate=rate_choice)
            if gen_terms:
                weighted = _explicit_weights(train, cfg, poly, gen_terms)
                cfg = replace(cfg, aux=AuxConfig.from_terms(weighted, cfg.rate.fs))
                model, _ = fit_logs(train, cfg, tuple(poly) + (K_AUX,), drop_unidentifiable=True)
            else:
                model, _ = fit_logs(train, cfg, tuple(poly), drop_unidentifiable=True)
            after = error_stats(evals, model)
            if model.config.rate != before_model.config.rate:      # compare on the common valid samples
                confirmed = confirmed_on_holdout(error_stats(evals, before_model, model),
                                                 error_stats(evals, model, before_model)) if hold else None
            else:
                confirmed = confirmed_on_holdout(before, after) if hold else None
            entry = {"effect": acc.family, "params": acc.params, "kind": kind_of(acc.family, acc.params),
                     "before": _clean(before), "after": _clean(after), "confirmed": confirmed,
                     "train_before": _clean(error_stats(train, before_model)) if hold else _clean(before),
                     "train_after": _clean(error_stats(train, model)) if hold else _clean(after),
                     "cv_gain": best["gain"], "threshold": scan["threshold"], "refined_from": best["coarse"],
                     "folds_improved": best["folds_improved"], "folds": best["folds"],
                     "ranking": scan["ranking"], "null_max": scan["null_max"],
                     "aux": model.config.aux.to_dict(), "rate": model.config.rate.to_dict(),
                     "before_runs": before["runs"], "after_runs": after["runs"]}
            entry["_plot"] = (before_model, model, best)
            iterations.append(entry)
            if confirmed is False:
                say(f"iteration {it}: {acc.family} NOT confirmed on the held-out runs "
                    f"({_fmt(_score(before)[0])} -> {_fmt(_score(after)[0])} deg/h): reverted")
                entry["status"] = "not confirmed on held-out: reverted (the model stays the last confirmed one)"
                model, cfg, gen_terms, rate_choice = before_model, before_cfg, before_gen, before_rate
                excluded.add(_step_key(acc.family, acc.params))
            else:
                entry["status"] = "confirmed on held-out" if confirmed else "accepted (no held-out runs)"
                accepted.append(acc)
        else:
            if max_iter > 0:
                stopped = {"reason": f"max_iter ({max_iter}) reached", "best": None, "threshold": None,
                           "ranking": [], "null_max": [], "phase": phase}
        if phase == "structure" and rev and max_iter > 0:
            say("structural candidates: regress-then-reverse (per-mode banks) with each combiner, by CV")
            entry, alt_model = _order_step(train, hold, evals, cfg, model, cv_blocks, cv_folds)
            if entry is not None and "skipped" in entry:
                report["structural_skipped"] = entry["skipped"]
                say(entry["skipped"])
            elif entry is not None:
                iterations.append(entry)
                if entry["confirmed"] is not False:
                    model = alt_model
                    cfg = replace(cfg, reversal=alt_model.config.reversal)
                    opts = {**opts, "reversal": {**opts["reversal"], **entry["params"]}}
                    accepted.append(_Accepted(entry["effect"], entry["params"]))
                say(f"structural: {entry['effect']} {entry['params']}: {entry['status']}")
        stops[phase] = stopped
    stopped = stops.get("effect") or stops.get("structure")
    final = error_stats(evals, model)
    kept = [e for e in iterations if e["confirmed"] is not False]
    if any(e["kind"] == "effect" for e in kept):
        verdict = "effect found"
    elif kept:
        verdict = "model structure improved"
    elif iterations:
        verdict = "no confirmed effect"
    else:
        verdict = "no significant missing effect"
    report.update({"iterations": iterations, "final": _clean(final), "final_runs": final["runs"],
                   "final_train": _clean(error_stats(train, model)) if hold else _clean(final),
                   "verdict": verdict, "verdict_detail": _verdict_detail(iterations, hold),
                   "artifacts": artifacts, "stopped": stopped, "characterization": characterization})
    model.fit["diagnose"] = {"effects": [{"effect": a.family, "params": a.params} for a in accepted],
                             "verdict": report["verdict"]}
    if out_dir is not None:
        write_report(report, model, out_dir, train, hold, plots=plots)
    for entry in iterations:
        entry.pop("_plot", None)
    return report, model


ORDER_ALTERNATIVES = ("none", "pair", "trend")   # regress_first with each combiner
STRUCTURAL = ("rate_estimator", "reversal_order", "board_temp")  # families that are the model's structure
PHASES = ("structure", "effect")
STRUCT_TAU_FRACTION = 0.25   # structure phase: lags (block, second thermometer) <= this x the longest run


def kind_of(family, params) -> str:
    """'structure' for a step that changes the model's own structure (rate estimator, order /
    combiner, the lag-state polynomial block of the proxy, the second thermometer and its lag),
    'effect' for an added effect regressor (module doc, step 3)."""
    return "structure" if family in STRUCTURAL or (family == "thermal_lag" and "order" in params) else "effect"


def _step_key(family, params) -> str:
    """The name under which a reverted step is not offered again: the family; the lag block apart."""
    return "thermal_lag_block" if family == "thermal_lag" and "order" in params else family


def _fold_logs(train, cv_blocks, cv_folds) -> list:
    """(training logs, held-out logs) per CV fold for whole-model refits: leave one run out, or
    with a single run its ``cv_blocks`` contiguous blocks dealt round-robin into ``cv_folds``
    folds (RunLog.select: the blocks become gap-separated segments)."""
    if len(train) >= 2:
        return [([g for j, g in enumerate(train) if j != f], [train[f]]) for f in range(len(train))]
    log = train[0]
    block = (np.arange(len(log)) * cv_blocks) // len(log)
    return [([log.select(block % cv_folds != k)], [log.select(block % cv_folds == k)]) for k in range(cv_folds)]


def _order_step(train, hold, evals, cfg, model, cv_blocks, cv_folds):
    """The structural candidate 'regress-then-reverse' (host_tools.reversal order regress_first:
    two coefficient banks by mode, the combiner applied to the residual) with each combiner of
    ORDER_ALTERNATIVES, the current terms and aux generators kept: every fold refits the whole
    model (current and alternative) on its training part and scores the error (std of 100-s
    averages, 1-s where undefined) on its held-out part.  The best alternative is a step when it
    lowers the CV error by >= CONFIRM_MIN_DROP in total and in a strict majority of folds; then it
    is confirmed on the held-out runs like every step.  Returns (entry, model) or (None, None)."""
    from host_tools.reversal import ReversalConfig
    terms = tuple(model.terms)
    rc = cfg.reversal
    folds = _fold_logs(train, cv_blocks, cv_folds)

    def cv(c):
        errs = []
        for tr, te in folds:
            try:
                m, _ = fit_logs(tr, c, terms, drop_unidentifiable=True)
                errs.append(_score(error_stats(te, m))[0])
            except ValueError:
                return None
        return None if any(e is None for e in errs) else np.array(errs)

    base = cv(cfg)
    if base is None:
        return None, None
    rows = []
    for comb in ORDER_ALTERNATIVES:
        if rc.order == "regress_first" and comb == rc.combiner:
            continue
        alt = replace(cfg, reversal=ReversalConfig(comb, rc.max_stale_s, rc.settle_s, order="regress_first"))
        e = cv(alt)
        if e is not None:
            rows.append({"combiner": comb, "cfg": alt, "gain": float(1.0 - e.sum() / base.sum()),
                         "folds_improved": int(np.sum(e < base)), "folds": len(folds)})
    if not rows:
        return None, None
    best = max(rows, key=lambda r: r["gain"])
    if not (best["gain"] >= CONFIRM_MIN_DROP and best["folds_improved"] > len(folds) // 2):
        return None, None
    alt_model, _ = fit_logs(train, best["cfg"], terms, drop_unidentifiable=True)
    try:        # the model the loop writes must go to the firmware path (hdrg quantize)
        from host_tools.quantize import quantize
        quantize(alt_model, n_random=100)
    except (ValueError, ArithmeticError) as exc:
        return {"skipped": f"regress-then-reverse ({best['combiner']}) gains {best['gain']:.3f} in CV but "
                           f"does not quantize on this build: {exc}"}, None
    before, after = error_stats(evals, model), error_stats(evals, alt_model)
    confirmed = confirmed_on_holdout(before, after) if hold else None
    entry = {"effect": "reversal_order", "params": {"order": "regress_first", "combiner": best["combiner"]},
             "kind": "structure",
             "before": _clean(before), "after": _clean(after), "confirmed": confirmed,
             "train_before": _clean(error_stats(train, model)), "train_after": _clean(error_stats(train, alt_model)),
             "cv_gain": best["gain"], "threshold": CONFIRM_MIN_DROP, "refined_from": None,
             "folds_improved": best["folds_improved"], "folds": best["folds"],
             "ranking": [{"label": f"reversal_order(regress_first, {r['combiner']})", "family": "reversal_order",
                          "gain": r["gain"], "folds_improved": r["folds_improved"], "folds": r["folds"]}
                         for r in sorted(rows, key=lambda r: -r["gain"])],
             "null_max": [], "aux": alt_model.config.aux.to_dict(), "rate": alt_model.config.rate.to_dict(),
             "before_runs": before["runs"], "after_runs": after["runs"],
             "status": ("confirmed on held-out" if confirmed else "accepted (no held-out runs)") if confirmed is not False
             else "not confirmed on held-out: reverted (the model stays the last confirmed one)"}
    return entry, alt_model


def _verdict_detail(iterations, hold) -> str:
    if not iterations:
        return "no candidate passed the selection rule on the training runs"
    parts = []
    for k, e in enumerate(iterations, 1):
        tag = {True: "confirmed on held-out", False: "not confirmed on held-out (reverted)",
               None: "not confirmed (no held-out runs)"}[e["confirmed"]]
        parts.append(f"step {k} {e['effect']}: {tag}")
    kept = [k for k, e in enumerate(iterations, 1) if e["confirmed"] is not False]
    final = f"final model: after step {kept[-1]}" if kept else "final model: the base model"
    return "; ".join(parts) + "; " + final


def _clean(stats) -> dict:
    return {k: stats[k] for k in STAT_KEYS}


def _scan(train, cfg, model, poly, gen_terms, rng, n_sur, g_min, cv_blocks, cv_folds, families, rate_alt,
          excluded=frozenset(), phase=None):
    """Score every candidate (module doc, steps 3-4) against the current base; returns a dict with
    the ranking, the null, the decision and the (refined) winner."""
    fs = cfg.rate.fs
    preps = [prepare(log, replace(cfg, aux=AuxConfig())) for log in train]
    gen_cols = [[generator_values(log, t, fs) for t in gen_terms] for log in train]
    X_logs = [_design(pr, poly, gc) for pr, gc in zip(preps, gen_cols)]
    valid = [_fit_mask(pr) for pr in preps]
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
                artifacts.append(_artifact_entry(ln, clines, why))
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

        nm = noise_model(r, log.t_s, v, fs, reversal=_combined(cfg))
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
    if (families is None or "periodic" in families) and phase != "structure":      # a period grid too: a line may hide under slow residual
        dur = max(float(log.t_s[-1] - log.t_s[0]) for log in train)
        grid = PERIOD_GRID_MIN_S * PERIOD_GRID_RATIO ** np.arange(64)
        cands += [effects.periodic(float(p)) for p in grid[grid <= dur / 3.0]
                  if not artifact_of(float(p), clines) and all(abs(p / q - 1.0) > 0.05 for q in periods)]
    # drop candidates equal to an accepted generator
    have = [json.dumps(t, sort_keys=True) for t in gen_terms]
    cands = [c for c in cands if not any(json.dumps(t, sort_keys=True) in have for t in c.terms)
             and _step_key(c.family, c.params) not in excluded
             and (phase is None or (kind_of(c.family, c.params) == "structure") == (phase == "structure"))]
    dur = max(float(log.t_s[-1] - log.t_s[0]) for log in train)
    tau_max = STRUCT_TAU_FRACTION * dur if phase == "structure" else dur
    # a structural lag longer than a quarter of the run is a ramp (aging), not the device's dynamics
    cands = [c for c in cands if c.params.get("tau_s", 0.0) <= tau_max]
    rows = []
    nsur = Y_logs[0].shape[1] - 1

    def evaluate(c):
        e1 = scanner.score([b.mean(_banked(pr, c.columns(log, fs))) for b, log, pr in zip(binners, train, preps)])
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
            AX = [_design(pr, poly, gc) for pr, gc in zip(apreps, gen_cols)]
            # a longer warm-up changes the valid set: both bases are scored on the common samples
            cb = [_Binner(log, v & _fit_mask(a), fs) for log, v, a in zip(train, valid, apreps)]
            cgroups = cv_groups([np.ones(b.n, bool) for b in cb], cv_blocks, cv_folds)
            Yc = [b.mean(Y) for b, Y in zip(cb, Y_logs)]
            g_base = _Scanner([b.mean(X) for b, X in zip(cb, X_logs)], Yc, cgroups).e0
            g_alt = _Scanner([b.mean(X) for b, X in zip(cb, AX)], Yc, cgroups).e0
            g = _gain(g_alt, g_base)
            if alt["estimator"] == "lsq":
                params = {"estimator": "lsq", "n": alt["n"], "window_s": alt["n"] / acfg.rate.fs}
            else:
                params = {"estimator": "iir", "shift": alt["shift"], "tau_s": 2.0 ** alt["shift"] / acfg.rate.fs}
            inner = ", ".join(f"{k}={_fmt(v)}" for k, v in params.items() if k != "estimator")
            rows.append({"family": "rate_estimator", "label": f"rate_estimator({alt['estimator']}, {inner})",
                         "params": params, "terms": [], "gain": float(g[0]),
                         "folds_improved": int(np.sum(g_alt[:, 0] < g_base[:, 0])), "folds": nfold,
                         "_cand": None, "_null": g[1:]})
    out = {"characterization": charac, "artifacts": artifacts, "combiner_lines": clines,
           "noise_models": noise_models, "accept": False, "reason": None, "winner": None, "ranking": [],
           "best": None, "threshold": None, "null_max": []}
    if not rows:
        out["reason"] = "no candidates"
        return out
    # rule (b): the largest gain of the whole scan on each surrogate; its 95 % level
    # (max-T: every candidate's gain standardized by its own null (median, 84th percentile - median),
    # so a candidate that fits noise easily (a wandering channel) does not raise the bar for the others)
    nulls = np.array([r["_null"] for r in rows]).reshape(len(rows), nsur)
    if nsur:     # robust location / upper-tail scale: a wild negative tail must not inflate the bar
        mu = np.median(nulls, axis=1)
        sd = np.maximum(np.quantile(nulls, 0.8413, axis=1) - mu, NULL_SD_FLOOR)
        null_max = ((nulls - mu[:, None]) / sd[:, None]).max(axis=0)
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
            trial = [best] + [evaluate(c) for c in effects.refine(cand, ratios, max_value=tau_max)]
            best = max(trial, key=lambda r: r["gain"])
            cand = best["_cand"]
    best = {k: v for k, v in best.items() if not k.startswith("_")}
    best.update(significant=True, coarse=coarse["label"], coarse_gain=coarse["gain"])
    out.update(accept=True, winner=best)
    return out


def _tier(family) -> int:
    """0: a regressor from the proxy, the mode and the sample counter only; 1: it needs another
    logged channel (board_temp, aux_*)."""
    return 1 if family == "board_temp" or family.startswith("aux_") else 0


def _preferred(rows) -> dict:
    """The winner of a ranking (sorted by gain): among the rows within TIE_TOLERANCE (relative) of
    the best gain, the best one of the lowest :func:`_tier` (Occam: when another channel explains
    no more than the proxy itself, within the noise of the gains, the proxy's lag is the
    simpler model and needs no extra input in the firmware)."""
    top = rows[0]["gain"]
    close = [r for r in rows if r["gain"] >= top - TIE_TOLERANCE * abs(top)]
    tier = min(_tier(r["family"]) for r in close)
    return max((r for r in close if _tier(r["family"]) == tier), key=lambda r: r["gain"])


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
    from host_tools.rate import RateConfig
    keep = [np.asarray(log.mode) != rl.MODE_EXCHANGE for log in train]
    ps = [log[cfg.proxy.column] for log in train]
    rate = RateConfig.from_data(ps, cfg.rate.fs, alt["estimator"], alt["n"], alt.get("shift", cfg.rate.shift),
                                restarts=[log.segments for log in train], masks=keep)
    return replace(cfg, rate=rate)


# ---------------------------------------------------------------------------------------------
# report files
# ---------------------------------------------------------------------------------------------

def _fmt(x, prec=4):
    return "n/a" if x is None else f"{x:.{prec}g}"


def _stats_line(s):
    return " | ".join(_fmt(s.get(k)) for k in STAT_KEYS)


def write_report(report, model, out_dir, train, hold, plots=True) -> None:
    """DIR/diagnose.json, DIR/diagnose.md, DIR/model.json and (plots) DIR/iter<k>_*.png."""
    os.makedirs(out_dir, exist_ok=True)
    evals = hold if hold else train
    for k, entry in enumerate(report["iterations"], 1):
        figs = []
        if plots and "_plot" in entry:
            figs = _plots(k, entry["_plot"], train, evals, out_dir)
        entry["figures"] = figs
    model.to_json(os.path.join(out_dir, "model.json"))
    report["model"] = "model.json"
    doc = jsonable(report, skip_private=True)
    with atomic_open(os.path.join(out_dir, "diagnose.json"), "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1, allow_nan=False)
        fh.write("\n")
    with atomic_open(os.path.join(out_dir, "diagnose.md"), "w", encoding="utf-8") as fh:
        fh.write(markdown(doc, model))


def markdown(doc, model) -> str:
    """The human report (diagnose.md) of a report dict."""
    on = doc["evaluated_on"]
    lines = ["# hdrg diagnose", "",
             f"Training runs: {', '.join(os.path.basename(s) for s in doc['train'])}  ",
             "Held-out runs: " + (", ".join(os.path.basename(s) for s in doc["holdout"])
                                  or "(none: figures on the training runs)"),
             "", f"**Verdict: {doc['verdict']}**", "",
             "Errors in deg/h on the " + ("held-out" if on == "holdout" else "training") + " runs: stability "
             "(1 sigma) and variation (p-p) of 1-s and 100-s averages of the compensated output.", "",
             "| step | effect | params | std 1 s | p-p 1 s | std 100 s | p-p 100 s | CV gain | threshold | held-out |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---|"]
    first = doc["baseline"][on]
    lines.append(f"| 0 | (base model) | terms {doc['settings']['terms']} | {_stats_line(first)} | | | |")
    for k, it in enumerate(doc["iterations"], 1):
        params = ", ".join(f"{a}={_fmt(b) if isinstance(b, float) else b}" for a, b in it["params"].items())
        lines.append(f"| {k} | {it['effect']} | {params} | {_stats_line(it['after'])} | "
                     f"{_fmt(it['cv_gain'])} | {_fmt(it['threshold'])} | {it['status']} |")
    lines += ["", f"{doc['verdict_detail']}.  Confirmation: {doc['confirm_rule']}."]
    for a in (doc.get("artifacts") or {}).get("lines", []):
        lines += ["", f"Line at {a['period_s']:.4g} s ({a['at']}, {a['amp_dph']:.3g} deg/h): {a['cause']}.  "
                      f"Structural fix: {a['structural_fix']}."]
    nf = doc["noise_floor"]
    lines += ["", f"Noise floor (white noise of the residual): {_fmt(nf['std_dph'])} deg/h at 1 s, "
                  f"{_fmt(nf['std100_dph'])} deg/h at 100 s.", "",
              f"Selection rule: {doc['rule']}.", ""]
    if doc.get("stopped"):
        st = doc["stopped"]
        lines += [f"Stopped: {st['reason']}.", ""]
        if st.get("ranking"):
            lines += ["Best remaining candidates (CV gain, folds improved):", ""]
            lines += [f"* {r['label']}: {r['gain']:.4f} ({r['folds_improved']}/{r['folds']})"
                      for r in st["ranking"][:6]]
            lines.append("")
    for k, it in enumerate(doc["iterations"], 1):
        lines += [f"## Iteration {k}: {it['effect']}", "",
                  f"CV gain {it['cv_gain']:.4f} (threshold {it['threshold']:.4f}), improves "
                  f"{it['folds_improved']} of {it['folds']} folds.  Training: "
                  f"std 100 s {_fmt(it['train_before']['std100_dph'])} -> {_fmt(it['train_after']['std100_dph'])}; "
                  f"{'held-out' if on == 'holdout' else 'training'}: {_fmt(it['before']['std100_dph'])} -> "
                  f"{_fmt(it['after']['std100_dph'])} deg/h.", "", "Ranking:", ""]
        lines += [f"* {r['label']}: {r['gain']:.4f} ({r['folds_improved']}/{r['folds']})" for r in it["ranking"][:8]]
        lines.append("")
        for f in it.get("figures", []):
            lines.append(f"![{f}]({f})")
        lines.append("")
    ch = doc.get("characterization") or {}
    for which in ("train", "holdout"):
        for c in ch.get(which, []) or []:
            lines += [f"### Residual of the base model: {os.path.basename(c['source'])} ({which})", "",
                      f"rms {_fmt(c['rms_dph'])} deg/h; Allan deviation above 2x the white-noise line at "
                      f"tau = {', '.join(_fmt(t) for t in c['allan']['structure_taus_s']) or 'none'} s; "
                      f"spectrum lines: {', '.join(_fmt(ln['period_s']) + ' s' for ln in c['lines']) or 'none'}.", ""]
            dep = sorted(c["dependence"].items(), key=lambda kv: -abs(kv[1]["corr"]))
            lines.append("Dependence (correlation, range of binned means in deg/h): " + "; ".join(
                f"{name} {d['corr']:+.2f} / {d['range_dph']:.3g}" for name, d in dep))
            lines.append("")
    lines += ["Final model: model.json (terms " + ", ".join(f"k{k} ({TERM_NAMES[k]})" for k in model.terms) + ").", ""]
    return "\n".join(lines)


def _plots(k, plot_info, train, evals, out_dir) -> list:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.signal import welch

    before_model, after_model, best = plot_info
    files = []
    # residual vs the candidate's fitted contribution (training runs)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    after_aux = after_model.config.aux
    for log, (pr, r) in zip(train, _residuals(train, before_model)):
        if best["terms"]:
            cols = np.column_stack([generator_values(log, t, after_model.config.rate.fs) for t in best["terms"]])
            weights = [t2["weight"] for t2 in after_aux.terms[-len(best["terms"]):]]
            k7 = after_model.coef[K_AUX]
            if after_model.coef_mode2 is not None:      # two banks: the k7 of the sample's mode
                k7 = np.where(np.asarray(log.mode) == 2, after_model.coef_mode2[K_AUX], k7)
            x = cols @ np.asarray(weights) * k7
            xlabel = f"fitted {best['label']} [deg/h]"
        else:
            x = residual(prepare(log, after_model), after_model)[0] - r
            xlabel = f"{best['label']}: change of the residual [deg/h]"
        v = pr.valid
        ax.plot(x[v], r[v], ",", alpha=0.4, label=os.path.basename(log.source))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("residual before [deg/h]")
    ax.set_title(f"iteration {k}: residual vs {best['label']}", fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    files.append(f"iter{k}_candidate.png")
    with atomic_path(os.path.join(out_dir, files[-1])) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    # Allan and spectrum before/after (evaluation runs)
    fig1, ax1 = plt.subplots(figsize=(6, 4.5))
    fig2, ax2 = plt.subplots(figsize=(6, 4.5))
    for name, m, style in (("before", before_model, "--"), ("after", after_model, "-")):
        for log, (pr, r) in zip(evals, _residuals(evals, m)):
            a = _allan_bridged(r, log.t_s, pr.valid)
            label = f"{os.path.basename(log.source)} {name}"
            if a["tau_s"]:
                ax1.loglog(a["tau_s"], a["adev_dph"], style, label=label)
            g = _filled(r, pr.valid)
            nper = min(len(g), max(256, len(g) // 4))
            if nper >= 16:
                f, p = welch(g, fs=after_model.config.rate.fs, nperseg=nper)
                ax2.loglog(f[1:], p[1:], style, label=label, lw=0.8)
    ax1.set_xlabel("averaging time [s]")
    ax1.set_ylabel("Allan deviation of the residual [deg/h]\n(exchanges bridged)")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=7)
    ax2.set_xlabel("frequency [Hz]")
    ax2.set_ylabel("PSD of the residual [(deg/h)^2/Hz]")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    for fig, name in ((fig1, "allan"), (fig2, "spectrum")):
        fig.tight_layout()
        files.append(f"iter{k}_{name}.png")
        with atomic_path(os.path.join(out_dir, files[-1])) as tmp:
            fig.savefig(tmp, dpi=90, format="png")
        plt.close(fig)
    return files
