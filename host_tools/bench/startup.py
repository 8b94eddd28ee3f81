"""`hdrg bench startup`: the output from power-on at constant ambient (the paper's Table 4) on
random FOREIGN devices (host_tools.simulation.sim_foreign), calibrated as a lab would.

Per device (seed ``S * 100000 + i``; every device has the foreign family's turn-on, ``turn_on``:
parasitic-charge settling that no thermometer sees, beside its self-heating):

* **calibrate** with ``hdrg fit``'s defaults (host_tools.fitting.fit_pipeline.fit_default) on
  :func:`calibration_runs`, each from its own power-on: two mode-reversal chamber runs (TRAIN_RUNS:
  one soaked at the warm end of the range, one at the cold end) and two 45-min start-ups at
  constant ambient (a lab's room on two days, TRAIN_STARTUPS: degC above the middle of the range):
  the protocol that lets the fit tell a turn-on from the self-heating's temperature-dependent
  bias, and hold one room start-up out while the other teaches it (host_tools.fitting.turn_on);
* **start-ups**: STARTUPS power-ons (indices 2, 3, ...) at constant ambient, each STARTUP_S (45
  min) long, the ambient drawn inside the calibrated range (:func:`ambient_of`);
* **pipelines**: mode reversal alone (the default combiner on the raw output, no model), the
  calibrated model (float golden model), and the noise floor (the same start-up with
  ``thermal=False``, mode reversal alone);
* **figures** (:func:`startup_figures`, the paper's Table 4 columns): from power-on + 180 s (the
  first mode-reversal output) to the end, the output less its mean over LATE_S (40..45 min):
  stability = std (1 sigma) of the 100-s means (bins from 180 s on; a bin with valid samples on
  less than START_MIN_BIN_SHARE of its span, e.g. the last 20 s, is left out), variation = their peak-to-peak, mean = the mean
  over the served samples; **turn-on** = the mean over the served part of the first 5 min
  (180..300 s); repeatability = the rms of the turn-on over the device's start-ups (how far
  the first minutes sit from the settled bias, power-on after power-on); valid share = valid
  outputs / servable samples (host_tools.bench.accuracy.servable).

Summary: per pipeline the median over devices of the per-device median stability (and variation,
|mean|, the paper's third column), the median of
the per-device ratio model / mode reversal alone, the median repeatability, the lowest valid
share, how many devices' models learned the turn-on (model.fit["turn_on"]), and for how many
`hdrg fit` warned that, held out, it serves a calibration power-on worse than mode reversal alone
(host_tools.fitting.turn_on.start_up_check; per device ``start_up_warning``).
"""
from __future__ import annotations

import time

import numpy as np

from host_tools.bench.accuracy import SEED_STRIDE, servable
from host_tools.bench.loop import LOOP_TOLERANCE
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.fitting.metrics import (START_BIN_S, START_FIRST_S, START_LATE_S, START_TURN_ON_S,
                                       start_figures)
from host_tools.golden.compensate import compensate
from host_tools.golden.reversal import DEFAULT_COMBINER, combine
from host_tools.simulation.sim_foreign import STARTUP_S, foreign_device, simulate_foreign

# the calibration runs: (chamber rate [degC/min], power-on index, power-on at the cold end): one
# power-on at each end of the range, so that a turn-on that depends on the temperature is told
# from one that does not (host_tools.fitting.turn_on: MIN_START_SPREAD)
TRAIN_RUNS = ((4.0, 0, False), (2.0, 1, True))
# plus 45-min power-ons at constant ambient: (degC above the range's middle, power-on index; the
# evaluated start-ups are 2, 3, ...): a lab's room on two days
TRAIN_STARTUPS = ((8.0, 99), (9.5, 98))
STARTUPS = 4                        # start-ups per device (the paper's four data sets)
FIRST_OUTPUT_S = START_FIRST_S     # the first mode-reversal output after power-on [s]
TURN_ON_S = START_TURN_ON_S         # the turn-on window ends 5 min after power-on [s]
LATE_S = START_LATE_S               # the offset baseline: the mean over 40..45 min [s]
BIN_S = START_BIN_S                 # averaging of the stability [s]
EFFECT = "turn_on"
PIPELINES = ("mode reversal alone", "hdrg fit defaults", "noise floor")
LOOP = "hdrg diagnose defaults"      # the closed loop's final model (optional: about 10 s per device)


def ambient_of(dev, power_on: int) -> float:
    """The ambient [degC] of start-up ``power_on``: uniform within 5 degC of the middle of the
    device's chamber range (inside what its calibration runs cover)."""
    mid = 0.5 * (dev.chamber["high_c"] + dev.chamber["low_c"])
    return float(mid + np.random.default_rng([dev.seed, 5, power_on]).uniform(-5.0, 5.0))


def calibration_runs(dev, effect: str | None = EFFECT) -> list:
    """The calibration runs of ``dev`` (a ForeignDevice): TRAIN_RUNS, then the TRAIN_STARTUPS
    start-ups of STARTUP_S at constant ambient; every one from its own power-on."""
    runs = [simulate_foreign(dev, rate, True, p, p, effect=effect, start_low=cold) for rate, p, cold in TRAIN_RUNS]
    mid = 0.5 * (dev.chamber["high_c"] + dev.chamber["low_c"])
    runs += [simulate_foreign(dev, 1.0, True, p, p, effect=effect, ambient_c=mid + above) for above, p in TRAIN_STARTUPS]
    return runs


def startup_figures(t_s, out, valid) -> dict:
    """Table 4 figures [deg/h] of one start-up's output ``out`` at its ``valid`` samples
    (host_tools.fitting.metrics.start_figures: the module doc's windows)."""
    return start_figures(t_s, out, valid)


def _mr_alone(log):
    c = combine(log, DEFAULT_COMBINER)
    return c.out_dph, np.asarray(c.valid, bool)


def evaluate_device(seed: int, startups: int = STARTUPS, effect: str | None = EFFECT, loop: bool = False) -> dict:
    """One device (module doc): {'seed', 'turn_on' (the device's), 'model_turn_on' (what the fit
    learned), 'startups': [{'ambient_c', pipeline: figures + 'valid_share'}], 'error'}.  ``effect``
    None: the control, a device without a turn-on (what the fit learns there is a false discovery);
    ``loop``: also the closed loop's model (host_tools.fitting.diagnose.diagnose, defaults, on the
    calibration runs)."""
    dev = foreign_device(seed)
    rec = {"seed": seed, "turn_on": dev.effects.get(EFFECT) if effect else None, "startups": [], "error": ""}
    train = calibration_runs(dev, effect)
    try:
        model, _ = fit_default(train)
    except (ValueError, np.linalg.LinAlgError) as exc:
        rec["error"] = f"{type(exc).__name__}: {exc}"
        return rec
    rec["model_turn_on"] = (model.fit.get("turn_on") or {}).get("chosen")
    rec["model_turn_on_why"] = (model.fit.get("turn_on") or {}).get("why")
    rec["model_terms"] = len(model.terms)
    rec["start_up_warning"] = bool(((model.fit.get("turn_on") or {}).get("start_up_check") or {}).get("worse"))
    loop_model = None
    if loop:
        from host_tools.fitting.diagnose import diagnose
        report, loop_model = diagnose(train, plots=False)
        rec["loop_steps"] = [e["effect"] for e in loop_model.fit.get("diagnose", {}).get("effects", [])]
        rec["loop_verdict"] = report.get("verdict")
    for k in range(startups):
        p = len(TRAIN_RUNS) + k
        amb = ambient_of(dev, p)
        log = simulate_foreign(dev, 1.0, True, p, p, effect=effect, ambient_c=amb)
        floor = simulate_foreign(dev, 1.0, True, p, p, effect=effect, ambient_c=amb, thermal=False)
        serve = servable(log)
        row = {"ambient_c": amb}
        res = compensate(log, model)
        outs = {PIPELINES[0]: _mr_alone(log), PIPELINES[1]: (res.rate_dph, np.asarray(res["valid"]) > 0),
                PIPELINES[2]: _mr_alone(floor)}
        if loop_model is not None:
            lres = compensate(log, loop_model)
            outs[LOOP] = (lres.rate_dph, np.asarray(lres["valid"]) > 0)
        for name, (out, valid) in outs.items():
            row[name] = {**startup_figures(log.t_s, out, valid & serve),
                         "valid_share": float((valid & serve).sum() / max(serve.sum(), 1))}
        rec["startups"].append(row)
    return rec


def _device_stat(rec, name, key, how=np.median):
    vals = np.array([s[name][key] for s in rec["startups"]], float)
    return float(how(vals)) if vals.size else float("nan")


def _rms(x):
    return np.sqrt(np.mean(np.square(x)))


def summarize(records) -> dict:
    """Per pipeline: median over devices of the per-device median stability, variation and
    repeatability (rms of the turn-on over start-ups), the lowest valid share; the median of the
    per-device ratio of stabilities (model / mode reversal alone); devices whose model learned the
    turn-on; failed devices."""
    ok = [r for r in records if not r["error"]]
    out = {"devices": len(records), "failed": len(records) - len(ok),
           "learned_turn_on": sum(1 for r in ok if r.get("model_turn_on")),
           "start_up_warnings": sum(1 for r in ok if r.get("start_up_warning"))}
    names = PIPELINES + ((LOOP,) if ok and all(LOOP in s for r in ok for s in r["startups"]) else ())
    for name in names:
        stab = np.array([_device_stat(r, name, "stability") for r in ok])
        out[name] = {"stability_dph": float(np.nanmedian(stab)) if ok else float("nan"),
                     "variation_dph": float(np.nanmedian([_device_stat(r, name, "variation") for r in ok])) if ok else float("nan"),
                     "mean_abs_dph": float(np.nanmedian([_device_stat(r, name, "mean", lambda x: np.median(np.abs(x)))
                                                         for r in ok])) if ok else float("nan"),
                     "repeatability_dph": float(np.nanmedian([_device_stat(r, name, "turn_on", _rms) for r in ok])) if ok else float("nan"),
                     "min_valid_share": min((s[name]["valid_share"] for r in ok for s in r["startups"]), default=float("nan"))}
    ratio = [_device_stat(r, PIPELINES[1], "stability") / _device_stat(r, PIPELINES[0], "stability") for r in ok]
    out["ratio_model_to_mr_alone"] = float(np.nanmedian(ratio)) if ok else float("nan")
    if LOOP in names:
        out["ratio_loop_to_mr_alone"] = float(np.nanmedian(
            [_device_stat(r, LOOP, "stability") / _device_stat(r, PIPELINES[0], "stability") for r in ok]))
        for r in ok:
            r["loop_vs_fit"] = loop_vs_fit(r)
        out["loop_worse_than_fit"] = [r["seed"] for r in ok if r["loop_vs_fit"]["worse"]]
        out["loop_vs_fit_max"] = {k: float(np.nanmax([r["loop_vs_fit"][k] for r in ok])) for k in ("stability", "repeatability")}
        out["loop_min_valid_share_vs_fit"] = float(min(r["loop_vs_fit"]["valid_share"] for r in ok))
    return out


def loop_vs_fit(rec) -> dict:
    """One device's loop against hdrg fit: the ratios loop / fit of its stability (median over
    start-ups) and repeatability (rms of the 0-5 min means), the ratio of their lowest valid
    shares, and ``worse`` when either ratio exceeds LOOP_TOLERANCE."""
    ratios = {"stability": _device_stat(rec, LOOP, "stability") / _device_stat(rec, PIPELINES[1], "stability"),
              "repeatability": _device_stat(rec, LOOP, "turn_on", _rms) / _device_stat(rec, PIPELINES[1], "turn_on", _rms),
              "valid_share": _device_stat(rec, LOOP, "valid_share", np.min) / max(_device_stat(rec, PIPELINES[1], "valid_share", np.min), 1e-12)}
    ratios["worse"] = bool(ratios["stability"] > LOOP_TOLERANCE or ratios["repeatability"] > LOOP_TOLERANCE)
    return ratios


def run_benchmark(n_devices: int = 20, seed: int = 0, startups: int = STARTUPS, progress=None, start: int = 0,
                  effect: str | None = EFFECT, loop: bool = False) -> dict:
    """The benchmark (module doc) on devices ``start`` .. ``start + n_devices - 1`` of set ``seed``;
    ``effect`` None: the control (no turn-on)."""
    for what, v, lo in (("--devices", n_devices, 1), ("--seed", seed, 0), ("--startups", startups, 2), ("--start", start, 0)):
        if not (isinstance(v, int) and not isinstance(v, bool) and v >= lo):
            raise ValueError(f"{what} must be an integer >= {lo}, not {v!r}")
    t0 = time.time()
    records = []
    for i in range(n_devices):
        records.append(evaluate_device(seed * SEED_STRIDE + start + i, startups, effect, loop))
        if progress:
            progress(f"device {i + 1}/{n_devices} ({time.time() - t0:.0f} s)")
    config = {"devices": n_devices, "start": start, "seed": seed, "startups": startups, "startup_s": STARTUP_S,
              "train_runs": [{"rate_c_per_min": r, "power_on": p, "cold_start": c} for r, p, c in TRAIN_RUNS]
              + [{"ambient_above_middle_c": a, "power_on": p} for a, p in TRAIN_STARTUPS], "effect": effect, "loop": loop,
              "elapsed_s": round(time.time() - t0, 1)}
    return {"config": config, "records": records, "summary": summarize(records)}


def format_table(result: dict) -> str:
    """The summary as a text table (deg/h)."""
    s = result["summary"]
    c = result["config"]
    lines = [f"Start-up at constant ambient: {s['devices']} foreign devices (set {c['seed']}, "
             f"{'with their turn-on' if c['effect'] else 'control: no turn-on'}), {c['startups']} "
             f"power-ons of {c['startup_s'] / 60:.0f} min each, calibrated on {len(TRAIN_RUNS)} chamber runs and "
             f"{len(TRAIN_STARTUPS)} room start-ups "
             f"with hdrg fit's defaults; from power-on + {FIRST_OUTPUT_S:g} s, less the {LATE_S[0] / 60:.0f}-"
             f"{LATE_S[1] / 60:.0f} min mean", "",
             f"{'pipeline':22s} {'stability':>10s} {'p-p':>8s} {'|mean|':>8s} {'0-5 min rms':>12s} {'min valid':>10s}",
             f"{'':22s} {'1 sigma':>10s} {'100-s':>8s} {'':>8s} {'repeatab.':>12s} {'share':>10s}"]
    for name in [n for n in PIPELINES + (LOOP,) if n in s]:
        r = s[name]
        lines.append(f"{name:22s} {r['stability_dph']:10.3f} {r['variation_dph']:8.3f} {r['mean_abs_dph']:8.3f} "
                     f"{r['repeatability_dph']:12.3f} "
                     f"{100 * r['min_valid_share']:9.1f}%")
    lines += ["", f"median ratio of stabilities, model / mode reversal alone: {s['ratio_model_to_mr_alone']:.2f}"
              + (f"; loop / mode reversal alone: {s['ratio_loop_to_mr_alone']:.2f}" if "ratio_loop_to_mr_alone" in s else ""),
              f"models that learned the turn-on: {s['learned_turn_on']} of {s['devices'] - s['failed']}; "
              f"hdrg fit warned of a held-out start-up worse than mode reversal alone: "
              f"{s.get('start_up_warnings', 0)}; failed devices: {s['failed']}"]
    if "loop_worse_than_fit" in s:
        m = s["loop_vs_fit_max"]
        lines.append(f"loop / hdrg fit per device, worst: stability {m['stability']:.3f}, 0-5 min repeatability "
                     f"{m['repeatability']:.3f}; lowest valid share loop / fit {s['loop_min_valid_share_vs_fit']:.3f}; "
                     f"devices where the loop ends more than {100 * (LOOP_TOLERANCE - 1):.0f} % worse than hdrg fit: "
                     f"{len(s['loop_worse_than_fit'])}" + (f" ({', '.join(map(str, s['loop_worse_than_fit']))})"
                                                           if s["loop_worse_than_fit"] else ""))
    return "\n".join(lines)
