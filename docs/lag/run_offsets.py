# Measurement script of docs/ACCURACY.md "Several training runs" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/run_offsets.py SET mr|ftr START STOP > rows.jsonl
"""Per-run offsets, tried by hand before building them into the fitter: the default fit on the
benchmark's training run + a second run from another power-on (same rate: "same", 3 degC/min:
"two", as docs/lag/two_rates.py with POWER_ON 2), then twice: per run and coefficient bank the mean
residual of the training samples the fit uses is removed from that run's rate (mode 2: with the
mode sign), and the default fit repeated.  Held-out std at 1 s / floor on the benchmark's held-out
run; compare with docs/lag/data/two_rates_po2.jsonl."""
import json, sys
import numpy as np
from host_tools.fitting import fit_pipeline as FP
from host_tools.golden.compensate import prepare
from host_tools.golden.regressors import regressor_matrix
from host_tools.golden.runlog import RunLog
from host_tools.bench.accuracy import device_runs, heldout_ratio
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

def offsets_removed(logs, model):
    out = []
    for log in logs:
        pr = prepare(log, model.config)
        X = regressor_matrix(pr.u, pr.v, pr.z)
        rate = np.array(log.rate_dph, float)
        banks = [(1, model.coef), (2, model.coef_mode2)] if model.coef_mode2 is not None else [(None, model.coef)]
        for m, coef in banks:
            sel = pr.used if m is None else pr.used & (pr.mode == m)
            o = float(np.mean(pr.y[sel] - X[sel] @ np.asarray(coef)))
            if m is None:
                rate -= o
            else:
                s = 1.0 if m == 1 else -1.0
                rate[pr.mode == m] -= s * o
        cols = dict(log.columns); cols["rate_dph"] = rate
        out.append(RunLog.from_arrays(metadata=dict(log.metadata), source=log.source, **cols))
    return out

st, kind, a, b = int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
rev = kind == "mr"; base = {0: 0, 1: 100000, 2: 200000}[st]
for seed in range(base + a, base + b):
    dev = foreign_device(seed); tr, ho, fl = device_runs(dev, rev)
    rec = {"seed": seed, "kind": kind}
    for name, extra in (("same", (4.0, 2, 2)), ("two", (3.0, 2, 2))):
        logs = [tr, simulate_foreign(dev, extra[0], rev, extra[1], extra[2])]
        m, _ = FP.fit_default(logs)
        for it in range(2):
            logs2 = offsets_removed(logs, m)
            m, _ = FP.fit_default(logs2)
        rec[name + "_off"] = heldout_ratio(m, ho, fl)
    print(json.dumps(rec), flush=True)
