"""Coefficient consistency per leg/block, combined models, conditioning, periodogram. Usage: python extra.py"""
import numpy as np
from load import load_tofu
from common import *
out = []
def P(*a): s = " ".join(str(x) for x in a); print(s); out.append(s)
for ax in "xy":
    c = load_tofu(ax); sl = slice(1, None)
    t, y, T = c["t_s"][sl], c["rate_dph"][sl], c["temp_c"][sl]
    acc = np.column_stack([c[k][sl] for k in ("aux_acc_x", "aux_acc_y", "aux_acc_z")])
    n = len(t); Tn = (T - 30) / 50
    imin, imax = np.argmin(T), np.argmax(T)
    iend = imax + np.argmin(T[imax:])   # final upturn excluded from both legs
    cool = np.zeros(n, bool); cool[:imin] = True; cool[imax:iend] = True
    heat = np.zeros(n, bool); heat[imin:imax] = True
    c1 = np.zeros(n, bool); c1[:imin] = True; c2 = np.zeros(n, bool); c2[imax:iend] = True
    for nm_, m_ in (("cool1", c1), ("heat", heat), ("cool2", c2)):
        vv = d_ls(t, T, 30)[m_]
        P(f"  leg {nm_}: {m_.sum()} samples, T {T[m_].min():.1f}..{T[m_].max():.1f} C, dT/dt(ls30) 5-95% {np.percentile(vv,5):+.2f}..{np.percentile(vv,95):+.2f} C/min, t {t[m_][0]:.0f}-{t[m_][-1]:.0f} s")
    P(f"===== axis {ax}")
    # --- coefficient consistency (physical units): fit on each subset separately
    Lr = {tau: lag(t, T, tau) for tau in (30, 100, 200, 300)}
    subsets = {"all": np.ones(n, bool), "cool": cool, "heat": heat, "cool1": c1, "cool2": c2}
    for nm, X, unit in [("acc_x", acc[:, 0], "dph/(m/s2)"), ("acc_y", acc[:, 1], "dph/(m/s2)"),
                        ("acc_z", acc[:, 2], "dph/(m/s2)"),
                        ("T-L[100]", T - Lr[100], "dph/degC"), ("T-L[200]", T - Lr[200], "dph/degC"),
                        ("v_ls30[C/min]", d_ls(t, T, 30), "dph/(C/min)")]:
        s = []
        for sn, m in subsets.items():
            A = np.column_stack([np.ones(n), cubic(Tn), X])[m]
            coef, *_ = np.linalg.lstsq(A, y[m], rcond=None)
            r = y[m] - A @ coef
            # crude SE with AR(1)-inflated variance (residuals are strongly correlated)
            rho = np.corrcoef(r[:-1], r[1:])[0, 1]; neff = len(r) * (1 - rho) / (1 + rho)
            cov = np.linalg.inv(A.T @ A) * r.var() * len(r) / max(neff, 5)
            s.append(f"{sn}={coef[-1]:+.1f}±{np.sqrt(cov[-1,-1]):.1f}")
        P(f"  cubicT+{nm:14s} coef [{unit}]: " + "  ".join(s))
    # --- range of the aux channels per leg (to judge g-sensitivity plausibility)
    for j, nm in enumerate("xyz"):
        P(f"  acc_{nm}: range all {np.ptp(acc[:, j]):.3f} m/s2 ({np.ptp(acc[:, j])/9.81*1e3:.1f} mg); corr with T {np.corrcoef(acc[:, j], T)[0,1]:+.2f}")
    # --- conditioning of the paper 17-term design (16 columns) with different v estimators
    for vn, v in [("d1", d1(t, T)), ("iir100", d_iir(t, T, 100)), ("ls30", d_ls(t, T, 30))]:
        X = np.column_stack([np.ones(n), p16(Tn, v / 3)])
        Xs = X / np.linalg.norm(X, axis=0)
        sv = np.linalg.svd(Xs, compute_uv=False)
        P(f"  p16[{vn}]: cond(col-normalised)={sv[0]/sv[-1]:.2e}, #sv>1e-2*max={np.sum(sv > 1e-2*sv[0])}/16,"
          f" corr(T,v)={np.corrcoef(T, v)[0,1]:+.2f}, corr(v, leg sign)={np.corrcoef(v, np.where(heat,1,-1))[0,1]:+.2f},"
          f" std(v)={v.std():.2f} C/min, noise of v (std of diff)={np.std(np.diff(v))/np.sqrt(2):.2f}")
    # --- combined models held out
    splits = {"C->H": [(cool, heat)], "H->C": [(heat, cool)]}
    edges = np.linspace(t[0], t[-1] + 1e-9, 6)
    splits["blk5"] = [(~((t >= edges[i]) & (t < edges[i+1])), (t >= edges[i]) & (t < edges[i+1])) for i in range(5)]
    an = (acc - acc.mean(0)) / acc.std(0)
    combos = {"cubicT": cubic(Tn),
              "cubicT+acc_y": np.column_stack([cubic(Tn), an[:, 1]]),
              "cubicT+(T-L)[200]": np.column_stack([cubic(Tn), (T - Lr[200]) / 50]),
              "cubicT+acc_y+(T-L)[200]": np.column_stack([cubic(Tn), an[:, 1], (T - Lr[200]) / 50]),
              "cubicT+acc_xyz+(T-L)[200]": np.column_stack([cubic(Tn), an, (T - Lr[200]) / 50]),
              "cubicT+lag(acc_y,200)": np.column_stack([cubic(Tn), lag(t, an[:, 1], 200)]),
              "quadT+acc_y": np.column_stack([Tn, Tn**2, an[:, 1]]),
              "linT+(T-L)[200]": np.column_stack([Tn, (T - Lr[200]) / 50]),
              }
    for nm, X in combos.items():
        s = []
        for sp, spl in splits.items():
            r, tm, _ = heldout(t, y, X, spl); m = metrics(t, r, tm)
            s.append(f"{sp}: rms1 {m['rms1']:.2f} s1 {m['s1']:.2f} s100 {m['s100']:.2f}")
        P(f"  {nm:26s} " + " | ".join(s))
    # --- periodogram of the cubic in-sample residual (periodic terms?)
    r = y - fit_predict(cubic(Tn), y, np.ones(n, bool))[0]
    from scipy.signal import periodogram, detrend
    f, pxx = periodogram(detrend(r), fs=1 / np.median(np.diff(t)))
    band = (f > 1 / 1000) & (f < 0.9)
    # local peak-to-background ratio (peaks stand out if > ~20x local median)
    from scipy.ndimage import median_filter
    bg = median_filter(pxx, 51); ratio = pxx / bg
    idx = np.argsort(ratio * band)[::-1][:5]
    P("  top periodogram peaks above local median (cubic residual): " + ", ".join(f"{1/f[i]:.1f}s x{ratio[i]:.0f}" for i in idx))
    # --- step detection on the cubic residual (x popcorn): jumps between consecutive 10-s means
    b = np.floor((t - t[0]) / 10).astype(int); mm = np.bincount(b, r) / np.bincount(b)
    j = np.diff(mm); thr = 5 * 1.4826 * np.median(np.abs(j - np.median(j)))
    big = np.where(np.abs(j) > thr)[0]
    P(f"  10-s-mean jumps > {thr:.1f} dph (5 robust sigma): {len(big)} at t~" + ",".join(f"{(k+1)*10:.0f}s({j[k]:+.1f})" for k in big[:15]))
open("out_extra.txt", "w").write("\n".join(out) + "\n")
