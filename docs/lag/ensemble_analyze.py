# Replays docs/lag/ensemble.py records (not part of the package).
# Usage: python docs/lag/ensemble_analyze.py A.jsonl [B.jsonl ...]
import json, sys, numpy as np
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
for key in ("mr", "ftr"):
    cols = {}
    for r in recs:
        if key + "_mean" not in r: continue
        cols.setdefault("default", []).append(r[key + "_default"])
        cols.setdefault("default_common", []).append(r[key + "_default_common"])
        cols.setdefault("mean5", []).append(r[key + "_mean"])
        cols.setdefault("medoid", []).append(r[key + "_medoid_r"])
        cr = r[key + "_common_r"]
        cols.setdefault("oracle", []).append(min(cr))
        for i, e in enumerate(r[key]):
            cols.setdefault(e["est"], []).append(cr[i])
        # cv-best
        cv = [e["cv"] for e in r[key]]
        cols.setdefault("leastcv", []).append(cr[int(np.argmin(cv))])
    n = len(cols["default"])
    base = np.array(cols["default_common"])
    print(key, n)
    for k, v in cols.items():
        v = np.array(v)
        print(f"  {k:16s} med {np.median(v):.2f} p90 {np.percentile(v,90):.2f} >1.5 {np.sum(v>1.5):2d} gm {np.exp(np.mean(np.log(v/base))):.3f} better {np.sum(v<0.9*base)} worse {np.sum(v>1.1*base)}")
