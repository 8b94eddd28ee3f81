# Analysis of docs/lag/select_sweep.py output: lag-block selection rules replayed offline.
# Usage: python docs/lag/select_analyze.py OUT*.jsonl
import json, sys
import numpy as np
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
print(len(recs), "devices")
dc = np.array([r["dc"] > 0.5 for r in recs])


def rule(d, scheme="b8", margin=0.2, refit=True, sensor=True, se=None, by_refit=False, top=4, gate=None):
    """(held-out ratio, block) of the rule on one device record."""
    base = np.array(d["screen_base"][scheme])
    c = [x for x in d["cands"] if sensor or not x["sensor"]]
    if not c:
        return d["base"], None
    if by_refit:   # the least refit CV among the refitted candidates (top 4 by the b8 screen)
        base = np.sqrt(sum(d["screen_base"]["b8"]))
        ok = sorted(c, key=lambda x: sum(x["screen"]["b8"]))[:top]
        if gate is not None:
            ok = [x for x in ok if np.sqrt(sum(x["screen"]["b8"])) < (1 - gate) * base]
        if any("cv" not in x and "err" not in x for x in ok):
            return np.nan, "not refitted"
        ok = [x for x in ok if "cv" in x]
        if not ok:
            return d["base"], None
        best = min(ok, key=lambda x: x["cv"])
        if best["cv"] < (1 - margin) * d["base_cv"]:
            return best["ratio"], best["block"]
        return d["base"], None
    best = min(c, key=lambda x: sum(x["screen"][scheme]))
    s = np.array(best["screen"][scheme])
    if se is not None:   # paired per-fold gain must exceed se standard errors
        g = base - s
        ok = g.mean() > se * g.std(ddof=1) / np.sqrt(len(g))
    else:
        ok = np.sqrt(s.sum()) < (1 - margin) * np.sqrt(base.sum())
    if ok and refit:
        if "cv" not in best:
            return np.nan, "not refitted"
        ok = best["cv"] < (1 - margin) * d["base_cv"]
    if ok:
        if "ratio" not in best:
            return np.nan, "not refitted"
        return best["ratio"], best["block"]
    return d["base"], None


def summ(kind, **kw):
    base = np.array([r[kind]["base"] for r in recs])
    out = [rule(r[kind], **kw) for r in recs]
    new = np.array([o[0] for o in out])
    f = lambda a: "%.2f / %.2f" % (np.nanmedian(a), np.nanpercentile(a, 90))
    return (f"{f(new)} dc {np.nanmedian(new[dc]):.2f}/{np.nanpercentile(new[dc], 90):.2f} chosen {sum(o[1] is not None for o in out)}"
            f" worse {np.sum(new > 1.1 * base)} better {np.sum(new < base / 1.1)} nan {np.isnan(new).sum()}")


for kind in ("ftr", "mr"):
    base = np.array([r[kind]["base"] for r in recs])
    print(f"== {kind} base (lag off) {np.median(base):.2f} / {np.percentile(base, 90):.2f}")
    for sensor in (False, True):
        for scheme in ("b4", "b8", "b16", "ph"):
            for margin in (0.1, 0.2, 0.3):
                print(f"  sensor {sensor:d} {scheme:3s} margin {margin:.1f} refit  ", summ(kind, scheme=scheme, margin=margin, sensor=sensor))
            for se in (1.0, 2.0, 3.0):
                print(f"  sensor {sensor:d} {scheme:3s} se {se:.0f}      refit  ", summ(kind, scheme=scheme, se=se, margin=0.0, sensor=sensor))
        for top in (1, 2, 3, 4):
            for gate in (None, 0.0, 0.1, 0.2):
                for margin in (0.1, 0.2, 0.3):
                    print(f"  sensor {sensor:d} top {top} gate {gate} by refit cv margin {margin:.1f}", summ(kind, by_refit=True, margin=margin, sensor=sensor, top=top, gate=gate))
    orc = np.array([min([r[kind]["base"]] + [x["ratio"] for x in r[kind]["cands"] if "ratio" in x]) for r in recs])
    print(f"  oracle among refitted {np.median(orc):.2f} / {np.percentile(orc, 90):.2f}")
