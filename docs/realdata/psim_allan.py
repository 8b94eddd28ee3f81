"""(a) Allan deviation of tofupilot residuals (cubicT in-sample and best held-out), (b) psim LSM6DSM burst-mean analysis.
Usage: python psim_allan.py"""
import numpy as np, allantools, warnings
from load import load_tofu, load_psim
from common import *
out = []
def P(*a): s = " ".join(str(x) for x in a); print(s); out.append(s)
P("== (a) Allan deviation (overlapping, fs=1.978 Hz) of the tofupilot cubic-in-T in-sample residual")
for ax in "xy":
    c = load_tofu(ax); t, y, T = c["t_s"][1:], c["rate_dph"][1:], c["temp_c"][1:]
    n = len(t); Tn = (T - 30) / 50; fs = 1 / np.median(np.diff(t))
    for nm, X in [("cubicT", cubic(Tn)), ("cubicT+(T-L)[200]+acc_xyz", np.column_stack([cubic(Tn), T - lag(t, T, 200), np.column_stack([c[k][1:] for k in ("aux_acc_x","aux_acc_y","aux_acc_z")])]))]:
        r = y - fit_predict(X, y, np.ones(n, bool))[0]
        taus = np.array([0.505, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000])
        tt, ad, ade, nn = allantools.oadev(r, rate=fs, data_type="freq", taus=taus)
        P(f"  {ax} {nm:28s} std {r.std():.2f}; ADEV " + " ".join(f"{a:.0f}s:{d:.2f}" for a, d in zip(tt, ad)))
        # white level: ARW-like coefficient = ADEV(1 s)*sqrt(1 s); also the raw high-pass floor
    # white floor from first differences (independent of drift)
    w = np.std(np.diff(y)) / np.sqrt(2)
    P(f"  {ax} white per-sample sigma from first differences: {w:.2f} dph -> expected 1-s mean {w/np.sqrt(fs):.2f}, 10-s {w/np.sqrt(10*fs):.2f}, 100-s {w/np.sqrt(100*fs):.3f} dph")
P("== (b) psim LSM6DSM: burst means (25 bursts, ~5 s each, every ~305 s), cooling only 23.8->15.6 C")
for ax in "xy":
    c, seg = load_psim(ax); t, y, T = c["t_s"], c["rate_dph"], c["temp_c"]
    ends = list(seg[1:]) + [len(t)]
    tb = np.array([t[a:b].mean() for a, b in zip(seg, ends)]); yb = np.array([np.median(y[a:b]) for a, b in zip(seg, ends)])
    ym = np.array([y[a:b].mean() for a, b in zip(seg, ends)])
    Tb = np.array([T[a:b].mean() for a, b in zip(seg, ends)])
    se = np.array([np.std(y[a:b]) / np.sqrt(b - a) for a, b in zip(seg, ends)])   # white-noise SE of a burst mean
    # within-burst Allan at 1 s (white check): std of 1-s means inside bursts
    m1 = []
    for a, b in zip(seg, ends):
        yy = y[a:b]; k = len(yy) // 50; m1 += list(yy[:k*50].reshape(k, 50).mean(1) - yy[:k*50].mean())
    nb = len(tb); Tn = (Tb - 20) / 4; th = (tb - tb[0]) / (tb[-1] - tb[0])
    vb = np.gradient(Tb, tb) * 60
    P(f"  axis {ax}: {nb} bursts, per-sample std median {np.median(se*np.sqrt(250)):.0f} dph, burst-mean white SE median {np.median(se):.2f} dph, within-burst 1-s-mean scatter {np.std(m1):.2f} dph (-> 5-s burst mean >= {np.std(m1)/np.sqrt(5):.1f});"
      f" dT/dt range {vb.min():.3f}..{vb.max():.3f} C/min; corr(T, t) {np.corrcoef(Tb, tb)[0,1]:+.4f}")
    # lag on the burst means: continuous first-order lag of the linearly interpolated burst-mean temperature
    models = {"lin T": Tn[:, None], "cubic T": cubic(Tn), "lin T + t": np.column_stack([Tn, th]),
              "cubic T + t": np.column_stack([cubic(Tn), th]), "quad T": np.column_stack([Tn, Tn**2])}
    for tau in (100, 300, 1000, 3000):
        models[f"lin lag(T,{tau})"] = ((lag(tb, Tb, tau) - 20) / 4)[:, None]
        models[f"cubic T + (T-L)[{tau}]"] = np.column_stack([cubic(Tn), (Tb - lag(tb, Tb, tau))])
    half = np.arange(nb) < nb // 2
    splits = {"LOO-burst": [(np.arange(nb) != i, np.arange(nb) == i) for i in range(nb)],
              "1st->2nd": [(half, ~half)], "2nd->1st": [(~half, half)],
              "blk5": [(~((np.arange(nb) // 5) == k), (np.arange(nb) // 5) == k) for k in range(5)]}
    for nm, X in models.items():
        s = []
        for sp, spl in splits.items():
            res = np.full(nb, np.nan)
            for tr, te in spl:
                A = np.column_stack([np.ones(nb), X]); coef, *_ = np.linalg.lstsq(A[tr], yb[tr], rcond=None)
                res[te] = (yb - A @ coef)[te]
            s.append(f"{sp} rms {np.sqrt(np.nanmean(res**2)):6.2f}")
        A = np.column_stack([np.ones(nb), X]); coef, *_ = np.linalg.lstsq(A, yb, rcond=None)
        ins = np.std(yb - A @ coef)
        P(f"    {nm:24s} in-sample {ins:6.2f} | " + " | ".join(s) + f" | cond {np.linalg.cond(A):.1e}")
open("out_psim_allan.txt", "w").write("\n".join(out) + "\n")
