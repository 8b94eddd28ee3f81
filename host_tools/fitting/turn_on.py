"""The power-on transient of the default fit: a term in the time since power-on, learned when the
training runs' power-ons agree on it.

Every chamber calibration run starts at a power-on (t_s is the time since power-on,
docs/RUN_LOG.md), so the fit sees the device's turn-on: self-heating, which the proxy sees, and
settling that no thermometer sees (parasitic charge; paper section 4.4).  The proxy terms model
the first; this module adds the second as the chip's aux generator ``decay_on`` (g = exp(-i /
(fs tau)), i samples since the log's first sample, the power-on; host_tools.golden.regressors,
firmware_ref/aux.py), carried in k7 beside the model's other generators (a lag-state block).

Choice (:func:`add_turn_on`), on the training runs only:

* tried with at least MIN_RUNS runs, every one recorded from its power-on
  (:func:`starts_at_power_on`: a leg cut from a longer run is not), whose power-ons span at
  least MIN_START_SPREAD of the calibrated proxy range (:func:`start_spread`), and terms chosen
  by the fit ('auto'): a single power-on cannot tell a repeatable turn-on from that power-on's
  drift, and power-ons at one temperature cannot tell it from the self-heating's bias, which
  depends on the temperature;
* candidates: ``decay_on`` with tau in TAU_GRID_S up to MAX_TAU_FRACTION x the shortest run (it
  must have decayed within every run);
* **two-stage score**: stage 1 is the model as fitted on ALL runs (its terms are not refitted
  per fold); its compensated output of every run (float golden model), less the run's mean (a
  power-on's own offset is not predictable), is the residual.  Stage 2, leaving one power-on
  out: the candidate's size is fitted by least squares on the other runs' residuals and
  subtracted from the held-out run's; scored by the sum of squares of BIN_S means over the first
  :func:`window_of` seconds after power-on (WINDOW_TAUS x tau, MIN_WINDOW_S .. START_WINDOW_S)
  and over the whole run, against the residual without it.  A held-out run with fewer than
  MIN_BINS means to score fails the candidate;
* **kept** when, on EVERY held-out run, the window's error falls by at least MARGIN and the whole
  run's rises by at most RUN_TOLERANCE; of several, the one of least mean window ratio.  The
  model is then refitted on all runs with the term in k7 (all coefficients together; its weight
  beside the model's generators by least squares, :func:`decay_weight`): that refit is not
  itself cross-validated, so the start-up benchmark is the check of what ships.  When the
  model's generators fill the chip's AUX_MAX_TERMS, the sign-twin terms of a mode-reversal lag
  block make room (each coefficient bank keeps its own k7).  model.fit["turn_on"]: the
  candidates' scores and the choice (model.json).

Measured by `hdrg bench startup` (host_tools.bench.startup; docs/ACCURACY.md "Start-up").
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from firmware_ref.formats import AUX_MAX_TERMS
from firmware_ref.terms import K_AUX

TAU_GRID_S = (60.0, 120.0, 240.0, 480.0, 960.0, 1920.0)   # candidate time constants [s]
MAX_TAU_FRACTION = 0.25     # tau <= this x the shortest training run (host_tools.fitting.effects: turn_on)
START_WINDOW_S = 2700.0     # scored window after each power-on [s]: the paper's 45-min start-up
MARGIN = 0.2                # start-window SSE must fall by this fraction on every held-out power-on
MIN_RUNS = 2
WINDOW_TAUS = 3.0           # scored window after power-on: this many time constants ...
MIN_WINDOW_S = 600.0        # ... at least this long, at most START_WINDOW_S [s]
RUN_TOLERANCE = 1.05        # the whole held-out run's error may not rise by more than this factor


POWER_ON_TOLERANCE_S = 1.0  # a run starts at its power-on when its first t_s is within this (or 2 samples)
MIN_START_SPREAD = 0.25     # the power-ons' proxies must span this share of the calibrated range ...
START_PROXY_S = 60.0        # ... each the median proxy over this long after its power-on [s]


def start_spread(logs, proxy) -> float:
    """The share of the calibrated proxy range (``proxy``: the model's ProxyConfig, width 2 span)
    between the coldest and the warmest power-on of ``logs`` (each: the median proxy over its
    first START_PROXY_S).  A turn-on learned from power-ons at one temperature cannot be told from
    the self-heating's temperature-dependent bias, which another ambient changes."""
    starts = []
    for log in logs:
        t = np.asarray(log.t_s, np.float64)
        p = np.asarray(log.proxy(proxy.kind)[1], np.float64)
        m = (t - t[0] < START_PROXY_S) & np.isfinite(p)
        starts.append(float(np.median(p[m])) if m.any() else float("nan"))
    return float((max(starts) - min(starts)) / (2.0 * proxy.span)) if starts else 0.0


def starts_at_power_on(log) -> bool:
    """True when ``log`` was recorded from its power-on: t_s is the time since power-on
    (docs/RUN_LOG.md), so its first t_s is within POWER_ON_TOLERANCE_S or two sample periods of 0
    (a leg cut from a longer run, or a capture started later, is not)."""
    t = np.asarray(log.t_s, np.float64)
    period = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return bool(len(t)) and 0.0 <= float(t[0]) <= max(POWER_ON_TOLERANCE_S, 2.0 * period)


def window_of(tau_s: float) -> float:
    """The window after power-on [s] on which a candidate of time constant ``tau_s`` is scored."""
    return float(min(START_WINDOW_S, max(MIN_WINDOW_S, WINDOW_TAUS * tau_s)))


BIN_S = 100.0               # scored: means over this many seconds (the stability metric's averaging)


MIN_BINS = 3                # a held-out run is scored only with this many BIN_S means in the window


def _binned_sq(out, t, valid, window_s=None) -> float:
    """Sum of squares of the BIN_S-s means of ``out`` [deg/h] over the valid samples (the run's
    mean removed), over the first ``window_s`` [s] after power-on (None: the whole run); NaN with
    fewer than MIN_BINS means (nothing to score)."""
    t = np.asarray(t, np.float64) - float(t[0])
    ok = np.asarray(valid, bool) & np.isfinite(out)
    if ok.sum() < 2:
        return float("nan")
    x = np.asarray(out, np.float64)[ok] - float(np.mean(np.asarray(out)[ok]))
    b = (t[ok] // BIN_S).astype(np.int64)
    keep = np.ones(len(b), bool) if window_s is None else t[ok] < window_s
    sums = np.bincount(b[keep], weights=x[keep])
    cnt = np.bincount(b[keep])
    m = sums[cnt > 0] / cnt[cnt > 0]
    return float(m @ m) if len(m) >= MIN_BINS else float("nan")


def _ratio(after: float, before: float) -> float:
    """after / before; +inf (a failed fold) when either is not a finite score or before is 0."""
    return after / before if np.isfinite(after) and np.isfinite(before) and before > 0 else float("inf")


def _outputs(logs, model) -> list:
    """Per run: (t [s since power-on], compensated output less its mean [deg/h], valid) of ``model``."""
    from host_tools.golden.compensate import compensate

    out = []
    for log in logs:
        res = compensate(log, model)
        ok = (np.asarray(res["valid"]) > 0) & np.isfinite(res.rate_dph)
        y = np.where(ok, res.rate_dph, 0.0)
        if ok.any():
            y = np.where(ok, y - y[ok].mean(), 0.0)
        out.append((np.asarray(log.t_s, np.float64) - float(log.t_s[0]), y, ok))
    return out


def _fold_scores(outputs, g_runs, window_s) -> list:
    """Per held-out run i: (error ratio over the first ``window_s`` [s], over the whole run) of the
    output with the decay term (amplitude by least squares on the OTHER runs' outputs, each run's
    own offset free) to the output without it; errors = sums of squares of BIN_S means."""
    parts = []
    for (t, y, ok), g in zip(outputs, g_runs):
        gc = np.where(ok, g - (g[ok].mean() if ok.any() else 0.0), 0.0)
        parts.append((float(gc @ y), float(gc @ gc), gc))
    out = []
    for i, ((t, y, ok), (_, _, gc)) in enumerate(zip(outputs, parts)):
        num = sum(p[0] for j, p in enumerate(parts) if j != i)
        den = sum(p[1] for j, p in enumerate(parts) if j != i)
        amp = num / den if den > 0 else 0.0
        after = y - amp * gc
        out.append(tuple(_ratio(_binned_sq(after, t, ok, w), _binned_sq(y, t, ok, w)) for w in (window_s, None)))
    return out


def decay_weight(train, cfg, poly, decay) -> float:
    """The weight of the ``decay`` term beside the model's k7 z (its weights kept): per coefficient
    bank b, least squares of the target on the poly terms, z and the decay give c_z,b and c_d,b;
    the weight is the common ratio sum_b c_d,b c_z,b / sum_b c_z,b^2 (one bank: c_d / c_z)."""
    from host_tools.fitting.diagnose_scan import design_matrix, fit_mask
    from host_tools.golden.compensate import prepare
    from host_tools.golden.regressors import AuxConfig, aux_regressor, generator_values

    Xs, ys = [], []
    for log in train:
        pr = prepare(log, replace(cfg, aux=AuxConfig()))
        X = design_matrix(pr, poly, [aux_regressor(log, cfg.aux), generator_values(log, decay, cfg.rate.fs)])
        m = fit_mask(pr)
        Xs.append(X[m])
        ys.append(np.asarray(pr.y, np.float64)[m])
    X, y = np.concatenate(Xs), np.concatenate(ys)
    norms = np.sqrt(np.einsum("ij,ij->j", X, X))
    norms[norms == 0] = 1.0
    c = np.linalg.lstsq(X / norms, y, rcond=None)[0] / norms
    per = len(poly) + 2
    cz = np.array([c[b * per + len(poly)] for b in range(len(c) // per)])
    cd = np.array([c[b * per + len(poly) + 1] for b in range(len(c) // per)])
    den = float(cz @ cz)
    return float(cd @ cz / den) if den > 0 else 0.0


def candidate_taus(logs) -> list:
    """The taus of TAU_GRID_S within MAX_TAU_FRACTION x the shortest run [s]."""
    shortest = min(float(log.t_s[-1] - log.t_s[0]) for log in logs)
    return [tau for tau in TAU_GRID_S if tau <= MAX_TAU_FRACTION * shortest]


def add_turn_on(logs, model, res, refit):
    """The model with the turn-on term in k7 when leave-one-power-on-out supports it (module doc),
    else ``(model, res)`` unchanged; either way model.fit["turn_on"] says what was tried.
    ``refit(logs, config, terms)`` -> (model, FitResult): the fit with fixed terms (the caller's
    per-run offsets included)."""
    from host_tools.fitting.diagnose_scan import poly_terms
    from host_tools.fitting.effects import effect_term
    from host_tools.golden.regressors import AuxConfig

    logs = list(logs)
    cfg = model.config
    info = {"method": "two-stage: the model's compensated outputs, the turn-on's size cross-validated by leaving "
                      "one power-on out (host_tools.fitting.turn_on)", "margin": MARGIN,
            "start_window_s": START_WINDOW_S, "chosen": None}
    taus = candidate_taus(logs) if len(logs) >= MIN_RUNS else []
    gens = [t for t in cfg.aux.terms if t.get("gen") != "decay_on"]
    late = [log for log in logs if not starts_at_power_on(log)]
    spread = start_spread(logs, cfg.proxy) if len(logs) >= MIN_RUNS and not late else 0.0
    # beside the turn-on, k7 keeps the model's generators; when the chip's AUX_MAX_TERMS are all
    # used, the sign-twin terms of a mode-reversal lag block go (each bank keeps its own k7)
    kept = gens if len(gens) < AUX_MAX_TERMS else [t for t in gens if not t.get("sign")]
    if len(kept) >= AUX_MAX_TERMS:
        info["why"] = f"k7 already holds {len(gens)} generator terms (the chip's limit is {AUX_MAX_TERMS})"
    elif late:
        info["why"] = (f"{late[0].source} does not start at its power-on (first t_s {float(late[0].t_s[0]):g} s; t_s is "
                       f"the time since power-on): a turn-on is learned only from runs recorded from their power-on")
    elif len(logs) < MIN_RUNS:
        info["why"] = f"{len(logs)} training run(s): a turn-on needs at least {MIN_RUNS} power-ons to be told from drift"
    elif spread < MIN_START_SPREAD:
        info["why"] = (f"the power-ons of the training runs span {100 * spread:.0f} % of the calibrated range (< "
                       f"{100 * MIN_START_SPREAD:g} %): a turn-on learned at one temperature cannot be told from the "
                       f"self-heating's temperature-dependent bias; record one run from a power-on soaked at each end "
                       f"of the range to learn it")
    elif not taus:
        info["why"] = f"the shortest run is shorter than {TAU_GRID_S[0] / MAX_TAU_FRACTION:g} s"
    info["start_spread"] = round(spread, 4)
    if "why" in info:
        model.fit["turn_on"] = info
        return model, res
    poly = poly_terms(model)

    def fit_with(train, decay):
        """(model, FitResult) fitted on ``train``: the poly terms, k7 = the model's generators
        (``kept``, weights kept) plus ``decay`` at the weight least squares gives it beside them."""
        terms = [dict(decay, weight=1.0)]
        if kept:
            r = decay_weight(train, replace(cfg, aux=AuxConfig.from_terms(kept, cfg.rate.fs)), poly, decay)
            terms = kept + [dict(decay, weight=r)]
            total = sum(abs(t["weight"]) for t in terms)
            terms = [dict(t, weight=t["weight"] / total) for t in terms]
        return refit(train, replace(cfg, aux=AuxConfig.from_terms(terms, cfg.rate.fs)), tuple(poly) + (K_AUX,))

    from host_tools.golden.regressors import generator_values
    outputs = _outputs(logs, model)
    rows, best = [], None
    for tau in taus:
        w = window_of(tau)
        decay = effect_term("decay_on", "turn_on", tau_s=tau)
        sc = _fold_scores(outputs, [generator_values(log, decay, cfg.rate.fs) for log in logs], w)
        start, whole = [x[0] for x in sc], [x[1] for x in sc]
        ok = max(start) <= 1.0 - MARGIN and max(whole) <= RUN_TOLERANCE
        rows.append({"tau_s": tau, "window_s": w, "start_ratio": [round(x, 4) if np.isfinite(x) else None for x in start],
                     "run_ratio": [round(x, 4) if np.isfinite(x) else None for x in whole], "kept": ok})
        if ok and (best is None or float(np.mean(start)) < best[1]):
            best = (tau, float(np.mean(start)), decay)
    info["candidates"] = rows
    if best is None:
        info["why"] = (f"no time constant lowers the start-window error by {100 * MARGIN:g} % on every held-out "
                       f"power-on without raising the whole run's by more than {100 * (RUN_TOLERANCE - 1):g} %")
        model.fit["turn_on"] = info
        return model, res
    new, new_res = fit_with(logs, best[2])
    for key, value in model.fit.items():
        new.fit.setdefault(key, value)
    info.update(chosen=f"decay_on tau {best[0]:g} s", tau_s=best[0],
                why=f"it lowers the start-window error by >= {100 * MARGIN:g} % on every held-out power-on")
    new.fit["turn_on"] = info
    return new, new_res
