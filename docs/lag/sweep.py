# Measurement script of docs/ACCURACY.md "Lag-state block" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/sweep.py START END OUT.jsonl; then python docs/lag/analyze.py OUT*.jsonl
"""Per foreign device: base default fit (lag off) and every lag candidate forced; held-out ratios. args: start end out"""
import time, sys, json
import host_tools.golden.compensate as C
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import fit_logs
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.bench.accuracy import heldout_ratio, set_devices
a, b, outp = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
C.DEFAULT_LAG_BLOCK = "off"
fo = open(outp, "w")
for rec, cases in set_devices(range(a, b)):
    for key, tr, ho, fl in cases:
        t = time.time()
        m, r = fit_default([tr])
        if r.cv is None:
            m, r = fit_logs([tr], m.config, None, blocks=True)
        d = {"base": heldout_ratio(m, ho, fl), "base_cv": r.cv["cv_rms"], "t_base": time.time() - t}
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
                    e["cv"] = r2.cv["cv_rms"]; e["ratio"] = heldout_ratio(m2, ho, fl); e["k7"] = 7 in m2.terms
                except ValueError as exc:
                    e["err"] = str(exc)[:100]
            d["cands"].append(e)
        rec[key] = d
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
