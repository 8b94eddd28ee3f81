# Analysis of docs/lag/two_rates.py records (docs/ACCURACY.md "Several training runs").
# Usage: python docs/lag/two_rates_analyze.py docs/lag/data/two_rates_po2.jsonl docs/lag/data/two_rates_po0.jsonl
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


if __name__ == "__main__":
    main()
