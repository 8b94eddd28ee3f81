# Measurement script of docs/ACCURACY.md "Rate preference" (not part of the package).
# Usage: python docs/lag/rate_prefer_analyze.py A.jsonl [B.jsonl ...]   (rate_prefer_sweep.py output)
"""Replays rate-selection rules offline: held-out std / floor of the chosen candidate's fit with
the lag block (median, p90, devices above 1.5; damping-change subset median), FTR and MR."""
import json, sys
import numpy as np

recs = [json.loads(line) for f in sys.argv[1:] for line in open(f)]
ORIG = ["diff", "diffn n=16", "lsq n=32", "iir shift=7", "iir shift=9"]
MORE = ORIG + ["iir shift=10", "lsq n=128"]


def pick(rows, rule):
    ok = {e["est"]: e for e in rows if "err" not in e}
    kind = rule[0]
    if kind == "fixed":
        return ok.get(rule[1])
    if kind in ("cv", "joint"):           # least CV rms: of the base fit ('cv'), after the lag block ('joint')
        key = "cv" if kind == "cv" else "cv_lag"
        return min((ok[k] for k in rule[1] if k in ok), key=lambda e: e[key])
    _, pref, margin, key, cands = rule   # 'prefer': pref unless the least-CV one beats it by margin
    best = min((ok[k] for k in cands if k in ok), key=lambda e: e[key])
    p = ok.get(pref)
    return best if p is None or best[key] < (1 - margin) * p[key] else p


rules = {"least CV (before)": ("cv", ORIG), "joint (rate x lag)": ("joint", ORIG), "least CV, 7 candidates": ("cv", MORE),
         "joint, 7 candidates": ("joint", MORE)}
rules.update({f"fixed {k}": ("fixed", k) for k in MORE})
for m in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7):
    rules[f"prefer iir 9, margin {m}"] = ("prefer", "iir shift=9", m, "cv", ORIG)
    rules[f"prefer iir 9, joint, margin {m}"] = ("prefer", "iir shift=9", m, "cv_lag", ORIG)
for kind in ("mr", "ftr"):
    print(kind, len(recs), "devices: median / p90 / devices > 1.5 | damping-change median")
    for name, rule in rules.items():
        r = np.array([(pick(x[kind], rule) or {"r_lag": np.nan})["r_lag"] for x in recs])
        dc = np.array([x["dc"] for x in recs]) > 0.5
        print(f"  {name:34s} {np.nanmedian(r):.2f} / {np.nanpercentile(r, 90):.2f} / {int((r > 1.5).sum()):2d}"
              f" | {np.nanmedian(r[dc]):.2f}")
