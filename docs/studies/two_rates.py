"""Several training runs (docs/ACCURACY.md, "Several training runs").

Per foreign device, the `hdrg fit` default fit (fit_pipeline.fit_default, per-run offsets removed)
on the benchmark's training run (4 degC/min, power-on 0) alone (``one``) and with a second run
(``two``: another chamber rate, SECOND_RATE degC/min, default 3, from power-on POWER_ON, default 2),
each held out on the benchmark's held-out run (2 degC/min, power-on 1; std at 1 s / noise floor).
``same``: the second run at the same 4 degC/min instead.

Measure (one JSON line per device on stderr; about 25 s per mode-reversal device):

    python docs/studies/two_rates.py SET mr|ftr START STOP [POWER_ON] 2>> docs/studies/two_rates.jsonl

(the record: sets 0, 1, 2 with devices 0..50, 0..40, 0..40, mr and ftr, POWER_ON 2.)  Table:

    python docs/studies/two_rates.py --table docs/studies/two_rates.jsonl
"""
import json
import os
import sys

import numpy as np

SET_BASE = {0: 0, 1: 100000, 2: 200000}
SETS = (("set 0", 0, 50), ("set 1", 100000, 100040), ("set 2", 200000, 200040))


def measure(st, kind, a, b, po=2):
    from host_tools.bench.accuracy import damping_change_dph, device_runs, heldout_ratio
    from host_tools.fitting import fit_pipeline as FP
    from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

    rev = kind == "mr"
    second = float(os.environ.get("SECOND_RATE", "3.0"))
    for seed in range(SET_BASE[st] + a, SET_BASE[st] + b):
        dev = foreign_device(seed)
        tr, ho, fl = device_runs(dev, rev)
        rec = {"seed": seed, "kind": kind, "dc": damping_change_dph(dev), "second_power_on": po, "second_rate": second}
        for name, extra in (("one", None), ("same", (4.0, po, 2)), ("two", (second, po, 2))):
            logs = [tr] if extra is None else [tr, simulate_foreign(dev, extra[0], rev, extra[1], extra[2])]
            try:
                m, _ = FP.fit_default(logs)
                rec[name] = heldout_ratio(m, ho, fl)
                rec[name + "_lag"] = m.fit.get("lag_block", {}).get("chosen")
                rec[name + "_rate"] = f"{m.config.rate.estimator}/{m.config.rate.n}/{m.config.rate.shift}"
            except ValueError as exc:
                rec[name], rec[name + "_error"] = None, str(exc)
        print(json.dumps(rec), file=sys.stderr, flush=True)


def table(paths):
    """Per kind and set: one run against one run + a run at another chamber rate (median / p90),
    the geometric mean of the ratio two / one with the devices better / worse by more than 10 %,
    the devices above 1.5, and the medians without / with a damping change."""
    print("| kind | set | n | one run | + run at another rate | x (better / worse) | devices > 1.5 "
          "| median, no damping change / damping change |")
    print("|---|---|---|---|---|---|---|---|")
    recs = [json.loads(line) for path in paths for line in open(path) if line.startswith("{")]
    for kind in ("mr", "ftr"):
        for name, lo, hi in SETS:
            rs = [r for r in recs if r["kind"] == kind and lo <= r["seed"] < hi
                  and r.get("one") is not None and r.get("two") is not None]
            if not rs:
                continue
            one, two = (np.array([r[k] for r in rs]) for k in ("one", "two"))
            dc = np.array([r["dc"] > 0.5 for r in rs])
            g = np.exp(np.mean(np.log(two / one)))
            print(f"| {kind.upper()} | {name} | {len(rs)} | {np.median(one):.2f} / {np.percentile(one, 90):.2f} | "
                  f"{np.median(two):.2f} / {np.percentile(two, 90):.2f} | x{g:.2f} ({(two < one / 1.1).sum()} / "
                  f"{(two > 1.1 * one).sum()}) | {(one > 1.5).sum()} -> {(two > 1.5).sum()} | "
                  f"{np.median(one[~dc]):.2f} -> {np.median(two[~dc]):.2f} / "
                  f"{np.median(one[dc]):.2f} -> {np.median(two[dc]):.2f} |")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--table"]:
        table(sys.argv[2:])
    else:
        measure(int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4]),
                int(sys.argv[5]) if len(sys.argv) > 5 else 2)
