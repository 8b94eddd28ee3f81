"""Error statistics and the confirmation rule of the closed loop (host_tools.fitting.diagnose, steps 5-6 of
its module doc): :func:`error_stats` (std / peak-to-peak of 1-s and 100-s averages of the
compensated output, rms with the mean, per leg; deg/h), THE held-out error of a step
(:func:`step_errors`, :data:`HELDOUT_METRIC`: the one function the loop confirms a step by and
host_tools.bench.loop scores it by), :func:`confirmed_on_holdout` (:data:`CONFIRM_RULE`),
:func:`material_on_holdout` (:data:`EFFECT_RULE`: when a confirmed effect step is named as an
effect) and
:func:`noise_floor`."""
from __future__ import annotations

import math

import numpy as np

from host_tools.fitting import metrics
from host_tools.golden.compensate import compensate, prepare, residual, starts_at_power_on
from host_tools.golden.flags import problems
from host_tools.golden.model import BiasModel


REPORT_TAUS = (1.0, 100.0)
CONFIRM_MIN_DROP = 0.05      # a confirmed step lowers the held-out error by >= 5 % ...
CONFIRM_TOL_1S = 0.01        # ... and raises the held-out 1-s std by at most 1 %
CONFIRM_TOL_RMS = 0.05      # ... and raises no held-out run's leg rms (mean offsets included) by more than 5 %
CONFIRM_TOL_SERVED = 0.005  # ... and lowers no held-out run's served share (valid outputs / samples) by more than 0.5 % of the samples
CONFIRM_TOL_START = 0.02    # ... and, where held-out runs start at a power-on, raises neither start-up figure by more than 2 %
RMS_MIN_SAMPLES = 10         # a leg (gap-free segment) needs this many valid samples to count
CONFIRM_RULE = ("a step is confirmed iff, on the held-out runs, the std of 100-s averages (1-s where "
                "100 s is undefined) drops by >= 5 %, the std of 1-s averages rises by at most 1 % and, per "
                "held-out run, the leg rms (quadratic mean over its gap-free segments of each segment's rms, "
                "mean offset included) rises by at most 5 %; where held-out runs start at a power-on and last "
                "45 min, neither start-up figure (the start window's stability, 1 sigma of 100-s means 180 s .. "
                "45 min, and the 0-5 min repeatability, rms over those runs) rises by more than 2 % and more than "
                "0.1 x its white-noise level, and no held-out run's output serves a share of its samples lower by more "
                "than 0.005; an unconfirmed step is reverted and its family "
                "not offered again (a periodic step: the periods within a factor 2^(1/2) of its period)")
EFFECT_MIN_DROP = 0.18       # an effect is NAMED ("effect found") only when its step lowers the held-out error >= 18 %
EFFECT_RULE = ("a confirmed step of kind 'effect' names an effect (verdict \"effect found\") only when it lowers the "
               f"held-out error by >= {100 * EFFECT_MIN_DROP:.0f} % (material); a confirmed effect step with a smaller drop stays in the "
               "model and is reported as minor (\"material\": false; verdict \"minor improvement confirmed\" when "
               "nothing else held): on clean devices such steps pick up slow features of the device that one "
               "training run cannot tell from an undeclared effect (docs/LOOP.md: chosen on the loop bench's seeds 0 "
               "and 1, checked on seed 2)")


# ---------------------------------------------------------------------------------------------
# error statistics
# ---------------------------------------------------------------------------------------------

STAT_KEYS = ("std_dph", "pp_dph", "std100_dph", "pp100_dph", "rms_dph", "start_std_dph", "start_rep_dph",
             "served_share")
START_KEYS = ("start_std_dph", "start_rep_dph")   # the start-up figures (runs from a power-on, >= 45 min)


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


def stats_one(y, t, valid) -> dict:
    """STAT_KEYS of one output: std / pp of 1-s and 100-s averages, rms with the mean [deg/h]."""
    m = metrics.bias_metrics(y, t, valid, taus=REPORT_TAUS)
    r1, r100 = metrics.at_tau(m, 1.0), metrics.at_tau(m, 100.0)
    ok = np.asarray(valid, bool) & np.isfinite(y)
    return {"std_dph": r1["stability_dph"], "pp_dph": r1["variation_dph"],
            "std100_dph": r100["stability_dph"], "pp100_dph": r100["variation_dph"],
            "rms_dph": float(np.sqrt(np.mean(np.asarray(y)[ok] ** 2))) if ok.any() else None}


def _mean_stats(rows) -> dict:
    """STAT_KEYS over the runs' rows: the mean over runs; ``start_std_dph`` the mean of the runs'
    start-window stabilities, ``start_rep_dph`` the rms of their 0-5 min means (the repeatability
    of start-ups); None where no run has the figure."""
    out = {}
    for key in STAT_KEYS:
        src = "start_turn_on_dph" if key == "start_rep_dph" else key
        vals = [r[src] for r in rows if r.get(src) is not None]
        if key == "start_rep_dph":
            out[key] = float(np.sqrt(np.mean(np.square(vals)))) if vals else None
        else:
            out[key] = float(np.mean(vals)) if vals else None
    return out


def error_stats(logs, model: BiasModel, other: BiasModel | None = None) -> dict:
    """The error of ``model`` on ``logs``: the compensated output (host_tools.golden.compensate) judged
    by host_tools.fitting.metrics: ``std_dph``/``pp_dph`` (1 sigma / peak-to-peak of 1-s averages) and
    ``std100_dph``/``pp100_dph`` (100-s averages), deg/h, mean over the logs (None where no log
    supports that tau); ``served_share`` the share of the samples the output serves; the start-up
    figures ``start_std_dph``/``start_rep_dph`` over the logs that are start-ups (:func:`start_stats`);
    ``runs`` holds the per-run values.  With ``other``, only the samples
    valid under both models count (a longer rate warm-up must not win by hiding samples)."""
    rows = []
    for log in logs:
        out = compensate(log, model)
        valid = np.asarray(out["valid"]) == 1
        served = _served(valid)
        if other is not None:
            valid &= np.asarray(compensate(log, other)["valid"]) == 1
        rows.append(_run_row(log, out, valid, model.config.proxy, served))
    return {**_mean_stats(rows), "runs": rows}


def _served(valid) -> float:
    """The share of a run's samples that a model's output serves (its own valid flags)."""
    return float(np.mean(valid)) if len(valid) else 0.0


def _run_row(log, out, valid, proxy, served) -> dict:
    """One run's row of :func:`error_stats`: ``out`` (compensated ``log``) judged on ``valid``;
    ``served_share`` the share of the run's samples the model's own output serves; the start-up
    figures where ``log`` is a start-up (:func:`start_stats`, ``proxy`` the model's ProxyConfig)."""
    return {"run": log.source, "served_share": served, **stats_one(out.rate_dph, log.t_s, valid),
            **start_stats(log, out.rate_dph, valid, proxy),
            "rms_legs_dph": leg_rms(out.rate_dph, valid, log.segments), "problems": problems(out)}


START_STILL = 0.1    # a start-up: the proxy moves over less than this share of the calibrated range in its first 45 min


def start_stats(log, y, valid, proxy) -> dict:
    """The start-up figures of one run's output ``y`` [deg/h] (host_tools.fitting.metrics.start_figures):
    ``start_std_dph`` (the stability of 100-s means from 180 s to 45 min after power-on, less the
    40-45 min mean) and ``start_turn_on_dph`` (the 0-5 min mean less the same), for a START-UP:
    a run recorded from its power-on (host_tools.fitting.turn_on.starts_at_power_on) over at least
    45 min at a constant ambient, i.e. whose proxy moves over less than START_STILL of the
    calibrated range (``proxy``: the model's ProxyConfig, 2 x span) in those 45 min (a chamber
    run's first 45 min judge its temperature compensation, which the other figures do); None
    otherwise."""
    none = {"start_std_dph": None, "start_turn_on_dph": None}
    if not starts_at_power_on(log) or proxy.column not in log:
        return none
    t = np.asarray(log.t_s, np.float64) - float(log.t_s[0])
    first = (t < metrics.START_LATE_S[1]) & (np.asarray(log.mode) != 3)
    p = np.asarray(log[proxy.column], np.float64)[first]
    p = p[np.isfinite(p)]
    if not len(p) or float(np.ptp(p)) > START_STILL * 2.0 * proxy.span:
        return none
    f = metrics.start_figures(log.t_s, y, valid, end_s=metrics.START_LATE_S[1])
    if not (np.isfinite(f["stability"]) and np.isfinite(f["turn_on"])):
        return none
    return {"start_std_dph": f["stability"], "start_turn_on_dph": f["turn_on"]}


def residuals(logs, model):
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
    for log, (pr, r) in zip(logs, residuals(logs, model)):
        a = metrics.allan(r, log.t_s, pr.valid)
        if a["adev_1s_dph"] is not None:
            vals.append(a["adev_1s_dph"])
    if not vals:
        return {"std_dph": None, "std100_dph": None, "method": "no 1-s Allan tau"}
    w = float(np.mean(vals))
    return {"std_dph": w, "std100_dph": w / 10.0,
            "method": "white noise: Allan deviation of the residual at 1 s; / sqrt(100) at 100 s"}


def heldout_score(stats):
    """(primary, 1-s) error of error_stats: the std of 100-s averages where defined, else of 1-s."""
    return (stats["std100_dph"] if stats["std100_dph"] is not None else stats["std_dph"]), stats["std_dph"]


HELDOUT_METRIC = ("held-out error: std of 100-s averages of the compensated output (1-s where 100 s is "
                  "undefined) [deg/h], mean over the held-out runs; two models are compared on the samples "
                  "valid under both")


def step_errors(logs, before: BiasModel, after: BiasModel) -> tuple:
    """THE held-out error of a step (:data:`HELDOUT_METRIC`), used both to confirm a step here and
    by host_tools.bench.loop to score it: ``(stats_before, stats_after)`` of :func:`error_stats` on
    ``logs``, each restricted to the samples valid under BOTH models (a longer rate warm-up or
    settle window must not win or lose by hiding samples); ``heldout_score(stats)[0]`` is the number."""
    rows_b, rows_a = [], []
    for log in logs:      # each model compensated once per run (error_stats(logs, a, b) twice would do it twice)
        out_b, out_a = compensate(log, before), compensate(log, after)
        valid_b, valid_a = np.asarray(out_b["valid"]) == 1, np.asarray(out_a["valid"]) == 1
        both, proxy = valid_b & valid_a, before.config.proxy     # one start-up test for both models
        rows_b.append(_run_row(log, out_b, both, proxy, _served(valid_b)))
        rows_a.append(_run_row(log, out_a, both, proxy, _served(valid_a)))
    return {**_mean_stats(rows_b), "runs": rows_b}, {**_mean_stats(rows_a), "runs": rows_a}


ON_HELD_OUT, LEAVING_ONE_OUT = "on held-out", "leaving one training run out"


def confirmation(train, hold) -> str | None:
    """How a step is confirmed: ON_HELD_OUT with held-out runs, LEAVING_ONE_OUT with none and
    several training runs (:func:`step_errors_leaving_runs_out`), None with neither (not confirmed)."""
    return ON_HELD_OUT if hold else LEAVING_ONE_OUT if len(train) >= 2 else None


def step_errors_leaving_runs_out(train, before_fit, after_fit) -> tuple:
    """:func:`step_errors` with no held-out runs, by leaving one training run out: for each run,
    ``before_fit(others)`` and ``after_fit(others)`` (callables: training runs -> BiasModel) fitted
    on the other runs and judged on it; pooled (:func:`pooled_step_errors`)."""
    pairs = []
    for i, log in enumerate(train):
        others = [lg for j, lg in enumerate(train) if j != i]
        pairs.append(step_errors([log], before_fit(others), after_fit(others)))
    return pooled_step_errors(pairs)


def pooled_step_errors(pairs) -> tuple:
    """(before, after) of several :func:`step_errors` results (one per held-out fold), their run
    rows pooled as those of held-out runs."""
    rows_b = [r for b, _ in pairs for r in b["runs"]]
    rows_a = [r for _, a in pairs for r in a["runs"]]
    return {**_mean_stats(rows_b), "runs": rows_b}, {**_mean_stats(rows_a), "runs": rows_a}


def confirmed_on_holdout(before, after) -> bool:
    """CONFIRM_RULE: the held-out std of 100-s averages (1-s where 100 s is undefined) drops by at
    least CONFIRM_MIN_DROP, the held-out std of 1-s averages does not rise by more than
    CONFIRM_TOL_1S (relative) and no held-out run or leg has its rms, mean offset included, raised
    by more than CONFIRM_TOL_RMS (:func:`offsets_hold`)."""
    p0, s0 = heldout_score(before)
    p1, s1 = heldout_score(after)
    if p0 is None or p1 is None:
        return False
    return bool(p1 <= p0 * (1.0 - CONFIRM_MIN_DROP)
                and (s0 is None or s1 is None or s1 <= s0 * (1.0 + CONFIRM_TOL_1S))
                and offsets_hold(before, after)
                and not worse_figures(before, after, START_KEYS + ("served_share",), CONFIRM_TOL_START))


START_NOISE_SHARE = 0.1    # a start-up figure is worse only when it also rises by > this x its white-noise level
# the white-noise level of a start-up figure, as a multiple of the output's std of 1-s averages:
# a 100-s mean (the start window's stability) and the 120-s mean over 180..300 s (the repeatability)
START_NOISE = {"start_std_dph": 1.0 / math.sqrt(100.0), "start_rep_dph": 1.0 / math.sqrt(120.0)}


def worse_figures(before, after, keys, tol: float) -> list:
    """The figures of ``keys`` (error_stats keys) that ``after`` raises by more than ``tol``
    (relative) over ``before``: [(key, before, after)]; a figure either side lacks is not compared.
    The start-up figures (START_KEYS) are compared per run too (``runs`` in the same order: each
    power-on's start window and |0-5 min mean|; key ``<key> (<run>)``): a step that serves the
    chamber runs better must not serve a start-up at room temperature worse.  A start-up figure
    of one power-on moves with the noise of a few 100-s means, so it counts as raised only when
    it also rises by more than START_NOISE_SHARE x its white-noise level (START_NOISE x the std of
    1-s averages of ``before``'s run, an upper bound on the white noise)."""
    out = []

    def check(k, b, a, std1, name=None):
        if b is None or a is None:
            return
        if k == "served_share":      # higher is better: an absolute share of the samples
            bad = a < b - CONFIRM_TOL_SERVED
        else:
            slack = START_NOISE_SHARE * START_NOISE[k] * (std1 or 0.0) if k in START_NOISE else 0.0
            bad = a > b * (1.0 + tol) + slack
        if bad:
            out.append((k if name is None else f"{k} ({name})", b, a))

    for k in keys:
        check(k, before.get(k), after.get(k), before.get("std_dph"))
    for rb, ra in zip(before.get("runs", []), after.get("runs", [])):
        for k, src in (("start_std_dph", "start_std_dph"), ("start_rep_dph", "start_turn_on_dph"),
                       ("served_share", "served_share")):
            if k in keys and rb.get(src) is not None and ra.get(src) is not None:
                check(k, abs(rb[src]), abs(ra[src]), rb.get("std_dph"), rb.get("run"))
    return out


def material_on_holdout(before, after) -> bool:
    """EFFECT_RULE: the held-out error (``heldout_score(...)[0]``) drops by at least EFFECT_MIN_DROP."""
    p0, p1 = heldout_score(before)[0], heldout_score(after)[0]
    return bool(p0 is not None and p1 is not None and p1 <= p0 * (1.0 - EFFECT_MIN_DROP))


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


def clean_stats(stats) -> dict:
    return {k: stats[k] for k in STAT_KEYS}


def step_metric(cb, ca) -> dict:
    """The step's held-out error (:data:`HELDOUT_METRIC`, :func:`step_errors`) before / after [deg/h]."""
    return {"before": heldout_score(cb)[0], "after": heldout_score(ca)[0], "metric": HELDOUT_METRIC}


def fmt_value(x, prec=4) -> str:
    """A number for the report and the console: ``prec`` significant digits, "n/a" for None."""
    return "n/a" if x is None else f"{x:.{prec}g}"
