# Replays selection rules over docs/lag/band_cv.py records (not part of the package).
# Usage: python docs/lag/band_cv_analyze.py A.jsonl [B.jsonl ...]
import json, sys
import numpy as np

recs = [json.loads(line) for f in sys.argv[1:] for line in open(f)]
recs = [r for r in recs if all("err" not in e for e in r["mr"])]
PREF = "iir shift=9"


def pick_pref(rows, key, margin):
    p = next(e for e in rows if e["est"] == PREF)
    best = min(rows, key=lambda e: e[key])
    return best if best[key] < (1 - margin) * p[key] else p


def rules():
    yield "default (prefer iir 9, CV margin 0.5)", lambda rows: pick_pref(rows, "cv", 0.5)["r"]
    yield "least time-block CV", lambda rows: min(rows, key=lambda e: e["cv"])["r"]
    yield "least band CV", lambda rows: min(rows, key=lambda e: e["band"])["r"]
    for m in (0.1, 0.2, 0.3):
        yield f"prefer iir 9, band-CV margin {m}", lambda rows, m=m: pick_pref(rows, "band", m)["r"]
    yield "default rate, lag block kept only if band CV agrees", \
        lambda rows: (lambda e: e["r"] if e["band"] <= e["band0"] else e["r0"])(pick_pref(rows, "cv", 0.5))
    yield "oracle (best held-out candidate)", lambda rows: min(e["r"] for e in rows)


base = np.array([pick_pref(r["mr"], "cv", 0.5)["r"] for r in recs])
print(f"{len(recs)} devices; held-out std / floor: median / p90 / devices > 1.5; geometric mean vs default; better / worse by > 10 %")
for name, f in rules():
    v = np.array([f(r["mr"]) for r in recs])
    print(f"| {name} | {np.median(v):.2f} / {np.percentile(v, 90):.2f} / {np.sum(v > 1.5)} | "
          f"{np.exp(np.mean(np.log(v / base))):.3f} | {np.sum(v < base / 1.1)} / {np.sum(v > base * 1.1)} |")
