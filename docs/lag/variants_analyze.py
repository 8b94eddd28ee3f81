# Analysis of docs/lag/variants.py output.
import json, sys
import numpy as np
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
print(len(recs), "devices")
dc = np.array([r["dc"] > 0.5 for r in recs])
for kind in ("ftr", "mr"):
    names = list(recs[0][kind])
    for n in names:
        a = np.array([r[kind][n]["r"] for r in recs]); t = np.array([r[kind][n]["t"] for r in recs])
        nl = sum(r[kind][n]["lag"] is not None for r in recs)
        print(f"{kind} {n:18s} {np.median(a):.2f} / {np.percentile(a, 90):.2f}  dc {np.median(a[dc]) if dc.any() else np.nan:.2f} / {np.percentile(a[dc], 90) if dc.any() else np.nan:.2f}"
              f"  lag chosen {nl}  fit time median {np.median(t):.1f} s")
