"""Leg-difference diagnostic: mean rate per 5-degC bin on cool1 (52->-17.6), heat (-17.6->74), cool2 (74->36),
the difference cool-heat, the cubic slope dB/dT, and the lag dT_eq = (cool-heat)/(dB/dT) / (2*|v|) that a pure
sensor lag would need. Usage: python legdiff.py"""
import numpy as np
from load import load_tofu
for ax in "xy":
    c = load_tofu(ax); t, y, T = c["t_s"][1:], c["rate_dph"][1:], c["temp_c"][1:]
    imin, imax = np.argmin(T), np.argmax(T)
    legs = {"cool1": slice(0, imin), "heat": slice(imin, imax), "cool2": slice(imax, None)}
    p = np.polyfit(T, y, 3); dp = np.polyder(p)
    print(f"== axis {ax}")
    print(" Tbin   cool1    heat   cool2  c1-h  c2-h  dB/dT  v_c1  v_h  v_c2  tau_eq(c1-h)[s]")
    for lo in range(-15, 75, 5):
        row = {}; vv = {}
        for k, s in legs.items():
            m = (T[s] >= lo) & (T[s] < lo + 5)
            # require the leg to be moving (exclude the end upturn of cool2)
            row[k] = y[s][m].mean() if m.sum() > 10 else np.nan
            vv[k] = (np.polyfit(t[s][m], T[s][m], 1)[0] * 60) if m.sum() > 10 else np.nan
        d1_ = row["cool1"] - row["heat"]; d2_ = row["cool2"] - row["heat"]; sl = np.polyval(dp, lo + 2.5)
        # lag model: B = f(T - tau*v)  => cool - heat = -f' tau (v_c - v_h)
        tau = -d1_ / sl / ((vv["cool1"] - vv["heat"]) / 60) if np.isfinite(d1_) else np.nan
        print(f"{lo:5d} {row['cool1']:7.1f} {row['heat']:7.1f} {row['cool2']:7.1f} {d1_:5.1f} {d2_:5.1f} {sl:6.2f} {vv['cool1']:5.1f} {vv['heat']:4.1f} {vv['cool2']:5.1f} {tau:8.0f}")
