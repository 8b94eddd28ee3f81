import numpy as np, matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from load import *
fig, axs = plt.subplots(5, 1, figsize=(12, 14), sharex=True)
for ax in "xy":
    c = load_tofu(ax); t = c["t_s"]
    axs[0 if ax=="x" else 1].plot(t, c["rate_dph"], lw=.3); axs[0 if ax=="x" else 1].set_ylabel(f"rate {ax}")
axs[2].plot(t, c["temp_c"]); axs[2].set_ylabel("T")
axs[3].plot(t[1:], np.diff(c["temp_c"])/np.diff(t)*60, lw=.3); axs[3].set_ylabel("dT/dt C/min")
for k in ["aux_acc_x","aux_acc_y","aux_acc_z"]:
    axs[4].plot(t, c[k]-np.median(c[k]), lw=.3, label=k)
axs[4].legend(); fig.savefig("look_tofu.png", dpi=70)
fig, axs = plt.subplots(2, 1, figsize=(10, 6))
for ax in "xy":
    c = load_tofu(ax); axs[0 if ax=="x" else 1].plot(c["temp_c"], c["rate_dph"], lw=.3)
fig.savefig("look_tofu_T.png", dpi=70)
