"""Held-out models of the measured tofupilot IMU thermal cycle (docs/REALDATA_FINDINGS.md).

The log (tests/data/tofupilot-imu-thermal, 8399 samples at 1.98 Hz, one chamber cycle) has three
monotonic legs: cool1 (start .. T min), heat (T min .. T max), cool2 (T max .. the last minimum).
Five hold-out splits: C->H (train on both cooling legs, hold out the heating leg), H->C, c1h->c2,
hc2->c1 and blk5 (five contiguous blocks, leave one out, pooled).  Every model is an ordinary
least-squares fit on the training samples; the held-out residual is scored as

* rms1: the rms of held-out 1-s means INCLUDING their mean (a leg offset is the hysteresis a plain
  std hides);
* s1 / s100: the std of held-out 1-s / 100-s means.

All in deg/h.  Prints one table per axis:

    python docs/studies/measured_splits.py > docs/studies/measured_splits.txt
"""
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402

from host_tools.golden.runlog import read_csv  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "tests" / "data" / "tofupilot-imu-thermal"


def load(ax):
    r = read_csv(str(DATA / f"tofupilot-imu-{ax}.csv"))
    return {k: np.asarray(v, float) for k, v in r.columns.items()}


def lag(t, u, tau):
    """Causal first-order lag, exact for piecewise-linear input, starting at u[0]."""
    y = np.empty_like(u)
    y[0] = u[0]
    h = np.diff(t)
    a = np.exp(-h / tau)
    g = 1 - tau * (1 - a) / h
    for i in range(1, len(u)):
        y[i] = a[i - 1] * y[i - 1] + (1 - a[i - 1]) * u[i - 1] + (u[i] - u[i - 1]) * g[i - 1]
    return y


def d1(t, T):
    """1-sample backward difference [degC/min]."""
    v = np.empty_like(T)
    v[1:] = np.diff(T) / np.diff(t) * 60
    v[0] = v[1]
    return v


def cubic(x):
    return np.column_stack([x, x ** 2, x ** 3])


def p16(Tn, vn):
    """The paper's eq. (8): T, T^2, T^3, v, v^2, v^3 and T^i v^j (i, j = 1..3), with an intercept."""
    cols = [Tn ** i for i in (1, 2, 3)] + [vn ** j for j in (1, 2, 3)]
    cols += [Tn ** i * vn ** j for i in (1, 2, 3) for j in (1, 2, 3)]
    return np.column_stack(cols)


def fit_predict(X, y, tr):
    A = np.column_stack([np.ones(len(y)), X]) if X is not None else np.ones((len(y), 1))
    coef, *_ = np.linalg.lstsq(A[tr], y[tr], rcond=None)
    return A @ coef


def binned_std(t, r, mask, tau):
    """std of non-overlapping tau-s means of r over bins wholly inside mask (>= 80 % filled)."""
    b = np.floor((t - t[0]) / tau).astype(int)
    nb = b.max() + 1
    cnt = np.bincount(b, minlength=nb)
    cm = np.bincount(b, weights=mask.astype(float), minlength=nb)
    s = np.bincount(b, weights=np.where(mask, r, 0), minlength=nb)
    full = (cm == cnt) & (cnt >= 0.8 * tau / np.median(np.diff(t)))
    m = s[full] / cnt[full]
    return np.std(m) if len(m) > 2 else np.nan


def heldout(t, y, X, splits):
    res = np.full(len(y), np.nan)
    tm = np.zeros(len(y), bool)
    for tr, te in splits:
        res[te] = (y - fit_predict(X, y, tr))[te]
        tm |= te
    s1 = binned_std(t, res, tm, 1.0)
    return {"rms1": float(np.sqrt(s1 ** 2 + np.mean(res[tm]) ** 2)), "s1": float(s1),
            "s100": float(binned_std(t, res, tm, 100.0))}


def study(ax):
    c = load(ax)
    sl = slice(1, None)                       # sample 0 is a power-on glitch
    t, y, T = c["t_s"][sl], c["rate_dph"][sl], c["temp_c"][sl]
    acc_y = c["aux_acc_y"][sl]
    n = len(t)
    Tn = (T - 30) / 50
    imin, imax = np.argmin(T), np.argmax(T)
    iend = imax + np.argmin(T[imax:])
    cool = np.zeros(n, bool)
    cool[:imin] = True
    cool[imax:iend] = True
    heat = np.zeros(n, bool)
    heat[imin:imax] = True
    c1 = np.zeros(n, bool)
    c1[:imin] = True
    c2 = np.zeros(n, bool)
    c2[imax:iend] = True
    edges = np.linspace(t[0], t[-1] + 1e-9, 6)
    blocks = [(t >= edges[i]) & (t < edges[i + 1]) for i in range(5)]
    splits = {"C->H": [(cool, heat)], "H->C": [(heat, cool)], "c1h->c2": [(c1 | heat, c2)],
              "hc2->c1": [(heat | c2, c1)], "blk5": [(~b, b) for b in blocks]}
    an = (acc_y - acc_y.mean()) / acc_y.std()
    L10, L200 = (lag(t, T, tau) for tau in (10, 200))
    models = {
        "cubic in T (baseline)": cubic(Tn),
        "paper's 16 terms, 1-sample rate": p16(Tn, d1(t, T) / 3),
        "cubic in lag(T, 10 s)": cubic((L10 - 30) / 50),
        "cubic in T + (T - lag(T, 200 s))": np.column_stack([cubic(Tn), Tn - (L200 - 30) / 50]),
        "cubic in T + acc_y": np.column_stack([cubic(Tn), an]),
        "cubic in T + lag(acc_y, 200 s)": np.column_stack([cubic(Tn), lag(t, an, 200)]),
        "cubic in T + time": np.column_stack([cubic(Tn), t / t[-1]]),
    }
    print(f"axis {ax}: held-out rms1 [s1 / s100] in deg/h, {n} samples")
    print("| model | " + " | ".join(splits) + " |")
    print("|---|" + "---|" * len(splits))
    for name, X in models.items():
        cells = []
        for sp in splits.values():
            m = heldout(t, y, X, sp)
            cells.append(f"{m['rms1']:.1f} [{m['s1']:.1f} / {m['s100']:.1f}]")
        print(f"| {name} | " + " | ".join(cells) + " |")
    print()


if __name__ == "__main__":
    for axis in (sys.argv[1:] or ["x", "y"]):
        study(axis)
