# Measurement script of docs/ACCURACY.md "Lag-state block" and "Rate and lag selection" (not part of the
# package). Prints the rate chosen; variants of host_tools.golden.compensate (C.NAME=VALUE) and fit_lag (NAME=VALUE).
"""Measured FTR data (tests/data): fit on one leg / half, hold out the other; std at 1 s of the
compensated held-out output [deg/h] of the default fit (host_tools.fitting.fit_pipeline.fit_default) with the
lag-state block off and on (host_tools.golden.compensate.DEFAULT_LAG_BLOCK), and the block chosen.
Usage: PYTHONPATH=. python docs/lag/measured.py [NAME=VALUE ...]  (host_tools.fitting.fit_lag constants)"""
import os
import time
import warnings

import sys

import numpy as np

import host_tools.golden.compensate as C
import host_tools.fitting.fit_lag as FL
from host_tools.fitting import metrics
from host_tools.golden import runlog as rl
from host_tools.fitting.fit_pipeline import fit_default

warnings.simplefilter("ignore")
D = os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data")


def std1(y, t, v):
    return metrics.at_tau(metrics.bias_metrics(y, t, v, taus=(1.0,)), 1.0)["stability_dph"]


for kv in sys.argv[1:]:        # e.g. 'LAG_MARGIN={"ftr": 0.05, "mr": 0.1}' LAG_PAIRS_FTR=False: a variant of the module constants
    k, v = kv.split("=")
    mod, k = (C, k[2:]) if k.startswith("C.") else (FL, k)
    setattr(mod, k, eval(v))
cases = []
for ax in "xy":
    log = rl.read(os.path.join(D, f"tofupilot-imu-thermal/tofupilot-imu-{ax}.csv"))
    k = int(np.argmin(log["temp_c"]))
    a, b = log.select(np.arange(k)), log.select(np.arange(k, len(log)))
    cases += [(f"tofu-{ax} cool->heat", a, b), (f"tofu-{ax} heat->cool", b, a)]
    log = rl.read(os.path.join(D, f"psim-tvac-lsm6dsm/psim-tvac-{ax}.csv"))
    h = len(log) // 2
    a, b = log.select(np.arange(h)), log.select(np.arange(h, len(log)))
    cases += [(f"psim-{ax} 1st->2nd", a, b), (f"psim-{ax} 2nd->1st", b, a)]
print("| case | raw | default, lag off | default, lag auto | block chosen | fit s off / on |")
print("|---|---|---|---|---|---|")
for name, tr, ho in cases:
    row, times, chosen = [std1(ho.rate_dph, ho.t_s, np.ones(len(ho), bool))], [], ""
    for mode in ("off", "auto"):
        C.DEFAULT_LAG_BLOCK = mode
        t0 = time.time()
        try:
            model, _ = fit_default([tr], proxy_margin=0.5, rate_margin=0.5)
            times.append(time.time() - t0)
            out = C.compensate(ho, model)
            row.append(std1(out.rate_dph, ho.t_s, out["valid"] > 0))
            if mode == "auto":
                chosen = (model.fit.get("lag_block", {}).get("chosen") or "none") + "; rate " + (
                    model.fit.get("rate_selection", {}).get("chosen") or model.config.rate.estimator)
        except ValueError as exc:
            row.append(float("nan"))
            chosen = f"error: {exc}"[:60]
    print(f"| {name} | " + " | ".join(f"{x:.1f}" for x in row) + f" | {chosen} | "
          + " / ".join(f"{x:.1f}" for x in times) + " |", flush=True)
