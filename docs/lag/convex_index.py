# Measurement script of docs/ACCURACY.md "What the tail needs" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/convex_index.py SET SEED... (device seeds of set SET: SET*100000 + SEED)
"""Prototype (float only): a 'virtual node' w = sum_i a_i x_i with a_i >= 0, sum a_i = 1, over
temperature-like channels in degC: the proxy as a temperature (the frequency's deviation over
-20.9 ppm/degC), the sensor, and their lags (60, 240, 960 s).  A positive-weighted mix of lagged
measured nodes is what a passive thermal network's hidden node looks like; unlike the unconstrained
composite (composite_index.py), it cannot form differences of lags that extrapolate.  The weights:
non-negative least squares of the default model's compensated TRAINING output on the channels (both
signs tried, the better kept), normalised to sum 1; w^1..3 offered to the lag block in place of the
sensor blocks (default margin).  Prints held-out std / floor of the default MR fit before and with it."""
import os
import sys
import numpy as np
from scipy.optimize import nnls
from host_tools.fitting import fit_lag as FL, fit_pipeline as FP
from host_tools.golden.compensate import compensate
from host_tools.bench.accuracy import device_runs, heldout_ratio as held
from host_tools.simulation.sim_foreign import foreign_device

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from composite_index import TAUS, lag, with_col   # noqa: E402  (the same lag and column as the unconstrained prototype)

PPM_PER_C = -20.9e-6


def channels(log, f0):
    f = np.asarray(log.columns["freq_hz"], float); T = np.asarray(log.columns["temp_c"], float)
    tp = (f / f0 - 1.0) / PPM_PER_C
    return np.vstack([tp, T] + [lag(tp, k) for k in TAUS] + [lag(T, k) for k in TAUS]).T


def one(seed, reversal=True):
    tr, ho, fl = device_runs(foreign_device(seed), reversal)
    m0, _ = FP.fit_default([tr]); r0 = held(m0, ho, fl)
    f0 = float(np.median(np.asarray(tr.columns["freq_hz"], float)))
    Xtr, Xho = channels(tr, f0), channels(ho, f0)
    out = compensate(tr, m0); v = np.asarray(out["valid"]) > 0
    y = np.asarray(out.rate_dph)[v]; y = y - y.mean()
    Xc = Xtr[v] - Xtr[v].mean(axis=0)
    best = None
    for sgn in (1.0, -1.0):
        a, res = nnls(Xc, sgn * y)
        if a.sum() > 0 and (best is None or res < best[1]):
            best = (a / a.sum(), res)
    if best is None:
        return r0, r0, None
    a = best[0]
    w_tr, w_ho = Xtr @ a, Xho @ a
    tr2, ho2 = with_col(tr, w_tr), with_col(ho, w_ho)
    orig, saved = FL.sensor_source, FL.SENSOR_TAUS_S
    FL.sensor_source = lambda logs, config: ("aux_w", 0.5 * (w_tr.min() + w_tr.max()), 0.6 * (w_tr.max() - w_tr.min()))
    FL.SENSOR_TAUS_S = (0.0,)
    try:
        m1, _ = FP.fit_default([tr2]); r1 = held(m1, ho2, fl)
    finally:
        FL.sensor_source, FL.SENSOR_TAUS_S = orig, saved
    return r0, r1, a


if __name__ == "__main__":
    s = int(sys.argv[1])
    for i in map(int, sys.argv[2:]):
        r0, r1, a = one(s * 100000 + i)
        print(s, i, "base %.2f convex %.2f" % (r0, r1), None if a is None else np.round(a, 2).tolist(), flush=True)
