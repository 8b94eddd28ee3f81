# Measurement scripts of docs/REGRESS_THEN_REVERSE.md (not part of the package).
import json, sys, itertools
import numpy as np
recs = sum((json.load(open(f)) for f in sys.argv[1:]), [])
keys = sorted({k for r in recs for k in r["r"]})
def stat(vals):
    v = np.array(vals, float); v = v[np.isfinite(v)]
    return (np.median(v), np.percentile(v, 90), len(v)) if len(v) else (np.nan, np.nan, 0)
big = [r for r in recs if r["dchange"] > 0.5]
print(f"{len(recs)} devices, {len(big)} damping-change")
rows = []
for k in keys:
    a = stat([r["r"][k].get("ratio", np.nan) for r in recs])
    b = stat([r["r"][k].get("ratio", np.nan) for r in big])
    rows.append((k, a, b))
for k, a, b in sorted(rows, key=lambda x: x[1][0]):
    print(f"{k:28s} median {a[0]:6.2f} p90 {a[1]:8.2f} n {a[2]:3d} | dchg median {b[0]:6.2f} p90 {b[1]:8.2f}")
# auto: per device pick min cv among candidates of one output kind
def auto(kind, ests, terms):
    out = []
    for r in recs:
        cands = [(r["r"][f"{kind}/{e}/{t}"].get("cv", np.inf), r["r"][f"{kind}/{e}/{t}"].get("ratio", np.nan), e, t)
                 for e in ests for t in terms if f"{kind}/{e}/{t}" in r["r"]]
        cands = [c for c in cands if np.isfinite(c[0])]
        if not cands:
            out.append((np.nan, None)); continue
        best = min(cands)
        out.append((best[1], f"{best[2]}/{best[3]}"))
    return out
ests_all = sorted({k.split("/")[1] for k in keys})
print("AUTO (min CV over time blocks of the training run)")
for kind in sorted({k.split("/")[0] for k in keys}):
    for ests in [ests_all, ["diff", "iir7", "iir9"], ["diff", "iir9"], ["diff", "lsq32", "iir9"]]:
        for terms in [["all"], ["auto"], ["all", "auto"]]:
            res = auto(kind, [e for e in ests if e in ests_all], terms)
            a = stat([x[0] for x in res]); b = stat([x[0] for x, r in zip(res, recs) if r["dchange"] > 0.5])
            print(f"auto {kind:10s} est {','.join(ests):28s} terms {','.join(terms):9s} median {a[0]:6.2f} p90 {a[1]:8.2f} | dchg {b[0]:6.2f} {b[1]:8.2f}")
