"""Sensitivity of the leg hold-out to the labelling of the final ~80 s upturn (T rises 34->36 C at the end).
Usage: python labelcheck.py"""
import numpy as np
from load import load_tofu
from common import *
for ax in "xy":
    c = load_tofu(ax); t, y, T = c["t_s"][1:], c["rate_dph"][1:], c["temp_c"][1:]
    n = len(t); Tn = (T - 30) / 50; imin, imax = np.argmin(T), np.argmax(T)
    iend = imax + np.argmin(T[imax:])          # start of the final upturn
    cool = np.zeros(n, bool); cool[:imin] = True; cool[imax:iend] = True
    heat = np.zeros(n, bool); heat[imin:imax] = True
    up = np.zeros(n, bool); up[iend:] = True
    print(f"axis {ax}: final upturn {up.sum()} samples ({t[iend]:.0f}-{t[-1]:.0f} s)")
    for nm, X in [("cubicT", cubic(Tn)), ("cubicT+(T-L)[200]", np.column_stack([cubic(Tn), (T - lag(t, T, 200)) / 50])),
                  ("cubicT+acc_y", np.column_stack([cubic(Tn), c["aux_acc_y"][1:]]))]:
        for lab, spl in [("C->H (upturn dropped)", [(cool, heat)]), ("H->C (upturn dropped)", [(heat, cool)]),
                         ("H+up->C", [(heat | up, cool)]), ("H->C+up", [(heat, cool | up)])]:
            r, tm, _ = heldout(t, y, X, spl); m = metrics(t, r, tm)
            print(f"  {nm:20s} {lab:22s} mean {m['mean']:+6.2f} s1 {m['s1']:5.2f} s10 {m['s10']:5.2f} s100 {m['s100']:5.2f} rms1 {m['rms1']:5.2f}")
