"""Held-out analysis of tofupilot IMU thermal cycle. Usage: python tofu.py [x|y] -> tofu_<ax>.tsv + stdout."""
import sys, json
import numpy as np
from load import load_tofu
from common import *

ax = sys.argv[1] if len(sys.argv) > 1 else "x"
c = load_tofu(ax)
sl = slice(1, None)            # sample 0 is a power-on glitch (rate -170 vs -254, T 51.6 vs 52.1)
t, y, T = c["t_s"][sl], c["rate_dph"][sl], c["temp_c"][sl]
acc = np.column_stack([c[k][sl] for k in ("aux_acc_x", "aux_acc_y", "aux_acc_z")])
n = len(t)
Tn = (T - 30) / 50
# legs by the turning points: cool1 = start..Tmin, heat = Tmin..Tmax, cool2 = Tmax..final minimum;
# the final 47-s upturn (94 samples, 34->36 C) belongs to neither leg (it is in the blk5 folds); see labelcheck.py
imin, imax = np.argmin(T), np.argmax(T); iend = imax + np.argmin(T[imax:])
cool = np.zeros(n, bool); cool[:imin] = True; cool[imax:iend] = True
heat = np.zeros(n, bool); heat[imin:imax] = True
nb = 5; edges = np.linspace(t[0], t[-1] + 1e-9, nb + 1)
blk = [((t >= edges[i]) & (t < edges[i+1])) for i in range(nb)]
c1 = np.zeros(n, bool); c1[:imin] = True; c2 = np.zeros(n, bool); c2[imax:iend] = True
SPLITS = {"C->H": [(cool, heat)], "H->C": [(heat, cool)],
          "c1h->c2": [(c1 | heat, c2)], "hc2->c1": [(heat | c2, c1)],
          "blk5": [(~b, b) for b in blk]}

L = {tau: lag(t, T, tau) for tau in (3, 10, 20, 30, 50, 70, 100, 150, 200, 300, 500, 700, 1000, 2000)}
V = {"d1": d1(t, T)}
for tau in (30, 100, 300, 1000): V[f"iir{tau}"] = (T - L[tau]) / tau * 60
for W in (10, 30, 100): V[f"ls{W}"] = d_ls(t, T, W)
th = t / t[-1]
models = {"raw(mean)": None, "cubicT": cubic(Tn)}
for kname, v in V.items():
    models[f"p16[{kname}]"] = p16(Tn, v / 3)
    models[f"cubicT+v[{kname}]"] = np.column_stack([cubic(Tn), v / 3])
for tau, l in L.items():
    ln = (l - 30) / 50
    models[f"cubicLag[{tau}]"] = cubic(ln)
    models[f"lagpoly[{tau}]"] = np.column_stack([cubic(Tn), ln, ln**2, ln * Tn])
    models[f"cubicT+(T-L)[{tau}]"] = np.column_stack([cubic(Tn), Tn - ln])
an = (acc - acc.mean(0)) / acc.std(0)
models["cubicT+acc_xyz"] = np.column_stack([cubic(Tn), an])
for j, nm in enumerate("xyz"): models[f"cubicT+acc_{nm}"] = np.column_stack([cubic(Tn), an[:, j]])
models["cubic(acc_z) only"] = cubic(an[:, 2])
models["cubicT+t"] = np.column_stack([cubic(Tn), th])
models["cubicT+t+t2"] = np.column_stack([cubic(Tn), th, th**2])
for tau0 in (100, 300, 1000): models[f"cubicT+exp(-t/{tau0})"] = np.column_stack([cubic(Tn), np.exp(-t / tau0)])
sbr = np.tanh(d_ls(t, T, 60) / 0.5)      # causal branch indicator (+1 heating, -1 cooling)
models["cubicT+branch(s,sT)"] = np.column_stack([cubic(Tn), sbr, sbr * Tn])
models["cubicT+branch(s,sT,sT2)"] = np.column_stack([cubic(Tn), sbr, sbr * Tn, sbr * Tn**2])
models["cubicT+acc_y+(T-L)[200]"] = np.column_stack([cubic(Tn), an[:, 1], Tn - (L[200]-30)/50])
models["cubicT+acc_xyz+(T-L)[200]"] = np.column_stack([cubic(Tn), an, Tn - (L[200]-30)/50])
models["cubicT+lag(acc_y,200)"] = np.column_stack([cubic(Tn), lag(t, an[:, 1], 200)])
models["cubicT+t+(T-L)[100]"] = np.column_stack([cubic(Tn), th, Tn - (L[100]-30)/50])

rows = []
for name, X in models.items():
    for sp, splits in SPLITS.items():
        r, tm, conds = heldout(t, y, X, splits)
        m = metrics(t, r, tm)
        # in-sample RSS on the training part (for selecting tau without peeking)
        ins = np.mean([np.std((y - fit_predict(X, y, tr)[0])[tr]) for tr, te in splits])
        rows.append(dict(axis=ax, model=name, split=sp, cond=float(np.max(conds)), train_std=ins, **m))
# tau selected on the TRAINING fit only (no peeking at the held-out part), per family and split
for fam in ("cubicLag", "lagpoly", "cubicT+(T-L)"):
    for sp in SPLITS:
        cand = [r for r in rows if r["model"].startswith(fam + "[") and r["split"] == sp]
        b = min(cand, key=lambda r: r["train_std"]); o = min(cand, key=lambda r: r["rms1"])
        rows.append(dict(b, model=f"{fam}[train-sel tau={b['model'].split('[')[1][:-1]}]"))
        rows.append(dict(o, model=f"{fam}[oracle tau={o['model'].split('[')[1][:-1]}]"))
import csv
with open(f"tofu_{ax}.tsv", "w") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0]), delimiter="\t"); w.writeheader()
    for r in rows: w.writerow({k: (f"{v:.3f}" if isinstance(v, float) else v) for k, v in r.items()})
print(f"axis {ax}: n={n}, cooling {cool.sum()} heating {heat.sum()} samples")
print(f"{'model':28s} {'split':5s} {'mean':>7s} {'s1':>7s} {'s10':>7s} {'s100':>7s} {'rms1':>7s} {'trn':>6s} {'cond':>8s}")
for r in rows:
    print(f"{r['model']:28s} {r['split']:5s} {r['mean']:7.2f} {r['s1']:7.2f} {r['s10']:7.2f} {r['s100']:7.2f} {r['rms1']:7.2f} {r['train_std']:6.2f} {r['cond']:8.1e}")
