# Measurement scripts of docs/REGRESS_THEN_REVERSE.md (not part of the package).
"""Measured FTR data: fit on one leg/half, hold out the other; std at 1 s of the compensated
held-out output [deg/h] per (estimator, terms).  Also the raw std and a cubic-in-temp baseline."""
import sys, warnings
import numpy as np
from host_tools.golden import runlog as rl
from host_tools.bench.accuracy import ESTIMATORS
from host_tools.golden.compensate import compensate, fit_config_from_logs
from host_tools.fitting.fit import fit_auto_rate, fit_logs
from host_tools.fitting import metrics

warnings.simplefilter("ignore")
D = "/work/shared/data/measured/"
def std1(y, t, v):
    return metrics.at_tau(metrics.bias_metrics(y, t, v, taus=(1.0,)), 1.0)["stability_dph"]

cases = []
for ax in "xy":
    log = rl.read(D + f"tofupilot-imu-thermal/tofupilot-imu-{ax}.csv")
    k = int(np.argmin(log["temp_c"]))
    a, b = log.select(np.arange(k)), log.select(np.arange(k, len(log)))
    cases += [(f"tofu-{ax} cool->heat", a, b), (f"tofu-{ax} heat->cool", b, a)]
    log = rl.read(D + f"psim-tvac-lsm6dsm/psim-tvac-{ax}.csv")
    h = len(log) // 2
    a, b = log.select(np.arange(h)), log.select(np.arange(h, len(log)))
    cases += [(f"psim-{ax} 1st->2nd", a, b), (f"psim-{ax} 2nd->1st", b, a)]
ests = sys.argv[1].split(",")
terms = sys.argv[2].split(";")
print("case".ljust(24), "raw".rjust(8), *[f"{e}/{t}".rjust(14) for e in ests for t in terms])
for name, tr, ho in cases:
    row = [std1(ho.rate_dph, ho.t_s, np.ones(len(ho), bool))]
    for e in ests:
        for t in terms:
            try:
                if e == "auto":   # the rate estimator chosen by cross-validation (host_tools.fitting.fit.fit_auto_rate)
                    model, res = fit_auto_rate([tr], t, proxy_margin=0.5, rate_margin=0.5)
                    print(name, "auto chose", model.fit["rate_selection"]["chosen"], file=sys.stderr)
                else:
                    est, n, sh = ESTIMATORS[e]
                    cfg = fit_config_from_logs([tr], rate_estimator=est, n=n, shift=sh, proxy_margin=0.5, rate_margin=0.5)
                    model, res = fit_logs([tr], cfg, t, drop_unidentifiable=True, blocks=True)
                out = compensate(ho, model)
                v = out["valid"] > 0
                row.append(std1(out.rate_dph, ho.t_s, v))
            except Exception as exc:
                row.append(float("nan")); print(name, e, t, exc, file=sys.stderr)
    print(name.ljust(24), *[f"{x:14.3f}" if i else f"{x:8.3f}" for i, x in enumerate(row)])
