"""In-sample cubic-in-T fit on each monotonic leg separately: how close to the noise floor is one leg?
Usage: python perleg.py"""
import numpy as np, allantools
from load import load_tofu
from common import *
for ax in "xy":
    c = load_tofu(ax); t, y, T = c["t_s"][1:], c["rate_dph"][1:], c["temp_c"][1:]
    n = len(t); imin, imax = np.argmin(T), np.argmax(T); iend = imax + np.argmin(T[imax:])
    legs = {"cool1": slice(0, imin), "heat": slice(imin, imax), "cool2": slice(imax, iend), "cool1[t>300s]": slice(594, imin)}
    w = np.std(np.diff(y)) / np.sqrt(2)
    for nm, s in legs.items():
        m = np.zeros(n, bool); m[s] = True
        for deg in (3, 5):
            X = np.column_stack([((T - 30) / 50) ** k for k in range(1, deg + 1)])
            r = y - fit_predict(X, y, m)[0]
            mt = metrics(t, r, m)
            _, ad, _, _ = allantools.oadev(r[m], rate=1.978, data_type="freq", taus=[1, 10, 100])
            print(f"{ax} {nm:14s} poly{deg}: std1 {mt['s1']:.2f} s10 {mt['s10']:.2f} s100 {mt['s100']:.2f}  ADEV1/10/100 {ad[0]:.2f}/{ad[1]:.2f}/{ad[2]:.2f}  (white: 1s {w/np.sqrt(1.978):.2f}, 10s {w/np.sqrt(19.78):.2f}, 100s {w/np.sqrt(197.8):.2f})")
