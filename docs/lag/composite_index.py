# Measurement script of docs/ACCURACY.md "What the tail needs" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/composite_index.py SEED [SEED ...]
"""Prototype (float only): a learned composite input w = sum_i a_i x_i over the proxy, the sensor and
their lags (60, 240, 960 s), a_i = least squares of the default model's compensated TRAINING output on
them; w^1..3 offered to the lag block (in place of the sensor blocks, default margin).  Held-out std /
floor of the default MR fit before and with it."""
import sys, numpy as np
from host_tools.fitting import fit_lag as FL, fit_pipeline as FP
from host_tools.golden.compensate import compensate
from host_tools.golden.runlog import RunLog
from host_tools.bench.accuracy import device_runs, heldout_ratio as held
from host_tools.simulation.sim_foreign import foreign_device
TAUS = (60.0, 240.0, 960.0)
def lag(x, tau):
    a = 1.0 / tau; y = np.empty_like(x); y[0] = x[0]
    for i in range(1, len(x)): y[i] = y[i-1] + a * (x[i] - y[i-1])
    return y
def basis(log, ref):
    f = np.asarray(log.columns["freq_hz"], float); T = np.asarray(log.columns["temp_c"], float)
    u = (f - ref[0]) / ref[1]; t = (T - ref[2]) / ref[3]
    cols = [u, t] + [lag(u, k) for k in TAUS] + [lag(t, k) for k in TAUS]
    return np.vstack(cols).T
def with_col(log, x, name="aux_w"):
    cols = dict(log.columns); cols[name] = x
    return RunLog.from_arrays(metadata=dict(log.metadata), source=log.source, **cols)
if __name__ == "__main__":
    for seed in map(int, sys.argv[1:]):
        tr, ho, fl = device_runs(foreign_device(seed), True)
        m0, _ = FP.fit_default([tr]); r0 = held(m0, ho, fl)
        f = np.asarray(tr.columns["freq_hz"], float); T = np.asarray(tr.columns["temp_c"], float)
        ref = (f.mean(), f.std(), T.mean(), T.std())
        Xtr, Xho = basis(tr, ref), basis(ho, ref)
        out = compensate(tr, m0); v = out["valid"] > 0
        y = np.asarray(out.rate_dph)[v]
        A = np.column_stack([Xtr[v], np.ones(v.sum())])
        coef, *_ = np.linalg.lstsq(A, y - y.mean(), rcond=None)
        w_tr, w_ho = Xtr @ coef[:-1], Xho @ coef[:-1]
        tr2, ho2 = with_col(tr, w_tr), with_col(ho, w_ho)
        orig = FL.sensor_source
        FL.sensor_source = lambda logs, config: ("aux_w", 0.5 * (w_tr.min() + w_tr.max()), 0.6 * (w_tr.max() - w_tr.min()))
        saved = FL.SENSOR_TAUS_S; FL.SENSOR_TAUS_S = (0.0,)
        try:
            m1, _ = FP.fit_default([tr2]); r1 = held(m1, ho2, fl)
        finally:
            FL.sensor_source = orig; FL.SENSOR_TAUS_S = saved
        print(seed, "base %.2f composite %.2f" % (r0, r1), m0.fit.get("lag_block", {}).get("chosen"), "->", m1.fit.get("lag_block", {}).get("chosen"), flush=True)
