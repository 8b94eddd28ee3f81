"""Do the accelerometer channels themselves show leg-to-leg hysteresis vs temperature? cubic-in-T fit per channel,
mean residual per leg and the per-leg ratio gyro-residual/acc-residual. Usage: python acchyst.py"""
import numpy as np
from load import load_tofu
from common import cubic, fit_predict
c = load_tofu("x"); cy = load_tofu("y")
t, T = c["t_s"][1:], c["temp_c"][1:]; n = len(t); Tn = (T - 30) / 50
imin, imax = np.argmin(T), np.argmax(T); iend = imax + np.argmin(T[imax:])
legs = {"cool1": slice(0, imin), "heat": slice(imin, imax), "cool2": slice(imax, iend)}
ch = {"gyro_x": c["rate_dph"][1:], "gyro_y": cy["rate_dph"][1:]}
for k in ("aux_acc_x", "aux_acc_y", "aux_acc_z"): ch[k] = c[k][1:] * 1e3 / 9.80665   # mg
res = {k: v - fit_predict(cubic(Tn), v, np.ones(n, bool))[0] for k, v in ch.items()}
print("mean residual of a global cubic in T, per leg (gyro deg/h, acc mg); last col = corr with gyro_x / gyro_y residual")
for k, r in res.items():
    print(f"  {k:10s} " + "  ".join(f"{l}={r[s].mean():+7.2f}" for l, s in legs.items()) +
          f"   corr_x {np.corrcoef(r, res['gyro_x'])[0,1]:+.2f} corr_y {np.corrcoef(r, res['gyro_y'])[0,1]:+.2f}")
print("ratio of leg-mean residuals gyro/acc [deg/h per mg] (constant across legs => consistent proxy)")
for g in ("gyro_x", "gyro_y"):
    for k in ("aux_acc_x", "aux_acc_y", "aux_acc_z"):
        print(f"  {g}/{k}: " + "  ".join(f"{l}={res[g][s].mean()/res[k][s].mean():+6.2f}" for l, s in legs.items()))
