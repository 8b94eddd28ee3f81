"""The materiality threshold of an effect step (diagnose_confirm.EFFECT_MIN_DROP), from loop-bench records.

    python docs/loop/materiality.py docs/loop/bench150_seed1.json [more records ...]

The threshold only labels steps (a confirmed effect step is kept in the model either way), so
the loop's trajectory, and every step's held-out drop, is the same for every threshold: records of
one bench run score all thresholds.  Printed: per clean run the held-out drops of its confirmed
effect steps, per effect run with effect_ratio >= 2 those naming the injected family, and for
each threshold the clean runs that would say "effect found" (false discovery; MR control) and
the effect runs detected by a material effect step."""
import json
import sys

from host_tools.bench.loop import MATTERS_RATIO, _confirmed_effect, _named


def drop(step):
    return 1.0 - step["after"] / step["before"]


def effect_steps(run, named=None):
    return [s for s in run["steps"] if _confirmed_effect(s) and (named is None or _named(named, s["effect"]))]


def main(paths):
    recs = [r for p in paths for r in json.load(open(p, encoding="utf-8"))["records"]]
    clean = [r for r in recs if not r["effect"]]
    matters = [r for r in recs if r["effect"] and r["effect_ratio"] and r["effect_ratio"] >= MATTERS_RATIO]
    print(f"{len(recs)} runs: {len(clean)} clean ({sum(r['reversal'] for r in clean)} MR), "
          f"{len(matters)} effect runs with effect_ratio >= {MATTERS_RATIO:g}")
    for r in clean:
        if effect_steps(r):
            print(f"  clean run {r['i']} ({'MR' if r['reversal'] else 'FTR'}): "
                  + ", ".join(f"{s['effect']} {100 * drop(s):.1f} %" for s in effect_steps(r)))
    for r in matters:
        if effect_steps(r, r["effect"]):
            print(f"  {r['effect']} run {r['i']} ({'MR' if r['reversal'] else 'FTR'}, ratio {r['effect_ratio']:.2f}): "
                  + ", ".join(f"{s['effect']} {100 * drop(s):.1f} %" for s in effect_steps(r, r["effect"])))
    print("threshold | false discovery (MR control) | detection")
    for thr in (0.05, 0.10, 0.15, 0.18, 0.20, 0.25, 0.30):
        fd = [r for r in clean if any(drop(s) >= thr for s in effect_steps(r))]
        det = [r for r in matters if any(drop(s) >= thr for s in effect_steps(r, r["effect"]))]
        print(f"{100 * thr:4.0f} %   | {len(fd)}/{len(clean)} ({sum(r['reversal'] for r in fd)}) | {len(det)}/{len(matters)}")


if __name__ == "__main__":
    main(sys.argv[1:])
