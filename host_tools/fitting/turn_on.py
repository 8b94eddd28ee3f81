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
* **what the chip does with it**: a candidate enters a model's k7 (:func:`with_decay`), and its
  **response** (:func:`responses`) is the change of the compensated output of every run (float
  golden model, through the combiner and the coefficient banks).  The output is linear in the
  term's size, so the response at size 1 is all that is needed;
* **the fit with the term** (:func:`_with_term`): the size by weighted least squares of the
  response on the base model's outputs (each run's own offset free), each run weighted by
  1 / the mean square of its 100-s means with the term at the size that run alone gives it
  (:func:`_run_weights`: a chamber run whose soaked ends the polynomial fits worse counts less
  than a start-up at constant ambient that the term explains); then the base's terms refitted on
  the runs with that turn-on taken out (:func:`without_term`).  The size is not traded in the
  refit, and the refit lets go of what the polynomial's ends and lag states had absorbed of the
  turn-on at a chamber run's soaked start (kept, it would count the turn-on twice there);
* **scored by leaving one power-on out**: the fit with the term on the other runs against the
  base refitted on them, on the held-out run: the error over the first :func:`window_of` seconds
  after power-on (WINDOW_TAUS x tau, MIN_WINDOW_S .. START_WINDOW_S) as the spread of its BIN_S
  means about their own mean (the start's shape: a chamber run's soaked start sits at a level the
  polynomial learns from that run alone, which the term must not be judged by), and over the
  whole run (sum of squares of BIN_S means).  A held-out run with fewer than MIN_BINS means to
  score, or a fold that cannot be fitted, fails the candidate;
* **kept** when the start windows' error ratio, averaged over the held-out runs with the run
  weights (in-sample: each run's misfit with the term at its own size, so a run the term
  explains counts more), is at most 1 - MARGIN, no held-out power-on's start window gets worse
  (START_TOLERANCE: power-ons at other temperatures veto a self-heating bias of one ambient), the
  whole runs' weighted ratio is at most RUN_TOLERANCE, and the size is at least MIN_SIZE_T times
  its standard error (:func:`_size_stderr`).  Of several, the one of least weighted error ratio
  over the first START_WINDOW_S (one window for every tau).  The model shipped is the fit with
  the term on all runs, as scored.  When the base's generators fill the chip's AUX_MAX_TERMS, the
  sign-twin terms of a mode-reversal lag block make room (each coefficient bank keeps its own
  k7), and the base is refitted without them first.  model.fit["turn_on"]: the candidates'
  scores and run weights, the choice, its size at power-on per coefficient bank (``amp_dph``:
  k7_b x the term's weight, deg/h; beside generators whose k7 differs between the banks, the
  term enters each bank in that proportion, which the response and so the scoring include).

Held out, the same folds also say what a user would see at start-up (:func:`start_up_check`):
each mode-reversal run's first 45 min under the model refitted on the other runs (its terms as
chosen on all runs), against mode reversal alone; only when the term is tried (above);
model.fit["turn_on"]["start_up_check"], and `hdrg fit` warns for a run served WORSE_THAN_REVERSAL x
worse.

Why the run weights and the shape of the start: every power-on of a calibration shows the
turn-on, but a chamber run that starts soaked at an end of the range also shows that end's
self-heating transient, which only that run teaches the polynomial; scored by its level or
weighted by its misfit without the term, the chamber runs vetoed true turn-ons and pulled the
size toward what the polynomial had absorbed (`hdrg bench startup`, set 0: median start-up error
0.39 x mode reversal alone, 0-5 min repeatability 0.35 deg/h; docs/ACCURACY.md "Start-up" for the
numbers now).

Measured by `hdrg bench startup` (host_tools.bench.startup; docs/ACCURACY.md "Start-up").
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from firmware_ref.formats import AUX_MAX_TERMS
from firmware_ref.terms import K_AUX
from host_tools.golden.compensate import starts_at_power_on  # noqa: F401  (re-exported: the fit's rule)

TAU_GRID_S = (60.0, 85.0, 120.0, 170.0, 240.0, 340.0, 480.0, 680.0, 960.0, 1360.0, 1920.0)   # candidate time constants [s], ratio 2^(1/2)
MAX_TAU_FRACTION = 0.36     # tau <= this x the shortest training run: 45-min power-ons reach tau 960 s, and 6 % of
                            # the decay is left at the shortest run's end (the loop's turn_on family keeps its own
                            # 0.25 x the longest run: host_tools.fitting.effects)
START_WINDOW_S = 2700.0     # scored window after each power-on [s]: the paper's 45-min start-up
MARGIN = 0.2                # the held-out start windows' error (run-weighted mean) must fall by this fraction ...
START_TOLERANCE = 1.0       # ... and no held-out power-on's start window may get worse
MIN_RUNS = 2
WINDOW_TAUS = 3.0           # scored window after power-on: this many time constants ...
MIN_WINDOW_S = 600.0        # ... at least this long, at most START_WINDOW_S [s]
RUN_TOLERANCE = 1.05        # the held-out whole runs' error (run-weighted mean) may not rise by more than this factor
MIN_SIZE_T = 5.0            # the size fitted on all runs: at least this many standard errors (100-s means); chosen
                            # on `hdrg bench startup --seed 1` (turn-ons 7.0 and up, the control's one 2.9)


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


def window_of(tau_s: float) -> float:
    """The window after power-on [s] on which a candidate of time constant ``tau_s`` is scored."""
    return float(min(START_WINDOW_S, max(MIN_WINDOW_S, WINDOW_TAUS * tau_s)))


BIN_S = 100.0               # scored: means over this many seconds (the stability metric's averaging)


MIN_BINS = 3                # a held-out run is scored only with this many BIN_S means in the window


def _bin_means(t, x, window_s=None) -> np.ndarray:
    """The BIN_S-s means of ``x`` [deg/h] at times ``t`` [s since power-on], over the first
    ``window_s`` [s] (None: all), of the bins that hold samples."""
    b = (np.asarray(t) // BIN_S).astype(np.int64)
    if window_s is not None:
        keep = np.asarray(t) < window_s
        b, x = b[keep], np.asarray(x)[keep]
    cnt = np.bincount(b)
    return np.bincount(b, weights=x)[cnt > 0] / cnt[cnt > 0]


def _binned_sq(out, t, valid, window_s=None, shape=False) -> float:
    """Sum of squares of the BIN_S-s means of ``out`` [deg/h] over the valid samples (the run's
    mean removed), over the first ``window_s`` [s] after power-on (None: the whole run); ``shape``:
    of the means less their own mean (the start's decay, not its level); NaN with fewer than
    MIN_BINS means (nothing to score)."""
    t = np.asarray(t, np.float64) - float(t[0])
    ok = np.asarray(valid, bool) & np.isfinite(out)
    if ok.sum() < 2:
        return float("nan")
    x = np.asarray(out, np.float64)[ok]
    m = _bin_means(t[ok], x - float(np.mean(x)), window_s)
    if len(m) < MIN_BINS:
        return float("nan")
    if shape:
        m = m - m.mean()
    return float(m @ m)


def _ratio(after: float, before: float) -> float:
    """after / before; +inf (a failed fold) when either is not a finite score or before is 0."""
    return after / before if np.isfinite(after) and np.isfinite(before) and before > 0 else float("inf")


def _outputs(logs, compensated) -> list:
    """Per run: (t [s since power-on], compensated output less its mean [deg/h], valid) of the
    ``compensated`` results (host_tools.golden.compensate.compensate of each run)."""
    out = []
    for log, res in zip(logs, compensated):
        ok = (np.asarray(res["valid"]) > 0) & np.isfinite(res.rate_dph)
        y = np.where(ok, res.rate_dph, 0.0)
        if ok.any():
            y = np.where(ok, y - y[ok].mean(), 0.0)
        out.append((np.asarray(log.t_s, np.float64) - float(log.t_s[0]), y, ok))
    return out


def _centred(g, ok) -> np.ndarray:
    """The response ``g`` less its mean over the valid samples ``ok`` (each run's offset is free)."""
    return np.where(ok, g - (g[ok].mean() if ok.any() else 0.0), 0.0)


def _run_weights(outputs, g_runs) -> list:
    """Per run: 1 / the mean square of its BIN_S means with the term of response ``g_runs`` at the
    size that run alone gives it (least squares): how far the model plus a turn-on of that time
    constant is from explaining the run.  A chamber run whose extremes the polynomial fits worse
    counts less in the term's size (weighted least squares) than a start-up at constant ambient that
    the term explains; weights from the misfit WITHOUT the term would instead make the clearest
    turn-ons weigh least.  0 for a run with nothing to score."""
    out = []
    for (t, y, ok), g in zip(outputs, g_runs):
        gc = _centred(g, ok)
        den = float(gc @ gc)
        m = _bin_means(t[ok], (y - (float(gc @ y) / den if den > 0 else 0.0) * gc)[ok])
        ms = float(m @ m) / len(m) if len(m) else 0.0
        out.append(1.0 / ms if ms > 0 else 0.0)
    return out


def _size_of(outputs, g_runs, weights) -> float:
    """The term's size [deg/h at power-on] by weighted least squares over the runs (``weights``,
    :func:`_run_weights`; each run's offset free): the output's change is size x response."""
    num = den = 0.0
    for (t, y, ok), g, wt in zip(outputs, g_runs, weights):
        gc = _centred(g, ok)
        num, den = num + wt * float(gc @ y), den + wt * float(gc @ gc)
    return -(num / den) if den > 0 else 0.0


def _with_term(logs, base, decay, refit, compensated) -> tuple:
    """The fit with the term of ``decay``'s time constant, on ``logs``: its size by weighted least
    squares on ``base``'s outputs (``compensated``: ``base`` on ``logs``); then ``base``'s terms
    refitted (``refit``) on the runs with that turn-on taken out (:func:`without_term`), so that no
    polynomial end or lag state keeps the part of the turn-on it absorbed at a chamber run's soaked
    start, and the term added at that size.  (model, FitResult of the refit, the refitted base,
    size, its standard error)."""
    outputs = _outputs(logs, compensated)
    resp = responses(logs, base, decay, compensated)
    weights = _run_weights(outputs, resp)
    size = _size_of(outputs, resp, weights)
    fs = base.config.rate.fs
    refitted, res = refit([without_term(log, decay, size, fs) for log in logs], base.config, base.terms)
    return (with_decay(refitted, decay, size), res, refitted, size, _size_stderr(outputs, resp, weights, size),
            weights)


def _both_served(a, b) -> np.ndarray:
    """The samples where both compensated results ``a`` and ``b`` give a valid, finite output."""
    return (np.asarray(a["valid"]) > 0) & (np.asarray(b["valid"]) > 0) & np.isfinite(a.rate_dph) & np.isfinite(b.rate_dph)


def _held_out_ratios(log, before, after, windows) -> tuple:
    """Error ratios on the held-out run ``log``, the model with the term ``after`` to the one
    without it (``before``: its results on ``log``): over the first ``w`` [s] after power-on for each
    w of ``windows``, then over the whole run (sums of squares of BIN_S means, on the samples both
    serve)."""
    from host_tools.golden.compensate import compensate

    a, b = before, compensate(log, after)
    ok = _both_served(a, b)
    t = np.asarray(log.t_s, np.float64)
    return tuple(_ratio(_binned_sq(b.rate_dph, t, ok, w, shape=w is not None), _binned_sq(a.rate_dph, t, ok, w, shape=w is not None))
                 for w in (*windows, None))


def _wmean(ratios, weights) -> float:
    """The mean of the held-out runs' error ``ratios`` weighted by the runs' ``weights``
    (:func:`_run_weights`); +inf when a fold failed."""
    w = np.asarray(weights, np.float64)
    r = np.asarray(ratios, np.float64)
    return float(np.sum(w * r) / np.sum(w)) if np.all(np.isfinite(r)) and np.sum(w) > 0 else float("inf")


FAILED = (float("inf"),) * 3   # a fold that cannot be fitted or scored


def _cv_ratios(logs, folds, decay, refit, windows) -> tuple:
    """Per held-out run i: :func:`_held_out_ratios` of the fit with the term on the OTHER runs
    (:func:`_with_term`, its size and its refit alike) against ``folds[i]`` = (the base refitted on
    the other runs, its results on them, its results on run i; None: it could not be fitted), or
    FAILED; and those fits (None where FAILED)."""
    out, models = [], []
    for i, fold in enumerate(folds):
        others = [log for j, log in enumerate(logs) if j != i]
        model = None
        if fold is not None:
            try:
                model = _with_term(others, fold[0], decay, refit, fold[1])[0]
                out.append(_held_out_ratios(logs[i], fold[2], model, windows))
            except (ValueError, np.linalg.LinAlgError):
                model = None
        if model is None:
            out.append(FAILED)
        models.append(model)
    return out, models


WORSE_THAN_REVERSAL = 1.2   # a held-out power-on that the model serves this much worse than mode reversal alone is named


def start_up_check(logs, models) -> dict:
    """What a user would see at start-up, held out: for each mode-reversal run of ``logs``, its
    first START_WINDOW_S after power-on compensated by ``models[i]`` (the model refitted on the
    OTHER runs, its terms as chosen on all runs; None: none could be fitted) against mode reversal alone (the default combiner on the raw
    output), on the samples both serve: the ratio of the std of their BIN_S means.  A chamber-
    calibrated model can be worse than reversal alone at a power-on at constant ambient (rate terms
    learned from chamber ramps meet the self-heating's gradients).  A run with fewer than MIN_BINS
    means served, or that cannot be compensated, is left out.  {'window_s', 'threshold', 'runs':
    [{'source', 'ratio'}], 'worse': [sources of ratio >= WORSE_THAN_REVERSAL]}."""
    from host_tools.golden.compensate import compensate
    from host_tools.golden.reversal import DEFAULT_COMBINER, combine

    rows = []
    for log, model in zip(logs, models):
        if model is None or not log.reversal:
            continue
        try:
            res, mr = compensate(log, model), combine(log, DEFAULT_COMBINER)
        except ValueError:
            continue
        ok = (np.asarray(res["valid"]) > 0) & np.asarray(mr.valid, bool) & np.isfinite(res.rate_dph) & np.isfinite(mr.out_dph)
        t = np.asarray(log.t_s, np.float64) - float(log.t_s[0])
        means = [_bin_means(t[ok], np.asarray(y)[ok], START_WINDOW_S) for y in (res.rate_dph, mr.out_dph)]
        if len(means[0]) < MIN_BINS:
            continue                 # too little served to judge
        spread = [float(np.std(m, ddof=1)) for m in means]
        if spread[1] > 0:
            rows.append({"source": log.source, "ratio": round(spread[0] / spread[1], 3)})
    return {"window_s": START_WINDOW_S, "threshold": WORSE_THAN_REVERSAL, "runs": rows,
            "worse": [r["source"] for r in rows if r["ratio"] >= WORSE_THAN_REVERSAL]}


def decay_terms_needed(model) -> int:
    """How many k7 terms :func:`with_decay` adds to ``model``: 1, or 2 beside generators whose k7
    differs between the two coefficient banks of a regress_first model (the decay and its sign
    twin, so that it enters both banks alike)."""
    banks = np.array(model.banks, np.float64)[:, K_AUX]
    gens = K_AUX in model.terms and model.config.aux.terms
    return 1 if not gens or len(banks) == 1 or np.isclose(banks[0], banks[1], rtol=1e-9) else 2


def with_decay(model, decay, scale: float):
    """``model`` (a BiasModel) with the ``decay`` term (a ``decay_on`` generator term) added to k7
    so that it adds ``scale`` x g [deg/h] to the bias of every coefficient bank (a turn-on flips
    like the rate, so the targets s x rate of both banks hold it alike):

    * without generators in k7: the decay is k7's only term (weight 1), every bank's k7 = scale;
    * beside generators (weights w_j, bank coefficients k7_b): one bank, or k7_1 = k7_2: the
      decay's weight is scale / k7; two banks with k7_1 != k7_2: the decay with weight
      scale (1/k7_1 + 1/k7_2) / 2 and its sign twin (``sign`` True: + in mode 1, - in mode 2) with
      weight scale (1/k7_1 - 1/k7_2) / 2.  When sum |w| then exceeds 1, all weights are divided
      by it and every k7_b multiplied by it (the other terms' part of the bias unchanged).

    The compensated output is linear in ``scale``: out(scale) = out(0) + scale x the response
    (:func:`responses`).  ValueError when a bank's k7 is 0 beside generators, or when k7 would hold
    more than AUX_MAX_TERMS terms."""
    from host_tools.golden.model import BiasModel
    from host_tools.golden.regressors import AuxConfig

    cfg = model.config
    gens = list(cfg.aux.terms) if K_AUX in model.terms else []
    banks = np.array(model.banks, np.float64)
    k7 = banks[:, K_AUX]
    if not gens:
        terms, banks[:, K_AUX] = [dict(decay, weight=1.0)], scale
    else:
        if np.any(k7 == 0.0):
            raise ValueError("a coefficient bank's k7 is 0: a decay cannot share k7 with its generators")
        if decay_terms_needed(model) == 1:
            added = [dict(decay, weight=scale / float(k7[0]))]
        else:
            inv = 1.0 / k7
            added = [dict(decay, weight=0.5 * scale * float(inv[0] + inv[1])),
                     dict(decay, sign=True, weight=0.5 * scale * float(inv[0] - inv[1]))]
        terms = gens + added
        if len(terms) > AUX_MAX_TERMS:
            raise ValueError(f"k7 would hold {len(terms)} generator terms (the chip's limit is {AUX_MAX_TERMS})")
        total = sum(abs(t["weight"]) for t in terms)
        if total > 1.0:
            terms = [dict(t, weight=t["weight"] / total) for t in terms]
            banks[:, K_AUX] *= total
    return BiasModel(replace(cfg, aux=AuxConfig.from_terms(terms, cfg.rate.fs)),
                     tuple(sorted(set(model.terms) | {K_AUX})), banks[0], dict(model.fit), model.source,
                     banks[1] if len(banks) > 1 else None)


def without_decay(model, decay):
    """``model`` with the ``decay`` term (and its sign twin) that :func:`with_decay` put in k7 taken
    out again: the other generators keep their weights and every bank its k7, so their part of
    the bias is unchanged (k7 leaves the terms when nothing else is in it).  Compensating a log
    with the result equals compensating it with ``model`` once the term's size is taken out of
    the log (:func:`without_term`)."""
    from host_tools.golden.model import BiasModel
    from host_tools.golden.regressors import AuxConfig

    cfg = model.config
    key = {k: v for k, v in decay.items() if k not in ("weight", "sign")}
    keep = [t for t in cfg.aux.terms if {k: v for k, v in t.items() if k in key} != key or t.get("gen") != "decay_on"]
    banks = np.array(model.banks, np.float64)
    terms = tuple(model.terms)
    if keep:
        aux = AuxConfig.from_terms(keep, cfg.rate.fs)
    else:
        aux, terms = AuxConfig(), tuple(k for k in model.terms if k != K_AUX)
        banks[:, K_AUX] = 0.0
    return BiasModel(replace(cfg, aux=aux), terms, banks[0], dict(model.fit), model.source,
                     banks[1] if len(banks) > 1 else None)


def decay_size(model, tau_s: float) -> list:
    """Per coefficient bank: what the ``decay_on`` terms of time constant ``tau_s`` in ``model``'s
    k7 add to the bias at power-on (g = 1) [deg/h]: k7_b x sum_j w_j (x -1 in bank 2 for a sign twin)."""
    banks = np.array(model.banks, np.float64)[:, K_AUX]
    ds = [t for t in model.config.aux.terms if t.get("gen") == "decay_on" and float(t["tau_s"]) == float(tau_s)]
    return [float(k * sum(t["weight"] * (-1.0 if (b == 1 and t.get("sign")) else 1.0) for t in ds))
            for b, k in enumerate(banks)]


def responses(logs, model, decay, compensated=None) -> list:
    """Per run: the change of the compensated output [deg/h] (float golden model) when ``decay``
    enters ``model`` at scale 1 (:func:`with_decay`), at the samples valid in both (0 elsewhere):
    what the chip's output does with the term, through the combiner and the coefficient banks.
    ``compensated``: ``model``'s results on ``logs`` when the caller has them (None: computed)."""
    from host_tools.golden.compensate import compensate

    probe = with_decay(model, decay, 1.0)
    if compensated is None:
        compensated = [compensate(log, model) for log in logs]
    out = []
    for log, a in zip(logs, compensated):
        b = compensate(log, probe)
        ok = _both_served(a, b)
        out.append(np.where(ok, b.rate_dph - a.rate_dph, 0.0))
    return out


def _size_stderr(outputs, resp, weights, scale: float) -> float:
    """Standard error [deg/h] of the size ``scale`` (:func:`_size_of`), from the BIN_S means of
    every run (weighted as in the fit of the size; fewer correlated errors than the samples, still
    optimistic for drift): sqrt(sum w |Y + scale R|^2 / (bins - 1) / sum w |R|^2)."""
    num = den = 0.0
    bins = 0
    for (t, y, ok), r, wt in zip(outputs, resp, weights):
        if not ok.any():
            continue
        ym, rm = _bin_means(t[ok], y[ok]), _bin_means(t[ok], r[ok] - r[ok].mean())
        num += wt * float(np.sum((ym + scale * rm) ** 2))
        den += wt * float(rm @ rm)
        bins += len(ym)
    return float(np.sqrt(num / max(bins - 1, 1) / den)) if den > 0 else float("inf")


def without_term(log, decay, size: float, fs: float):
    """``log`` with what the ``decay`` term (a ``decay_on`` generator term) at ``size`` [deg/h] adds
    to the bias of every coefficient bank taken out of its rate: size x g, times the mode sign s on
    a mode-reversal log (the term flips like the rate; a bank's target is s x rate).  Compensating
    it with a model equals compensating ``log`` with that model plus the term (:func:`with_decay`)
    on every valid sample (s = 0 only in exchanges)."""
    from host_tools.golden.regressors import generator_values, mode_sign

    g = size * generator_values(log, decay, fs)
    rate = np.asarray(log.rate_dph, np.float64)
    return log.with_columns(rate_dph=rate - (mode_sign(log.mode) * g if log.reversal else g))


def chosen_term(model):
    """(the ``decay_on`` term, its scale [deg/h at power-on]) that :func:`add_turn_on` put in
    ``model``, or None when it chose none."""
    from host_tools.fitting.effects import effect_term

    info = model.fit.get("turn_on") or {}
    if not info.get("chosen"):
        return None
    return effect_term("decay_on", "turn_on", tau_s=info["tau_s"]), float(info["scale"])


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
    info = {"method": "per time constant: the size by run-weighted least squares on the model's compensated outputs, "
                      "the other coefficients refitted with the turn-on taken out; scored by leaving one power-on "
                      "out, refit included (host_tools.fitting.turn_on)", "margin": MARGIN,
            "start_window_s": START_WINDOW_S, "chosen": None}
    taus = candidate_taus(logs) if len(logs) >= MIN_RUNS else []
    gens = [t for t in cfg.aux.terms if t.get("gen") != "decay_on"]
    late = [log for log in logs if not starts_at_power_on(log)]
    spread = start_spread(logs, cfg.proxy) if len(logs) >= MIN_RUNS and not late else 0.0
    # beside the turn-on, k7 keeps the model's generators; when the chip's AUX_MAX_TERMS cannot
    # also hold the decay (with its sign twin: decay_terms_needed), the sign-twin terms of a
    # mode-reversal lag block go (each bank keeps its own k7)
    kept = (gens if len(gens) + decay_terms_needed(model) <= AUX_MAX_TERMS
            else [t for t in gens if not t.get("sign")])
    if len(gens) < len(cfg.aux.terms) and K_AUX in model.terms:
        info["why"] = "k7 already holds a decay since power-on"
    elif len(kept) + (1 if not kept or model.coef_mode2 is None else 2) > AUX_MAX_TERMS:
        info["why"] = f"k7 already holds {len(gens)} generator terms (the chip's limit is {AUX_MAX_TERMS})"
    elif late:
        info["why"] = (f"{late[0].source} does not start at its power-on (first t_s {float(late[0].t_s[0]):g} s; t_s is "
                       f"the time since power-on): a turn-on is learned only from runs recorded from their power-on")
    elif len(logs) < MIN_RUNS:
        info["why"] = f"{len(logs)} training run(s): a turn-on needs at least {MIN_RUNS} power-ons to be told from drift"
    elif spread < MIN_START_SPREAD:
        info["why"] = (f"the power-ons of the training runs span {100 * spread:.0f} % of the calibrated range (< "
                       f"{100 * MIN_START_SPREAD:g} %): a turn-on learned at one temperature cannot be told from the "
                       f"self-heating's temperature-dependent bias")
    elif not taus:
        info["why"] = f"the shortest run is shorter than {TAU_GRID_S[0] / MAX_TAU_FRACTION:g} s"
    info["start_spread"] = round(spread, 4)
    if "why" in info:
        model.fit["turn_on"] = info
        return model, res
    base, base_res = model, res
    if len(kept) < len(gens):    # the chip's k7 is full: the sign twins go, and the rest is refitted without them
        base, base_res = refit(logs, replace(cfg, aux=AuxConfig.from_terms(kept, cfg.rate.fs)),
                               tuple(poly_terms(model)) + (K_AUX,))
        for key, value in model.fit.items():
            base.fit.setdefault(key, value)
    k7 = np.array(base.banks, np.float64)[:, K_AUX]
    if K_AUX in base.terms and base.config.aux.terms and np.any(k7 == 0.0):
        info["why"] = "a coefficient bank's k7 is 0 beside the model's generators: a decay cannot share k7 with them"
        model.fit["turn_on"] = info
        return model, res
    from host_tools.golden.compensate import compensate

    compensated = [compensate(log, base) for log in logs]      # once: every candidate's response is against it
    folds = []           # per held-out run: the base refitted on the others, its results there and on the run
    for i in range(len(logs)):
        others = [log for j, log in enumerate(logs) if j != i]
        fold = _refit_or_none(refit, others, base)
        folds.append(None if fold is None else (fold, [compensate(log, fold) for log in others], compensate(logs[i], fold)))
    rows, best = [], None
    for tau in taus:
        w = window_of(tau)
        decay = effect_term("decay_on", "turn_on", tau_s=tau)
        try:
            fitted = _with_term(logs, base, decay, refit, compensated)
        except (ValueError, np.linalg.LinAlgError) as exc:
            rows.append({"tau_s": tau, "window_s": w, "kept": False, "error": str(exc)})
            continue
        sc, fold_models = _cv_ratios(logs, folds, decay, refit, (w, START_WINDOW_S))
        start, whole = [x[0] for x in sc], [x[2] for x in sc]
        scale, se, weights = fitted[3], fitted[4], fitted[5]
        size_t = abs(scale) / se if se > 0 else 0.0
        ok = (_wmean(start, weights) <= 1.0 - MARGIN and max(start) <= START_TOLERANCE
              and _wmean(whole, weights) <= RUN_TOLERANCE and size_t >= MIN_SIZE_T)
        rows.append({"tau_s": tau, "window_s": w, "start_ratio": [round(x, 4) if np.isfinite(x) else None for x in start],
                     "run_ratio": [round(x, 4) if np.isfinite(x) else None for x in whole],
                     "run_weight": [round(x / max(weights), 4) for x in weights] if max(weights) > 0 else None,
                     "size_t": round(size_t, 2), "kept": ok})
        rank = _wmean([x[1] for x in sc], weights)       # START_WINDOW_S: one window for every tau
        if ok and (best is None or rank < best[1]):
            best = (tau, rank, decay, fitted, fold_models)
    info["candidates"] = rows
    if best is not None:
        checked = best[4]
    elif base is model:
        checked = [f and f[0] for f in folds]
    else:                            # the model ships as it was (its generators' sign twins included)
        checked = [_refit_or_none(refit, [log for j, log in enumerate(logs) if j != i], model) for i in range(len(logs))]
    info["start_up_check"] = start_up_check(logs, checked)
    if best is None:
        info["why"] = (f"no time constant lowers the held-out start windows' error by {100 * MARGIN:g} % (run-weighted) "
                       f"without raising any held-out power-on's, or the whole runs' error by more than "
                       f"{100 * (RUN_TOLERANCE - 1):g} %, with a size at least {MIN_SIZE_T:g} x its standard error")
        model.fit["turn_on"] = info
        return model, res
    new, new_res, refitted, scale, se, _ = best[3]
    info["size_stderr_dph"] = se if np.isfinite(se) else None
    for key, value in base.fit.items():   # the term selection's cross-validation and choices; the refit's own
        if key in SELECTION_KEYS or key not in new.fit:     # coefficients, offsets and residuals stay
            new.fit[key] = value
    sizes = decay_size(new, best[0])
    size = (f"{sizes[0]:+.3g}" if len(sizes) == 1 or np.isclose(sizes[0], sizes[1], rtol=0.01)
            else f"{sizes[0]:+.3g} (mode 1) / {sizes[1]:+.3g} (mode 2)")
    info.update(chosen=f"decay_on tau {best[0]:g} s, {size} deg/h at power-on", tau_s=best[0],
                scale=scale, amp_dph=sizes,
                why=f"held out, it lowers the start windows' error by >= {100 * MARGIN:g} % (run-weighted), "
                    f"no power-on's start gets worse")
    new.fit["turn_on"] = info
    res = _result_of(new_res, refitted, new, se)
    return new, (res if res is None or base_res is None else replace(res, cv=base_res.cv))


SELECTION_KEYS = ("cv", "requested", "insignificant")   # model.fit keys of the term selection, kept from the base


def _refit_or_none(refit, logs, model):
    """``model``'s terms refitted on ``logs`` (``refit``), or None when they cannot be fitted."""
    try:
        return refit(logs, model.config, model.terms)[0]
    except (ValueError, np.linalg.LinAlgError):
        return None


def _result_of(res, base, model, size_stderr: float):
    """``res`` (the FitResult of ``base``, the refit on the runs with the turn-on taken out) with
    ``model``'s terms and coefficients.  k7's standard error: without generators beside the decay,
    the size's (:func:`_size_stderr`, deg/h); beside them, the base's k7 error scaled as k7 was by
    the renormalization of the weights.  The caller keeps the term selection's cross-validation."""
    if res is None:
        return None
    k0 = np.array(base.banks, np.float64)[:, K_AUX]
    k1 = np.array(model.banks, np.float64)[:, K_AUX]
    err = [None if e is None else np.array(e, np.float64) for e in (res.stderr, res.stderr_mode2)]
    gens = K_AUX in base.terms and bool(base.config.aux.terms)
    for b, e in enumerate(err):
        if e is not None:
            e[K_AUX] = e[K_AUX] * abs(k1[b] / k0[b]) if gens else size_stderr
    return replace(res, coef=np.array(model.coef, np.float64), terms=tuple(model.terms), stderr=err[0],
                   coef_mode2=None if model.coef_mode2 is None else np.array(model.coef_mode2, np.float64),
                   stderr_mode2=err[1])
