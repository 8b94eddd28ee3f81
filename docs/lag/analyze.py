# Analysis of docs/lag/sweep.py output (docs/ACCURACY.md "Lag-state block"): selection rules replayed offline.
import json, sys, numpy as np, itertools
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
print(len(recs), "devices")
def rule(d, allowed, margin, refit_margin=None, screen_only=False):
    rm = margin if refit_margin is None else refit_margin
    c = [x for x in d["cands"] if allowed(x["block"]) and "cv" in x]
    if not c: return d["base"], None
    best = min(c, key=lambda x: x["screen"])
    if best["screen"] < (1 - margin) * d["screen_base"] and (screen_only or best["cv"] < (1 - rm) * d["base_cv"]):
        return best["ratio"], best["block"]
    return d["base"], None
def taus(b):
    import re
    return [float(t) for t in re.findall(r"lag\(u, (\d+) s\)", b)]
def summarize(kind, allowed, margin, **kw):
    base = np.array([r[kind]["base"] for r in recs]); new = np.array([rule(r[kind], allowed, margin, **kw)[0] for r in recs])
    dc = np.array([r["dc"] > 0.5 for r in recs])
    nch = sum(rule(r[kind], allowed, margin, **kw)[1] is not None for r in recs)
    f = lambda a: "%.2f / %.2f" % (np.median(a), np.percentile(a, 90))
    return f"base {f(base)} dc {np.median(base[dc]):.2f} -> new {f(new)} dc {np.median(new[dc]):.2f}  chosen {nch}  worse>10% {np.sum(new > 1.1*base)} better>10% {np.sum(new < base/1.1)}"
for kind in ("ftr", "mr"):
    for name, allowed in (("all", lambda b: True), ("tau>=120", lambda b: min(taus(b)) >= 120), ("tau>=240", lambda b: min(taus(b)) >= 240),
                          ("single", lambda b: len(taus(b)) == 1), ("single tau>=120", lambda b: len(taus(b)) == 1 and min(taus(b)) >= 120),
                          ("order3 only", lambda b: b.count("^1..3") == len(taus(b)))):
        for margin in (0.05, 0.1, 0.2, 0.3):
            print(kind, name.ljust(16), margin, summarize(kind, allowed, margin))
print("--- per device mr/ftr: base, chosen(0.2), oracle")
for r in recs:
    for kind in ("ftr","mr"):
        d = r[kind]; ok=[x for x in d["cands"] if "ratio" in x]
        orc = min(ok, key=lambda x: x["ratio"]) if ok else None
        byc = min(ok, key=lambda x: x["cv"]) if ok else None
        new, blk = rule(d, lambda b: True, 0.2)
        print(r["seed"], kind, "base %.2f new %.2f (%s) oracle %.2f (%s) bycv %.2f (%s, cv %.3f vs base %.3f)" % (d["base"], new, blk, orc["ratio"], orc["block"], byc["ratio"], byc["block"], byc["cv"], d["base_cv"]), "t_base %.1f t_screen %.1f" % (d["t_base"], d["t_screen"]))
print("--- oracle")
for kind in ("ftr","mr"):
    orc = np.array([min([r[kind]["base"]] + [x["ratio"] for x in r[kind]["cands"] if "ratio" in x]) for r in recs])
    print(kind, "oracle %.2f / %.2f" % (np.median(orc), np.percentile(orc, 90)))
