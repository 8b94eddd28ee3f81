# Analysis of docs/lag/rate_sweep.py output: rate-selection rules replayed offline.
import json, sys
import numpy as np
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
print(len(recs), "devices")
f = lambda a: "%.2f / %.2f" % (np.median(a), np.percentile(a, 90))
dc = np.array([r["dc"] > 0.5 for r in recs])
for kind in ("ftr", "mr"):
    print("==", kind)
    labels = [e["est"] for e in recs[0][kind]]
    for lab in labels:
        for col in ("r_own", "r_own_lag", "r_com", "r_com_lag"):
            a = np.array([next(e for e in r[kind] if e["est"] == lab).get(col, np.nan) for r in recs])
            print(f"  fixed {lab:14s} {col:10s} {f(a)}  dc {np.median(a[dc]):.2f}")
    for score in ("cv_own", "cv_com"):
        for col in ("r_own", "r_own_lag", "r_com", "r_com_lag"):
            for margin in (0.0, 0.05, 0.1):
                out, picks = [], []
                for r in recs:
                    ok = [e for e in r[kind] if score in e]
                    best = min(ok, key=lambda e: e[score])
                    # parsimony: prefer the first candidate (diff) unless beaten by margin
                    first = ok[0]
                    pick = best if best[score] < (1 - margin) * first[score] else first
                    out.append(pick[col]); picks.append(pick["est"])
                out = np.array(out)
                print(f"  pick by {score} margin {margin:.2f} -> {col:10s} {f(out)} dc {np.median(out[dc]):.2f}  picks",
                      {p: picks.count(p) for p in sorted(set(picks))})
    orc = np.array([min(e.get("r_own_lag", 1e9) for e in r[kind]) for r in recs])
    print("  oracle r_own_lag", f(orc))
