# Measurement script of docs/ACCURACY.md "Rate preference", "What the tail needs" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/oracle_node.py SEED [SEED ...]
"""Oracle: the TRUE temperature of the common-mode node (E) or of the damping node (D), from the
simulator, offered to the lag-state block as a sensor-like column (tau 0, powers 1..3) beside the usual
proxy blocks, no margin; held-out std / floor of the default MR fit with it.  Answers: would knowing
the node that carries the bias bring a tail device to the floor?"""
import sys
import numpy as np
from host_tools.fitting import fit_lag as FL, fit_pipeline as FP
from host_tools.golden.runlog import RunLog
from host_tools.bench.accuracy import device_runs, heldout_ratio
from host_tools.simulation.sim_foreign import foreign_device, chamber_profile, node_temperatures

def with_col(log, dev, rate, node, name="aux_te"):
    prof = chamber_profile(dev, rate)
    t = np.asarray(log.columns["t_s"], float)
    temps = node_temperatures(dev, t, np.interp(t, prof[:, 0], prof[:, 1]))
    cols = dict(log.columns); cols[name] = temps[node]
    return RunLog.from_arrays(metadata=dict(log.metadata), source=log.source, **cols)

def ratio(tr, ho, fl, patch):
    saved = {k: getattr(FL, k) for k in patch}
    for k, v in patch.items(): setattr(FL, k, v)
    try:
        m, _ = FP.fit_default([tr])
        return heldout_ratio(m, ho, fl), m.fit.get("lag_block", {}).get("chosen")
    finally:
        for k, v in saved.items(): setattr(FL, k, v)

for seed in map(int, sys.argv[1:]):
    dev = foreign_device(seed)
    tr, ho, fl = device_runs(dev, True)
    res = {"base": ratio(tr, ho, fl, {})}
    for nm, node in (("E", dev.common_node), ("D", dev.damping_node)):
        tr2, ho2 = with_col(tr, dev, 4.0, node), with_col(ho, dev, 2.0, node)
        orig = FL.sensor_source
        def ss(logs, config):
            x = np.concatenate([l.columns["aux_te"] for l in logs]); lo, hi = x.min(), x.max()
            return ("aux_te", 0.5*(lo+hi), 0.6*(hi-lo))
        FL.sensor_source = ss
        try:
            res["oracle"+nm] = ratio(tr2, ho2, fl, {"SENSOR_TAUS_S": (0.0,), "LAG_MARGIN": {"ftr": -9, "mr": -9}})
        finally:
            FL.sensor_source = orig
    print(seed, {k: (round(v[0], 2), v[1]) for k, v in res.items()}, flush=True)
