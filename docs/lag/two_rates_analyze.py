# Analysis of docs/lag/two_rates.py records (docs/ACCURACY.md "Several training runs").
# Usage: python docs/lag/two_rates_analyze.py docs/lag/data/two_rates_po2.jsonl docs/lag/data/two_rates_po0.jsonl
#        python docs/lag/two_rates_analyze.py --by-rate F.jsonl ...   (one row per file: the "two" case
#        against "one", whatever its second_rate / second_power_on; plus devices above 1.5 and the
#        medians with / without a damping change)
"""Per set and kind: held-out std at 1 s / floor, median / p90, of the fit on one run, and on that
run + a second one (same rate / another rate), with the second run from another power-on (po 2) or
the same one (po 0); and the geometric mean of (two runs) / (one run) with the count of devices
better / worse by more than 10 %."""
import json
import sys
import numpy as np

SETS = (("set 0", 0, 50), ("set 1", 100000, 100040), ("set 2", 200000, 200040))


def main():
    recs = [json.loads(line) for path in sys.argv[1:] for line in open(path) if line.startswith("{")]
    print("| kind | set | n | one run | + same rate, other power-on | + other rate, other power-on "
          "| + same rate, same power-on | + other rate, same power-on |")
    print("|---|---|---|---|---|---|---|---|")
    for kind in ("mr", "ftr"):
        for name, lo, hi in SETS:
            by_po = {}
            for r in recs:
                if r["kind"] == kind and lo <= r["seed"] < hi:
                    by_po.setdefault(r.get("second_power_on", 2), {})[r["seed"]] = r
            if not by_po:
                continue
            seeds = sorted(set.intersection(*(set(d) for d in by_po.values())))
            first = by_po[max(by_po)]
            one = np.array([first[s]["one"] for s in seeds])
            cells = [f"{np.median(one):.2f} / {np.percentile(one, 90):.2f}"]
            for po in (2, 0):
                for k in ("same", "two"):
                    if po not in by_po:
                        cells.append("")
                        continue
                    x = np.array([by_po[po][s][k] for s in seeds])
                    g = np.exp(np.mean(np.log(x / one)))
                    cells.append(f"{np.median(x):.2f} / {np.percentile(x, 90):.2f}; x{g:.2f} "
                                 f"({(x < one / 1.1).sum()} better, {(x > 1.1 * one).sum()} worse)")
            print(f"| {kind.upper()} | {name} | {len(seeds)} | " + " | ".join(cells) + " |")


def by_rate(paths):
    print("| records | kind | set | n | second run (rate, power-on) | one run | two runs | x (better / worse) "
          "| devices > 1.5 | median, no damping change / damping change |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        recs = [json.loads(line) for line in open(path) if line.startswith("{")]
        for kind in ("mr", "ftr"):
            for name, lo, hi in SETS:
                rs = [r for r in recs if r["kind"] == kind and lo <= r["seed"] < hi
                      and r.get("one") is not None and r.get("two") is not None]
                if not rs:
                    continue
                one, two = (np.array([r[k] for r in rs]) for k in ("one", "two"))
                dc = np.array([r["dc"] > 0.5 for r in rs])
                g = np.exp(np.mean(np.log(two / one)))
                print(f"| {path.rsplit('/', 1)[-1]} | {kind.upper()} | {name} | {len(rs)} | "
                      f"{rs[0].get('second_rate', 3.0):g} degC/min, {rs[0].get('second_power_on', 2)} | "
                      f"{np.median(one):.2f} / {np.percentile(one, 90):.2f} | {np.median(two):.2f} / {np.percentile(two, 90):.2f} | "
                      f"x{g:.2f} ({(two < one / 1.1).sum()} / {(two > 1.1 * one).sum()}) | "
                      f"{(one > 1.5).sum()} -> {(two > 1.5).sum()} | "
                      f"{np.median(one[~dc]):.2f} -> {np.median(two[~dc]):.2f} / {np.median(one[dc]):.2f} -> {np.median(two[dc]):.2f} |")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--by-rate"]:
        by_rate(sys.argv[2:])
    else:
        main()
