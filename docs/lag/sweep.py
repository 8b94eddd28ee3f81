# Measurement script of docs/ACCURACY.md "Lag-state block" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/sweep.py START END OUT.jsonl; then python docs/lag/analyze.py OUT*.jsonl
"""Per foreign device: base default fit (lag off) and every lag candidate forced; held-out ratios. args: start end out"""
import time, sys, json
import numpy as np
import host_tools.golden.compensate as C
from host_tools.fitting import fit_lag as FL
from host_tools.simulation.sim_foreign import foreign_device
from host_tools.fitting.fit import fit_logs
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.bench.accuracy import damping_change_dph, device_runs, heldout_valid
a, b, outp = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
C.DEFAULT_LAG_BLOCK = "off"
def ratio(m, ho, fl):
    return float(np.std(heldout_valid(m, ho)) / fl)
fo = open(outp, "w")
for seed in range(a, b):
    dev = foreign_device(seed)
    rec = {"seed": seed, "dc": damping_change_dph(dev)}
    for rev in (False, True):
        key = "mr" if rev else "ftr"
        tr, ho, fl = device_runs(dev, rev)
        t = time.time()
        m, r = fit_default([tr])
        if r.cv is None:
            m, r = fit_logs([tr], m.config, None, blocks=True)
        d = {"base": ratio(m, ho, fl), "base_cv": r.cv["cv_rms"], "t_base": time.time() - t}
        t = time.time()
        sc = FL.screen([tr], m)
        d["t_screen"] = time.time() - t
        d["screen_base"] = sc["base"]
        rows = sc["rows"]
        singles = [x for x in rows if len(x["cand"]) == 1]
        pairs = sorted([x for x in rows if len(x["cand"]) == 2], key=lambda x: x["screen_cv_rms"])[:6]
        d["cands"] = []
        for x in singles + pairs:
            e = {"block": x["block"], "screen": x["screen_cv_rms"]}
            cfg2 = FL.lag_config(m.config, x["cand"], sc["coefs"](x["cand"]), sc["sensor"])
            if cfg2 is None:
                e["err"] = "too many terms"
            else:
                try:
                    t = time.time()
                    m2, r2 = fit_logs([tr], cfg2, None, blocks=True, drop_unidentifiable=True)
                    e["t"] = time.time() - t
                    e["cv"] = r2.cv["cv_rms"]; e["ratio"] = ratio(m2, ho, fl); e["k7"] = 7 in m2.terms
                except ValueError as exc:
                    e["err"] = str(exc)[:100]
            d["cands"].append(e)
        rec[key] = d
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(seed, "done", flush=True)
