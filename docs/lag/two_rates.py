# Measurement script of docs/ACCURACY.md "One training rate cannot identify the node" (not part of the package).
# Usage: [RUN_OFFSETS=off] PYTHONPATH=. python docs/lag/two_rates.py SET mr|ftr START STOP [POWER_ON] 2>> rows.jsonl
"""Is the tail a limit of the method or of the data?  Per device, the default fit (`hdrg fit`
without options, fit_pipeline.fit_default) on three training sets, each held out on the
benchmark's held-out run (2 degC/min, power-on 1, noise seed 1; std at 1 s / floor):

* ``one``: the benchmark's training run (4 degC/min, power-on 0, noise seed 0);
* ``same``: that run + a second run at the SAME rate (4 degC/min, power-on 2, noise seed 2): more
  data, no new information about the dynamics;
* ``two``: that run + a second run at ANOTHER rate (3 degC/min, power-on 2, noise seed 2): with two
  logs the cross-validation groups are the runs, so every candidate (rate estimator, lag block,
  terms) is judged by how it extrapolates to another chamber rate.

POWER_ON (default 2) is the second run's power-on index; 0 = the SAME power-on as the first run
(no new damping change, only new noise): separates "a second run" from "a second power-on".
SECOND_RATE (default 3.0 degC/min): the chamber rate of the ``two`` run (1.0 brackets the held-out
2 degC/min: interpolation in rate instead of extrapolation).  CASES (default "one,same,two"): the
training sets to fit.
RUN_OFFSETS=off: several runs pooled without the per-run offsets (fit_default run_offsets="off", the
default before they were built; docs/lag/data/two_rates_po{2,0}.jsonl were measured that way).

One JSON line per device on stderr."""
import json
import os
import sys
from host_tools.fitting import fit_pipeline as FP
from host_tools.bench.accuracy import device_runs, heldout_ratio, damping_change_dph
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

SET_BASE = {0: 0, 1: 100000, 2: 200000}


def main():
    st, kind, a, b = int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    rev = kind == "mr"
    po = int(sys.argv[5]) if len(sys.argv) > 5 else 2
    for seed in range(SET_BASE[st] + a, SET_BASE[st] + b):
        dev = foreign_device(seed)
        tr, ho, fl = device_runs(dev, rev)
        second = float(os.environ.get("SECOND_RATE", "3.0"))
        cases = os.environ.get("CASES", "one,same,two").split(",")
        rec = {"seed": seed, "kind": kind, "dc": damping_change_dph(dev), "second_power_on": po, "second_rate": second}
        for name, extra in (("one", None), ("same", (4.0, po, 2)), ("two", (second, po, 2))):
            if name not in cases:
                rec[name] = None
                continue
            logs = [tr] if extra is None else [tr, simulate_foreign(dev, extra[0], rev, extra[1], extra[2])]
            try:
                m, _ = FP.fit_default(logs, run_offsets=os.environ.get("RUN_OFFSETS", "auto"))
                rec[name] = heldout_ratio(m, ho, fl)
                rec[name + "_lag"] = m.fit.get("lag_block", {}).get("chosen")
                rec[name + "_rate"] = f"{m.config.rate.estimator}/{m.config.rate.n}/{m.config.rate.shift}"
            except ValueError as exc:
                rec[name], rec[name + "_error"] = None, str(exc)
        print(json.dumps(rec), file=sys.stderr, flush=True)
        print(seed, kind, " ".join(f"{k} {rec[k]:.2f}" if rec[k] is not None else f"{k} -" for k in ("one", "same", "two")), flush=True)


if __name__ == "__main__":
    main()
