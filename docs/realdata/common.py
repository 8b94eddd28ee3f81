"""Shared helpers: causal filters, feature sets, hold-out splits, metrics (all deg/h)."""
import os
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np

def lag(t, u, tau):
    """Causal first-order lag, exact for piecewise-linear input (first-order hold), y0=u0."""
    y = np.empty_like(u); y[0] = u[0]
    h = np.diff(t)
    a = np.exp(-h / tau)
    g = 1 - tau * (1 - a) / h
    for i in range(1, len(u)):
        y[i] = a[i-1] * y[i-1] + (1 - a[i-1]) * u[i-1] + (u[i] - u[i-1]) * g[i-1]
    return y

def d1(t, T):
    """1-sample backward difference, degC/min (first sample repeats the second)."""
    v = np.empty_like(T); v[1:] = np.diff(T) / np.diff(t) * 60; v[0] = v[1]; return v

def d_iir(t, T, tau):
    """Causal derivative of the first-order lag state: dL/dt = (T - L)/tau, degC/min."""
    return (T - lag(t, T, tau)) / tau * 60

def d_ls(t, T, W):
    """Causal least-squares slope over the trailing W seconds, degC/min."""
    v = np.zeros_like(T); j = 0
    cs = lambda x: np.concatenate([[0], np.cumsum(x)])
    St, ST, Stt, StT = cs(t - t[0]), cs(T), cs((t - t[0])**2), cs((t - t[0]) * T)
    for i in range(len(T)):
        while t[i] - t[j] > W: j += 1
        n = i - j + 1
        if n < 3: v[i] = 0 if i == 0 else (T[i]-T[j])/(t[i]-t[j])*60; continue
        s_t, s_T, s_tt, s_tT = St[i+1]-St[j], ST[i+1]-ST[j], Stt[i+1]-Stt[j], StT[i+1]-StT[j]
        v[i] = (n * s_tT - s_t * s_T) / (n * s_tt - s_t**2) * 60
    return v

def p16(Tn, vn):
    """Paper eq. (8): T, T^2, T^3, v, v^2, v^3 and T^i v^j (i,j=1..3): 15 regressors + intercept."""
    cols = [Tn**i for i in (1, 2, 3)] + [vn**j for j in (1, 2, 3)]
    cols += [Tn**i * vn**j for i in (1, 2, 3) for j in (1, 2, 3)]
    return np.column_stack(cols)

def cubic(x): return np.column_stack([x, x**2, x**3])

def fit_predict(X, y, tr):
    A = np.column_stack([np.ones(len(y)), X]) if X is not None and X.size else np.ones((len(y), 1))
    coef, *_ = np.linalg.lstsq(A[tr], y[tr], rcond=None)
    return A @ coef, coef, np.linalg.cond(A[tr])

def binned_std(t, r, mask, tau):
    """std of non-overlapping tau-s averages of r, bins fully inside mask (>=80% filled)."""
    if tau is None: return np.std(r[mask])
    b = np.floor((t - t[0]) / tau).astype(int)
    nb = b.max() + 1
    cnt = np.bincount(b, minlength=nb); cm = np.bincount(b, weights=mask.astype(float), minlength=nb)
    s = np.bincount(b, weights=np.where(mask, r, 0), minlength=nb)
    dt = np.median(np.diff(t)); full = (cm == cnt) & (cnt >= 0.8 * tau / dt)
    m = s[full] / cnt[full]
    return np.std(m) if len(m) > 2 else np.nan

def metrics(t, r, mask):
    return dict(mean=np.mean(r[mask]), s1=binned_std(t, r, mask, 1.0),
                s10=binned_std(t, r, mask, 10.0), s100=binned_std(t, r, mask, 100.0),
                rms1=np.sqrt(binned_std(t, r, mask, 1.0)**2 + np.mean(r[mask])**2))

def heldout(t, y, X, splits):
    """splits: list of (train_mask, test_mask). Returns pooled held-out residual and its test mask."""
    res = np.full(len(y), np.nan); tm = np.zeros(len(y), bool); conds = []
    for tr, te in splits:
        pred, coef, cond = fit_predict(X, y, tr)
        res[te] = (y - pred)[te]; tm |= te; conds.append(cond)
    return res, tm, conds
