"""Combined models on all 5 splits (held-out rms1 [s1/s100], deg/h). Usage: python combos.py"""
import numpy as np
from load import load_tofu
from common import *
for ax in "xy":
    c = load_tofu(ax); sl = slice(1, None)
    t, y, T = c["t_s"][sl], c["rate_dph"][sl], c["temp_c"][sl]
    n = len(t); Tn = (T - 30) / 50
    imin, imax = np.argmin(T), np.argmax(T); iend = imax + np.argmin(T[imax:])
    c1 = np.zeros(n, bool); c1[:imin] = True; c2 = np.zeros(n, bool); c2[imax:iend] = True
    heat = np.zeros(n, bool); heat[imin:imax] = True; cool = c1 | c2
    e = np.linspace(t[0], t[-1] + 1e-9, 6); blk = [(t >= e[i]) & (t < e[i+1]) for i in range(5)]
    SPL = {"C->H": [(cool, heat)], "H->C": [(heat, cool)], "c1h->c2": [(c1 | heat, c2)],
           "hc2->c1": [(heat | c2, c1)], "blk5": [(~b, b) for b in blk]}
    ay = c["aux_acc_y"][sl]; ay = (ay - ay.mean()) / ay.std()
    L = lambda tau: (lag(t, T, tau) - 30) / 50
    M = {"cubicT": cubic(Tn), "cubicLag[10]": cubic(L(10)),
         "cubicLag[10]+(T-L)[300]": np.column_stack([cubic(L(10)), Tn - L(300)]),
         "cubicLag[10]+acc_y": np.column_stack([cubic(L(10)), ay]),
         "cubicLag[10]+lag(acc_y,100)": np.column_stack([cubic(L(10)), lag(t, ay, 100)]),
         "cubicT+lag(acc_y,100)": np.column_stack([cubic(Tn), lag(t, ay, 100)]),
         "cubicT+lag(acc_y,300)": np.column_stack([cubic(Tn), lag(t, ay, 300)]),
         "cubicLag[10]+acc_y+(T-L)[300]": np.column_stack([cubic(L(10)), ay, Tn - L(300)])}
    print(f"axis {ax}: " + " | ".join(SPL))
    for nm, X in M.items():
        cells = []
        for s, spl in SPL.items():
            r, tm, _ = heldout(t, y, X, spl); m = metrics(t, r, tm)
            cells.append(f"{m['rms1']:6.1f} [{m['s1']:.1f}/{m['s100']:.1f}]")
        print(f"  {nm:30s} " + " ".join(cells))
