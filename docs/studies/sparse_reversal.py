"""How far sparse reversal can go on the foreign family: served share and held-out accuracy of a
gyroscope that runs in mode 1 and reverses once every P minutes, beside the paper's schedule and
FTR, and the bounds no sparse combiner can pass.

Per device (foreign family, the accuracy benchmark's protocol: train at 4 degC/min, power-on 0,
noise seed 0; hold out at 2 degC/min, power-on 1, noise seed 1): `hdrg fit`'s model
(host_tools.fitting.fit_pipeline.fit_default) on the paper-schedule training run, and the held-out
run simulated again under each schedule (host_tools.simulation.sim_physics.sparse_sequence: 30-s
exchanges, 45-s excursion windows, the first excursion right after power-on).  Scored from
power-on + 180 s on **every** sample: a sample without a valid output (exchange, settling, stale,
no correction yet) counts as not served; the metric is the std at 1 s of the served samples over
the device's noise floor (the benchmark's: the paper-schedule floor run, one mode's output).

Rows:

* ``ftr``: `hdrg fit`'s model of an FTR training run on the FTR held-out run (its own floor).
* ``paper``: the paper's schedule (30 s exchange, 120 s per mode) with `hdrg fit`'s model.
* ``sparse P offset``: the residual r = s x rate - B_mode of the same model; each excursion gives
  D = (mean r over the last 45 s of mode 1 before it - mean r over its mode-2 window) / 2, the
  damping term's change since calibration; the output is r - D in mode 1 and r + D in mode 2,
  from the first excursion on (D held between excursions).
* ``sparse P offset+gain``: D = a + g x dm, dm = the model's own damping term (bank 1 - bank 2)/2
  at the sample, (a, g) least squares over the run's excursions so far once their dm spans
  2 deg/h (offset only before).
* ``hindsight P``: the best offset + gain on dm for the whole held-out run, fitted on its mode-1
  samples after the fact (no causal combiner can do better with this correction family).
* ``perfect damping``: the model's common-mode error plus one mode's noise, i.e. the output of a
  combiner that knew the damping term exactly at every sample (the same run simulated in mode 1
  and in mode 2 throughout: (r1 + r2) / 2, plus the noise of the floor run).  Any output that
  passes the present sample at full bandwidth carries one mode's noise; the paper's pair averages
  two modes and halves it (its metric can go below 1).
* ``perfect damping and slow noise``: the same, with the noise's flicker and random walk known too
  (they do not flip sign with the mode, so an excursion sees them as damping): the common-mode
  error and the white noise alone, sqrt(var + white^2).

    python docs/studies/sparse_reversal.py --workers 2 > docs/studies/sparse_reversal.txt
    python docs/studies/sparse_reversal.py --startup 20 --workers 2 > docs/studies/sparse_reversal_startup.txt

The second command: the start-up benchmark's devices (`hdrg bench startup`: 20 devices, 4
power-ons each at constant ambient) under the paper's schedule and under sparse reversal.
"""
import argparse

import numpy as np

from host_tools.bench.accuracy import SEED_STRIDE, floor_of
from host_tools.bench.startup import EFFECT, STARTUPS, TRAIN_RUNS, ambient_of, calibration_runs
from host_tools.fitting.metrics import start_figures
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.golden.compensate import compensate, prepare
from host_tools.golden.reversal import combine
from host_tools.lot.parallel import map_ordered
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign
from host_tools.simulation.sim_physics import sparse_sequence

PERIODS_MIN = (5, 10, 20, 30, 45, 60)
EXCHANGE_S, WINDOW_S, SERVED_FROM_S = 30.0, 45.0, 180.0
GAIN_SPAN_DPH = 2.0
SET_DEVICES = {0: 50, 1: 40, 2: 40}   # the accuracy records' devices (docs/studies/accuracy_set*.json)


def sparse_output(mode, r, used, dm, gain: bool) -> np.ndarray:
    """The causal sparse combiner of the module doc: output [deg/h], NaN where not served."""
    n = len(r)
    out = np.full(n, np.nan)
    home, excursion, hist = [], [], []
    a = g = 0.0
    have = False
    for i in range(n):
        m = mode[i]
        if used[i] and m == 1:
            home.append(i)
            if have:
                out[i] = r[i] - (a + g * dm[i])
        elif used[i] and m == 2:
            excursion.append(i)
            if have:
                out[i] = r[i] + (a + g * dm[i])
        if m == 3 and excursion and i > 0 and mode[i - 1] == 2:        # an excursion's window closed
            w2 = np.array(excursion)
            w1 = np.array([k for k in home[-len(w2):] if k > w2[0] - 2 * (EXCHANGE_S + WINDOW_S)])
            excursion = []
            if len(w1) == 0:
                continue
            d = (r[w1].mean() - r[w2].mean()) / 2
            hist.append(((dm[w1].mean() + dm[w2].mean()) / 2, d))
            h = np.array(hist)
            if gain and np.ptp(h[:, 0]) > GAIN_SPAN_DPH:
                a, g = np.linalg.lstsq(np.c_[np.ones(len(h)), h[:, 0]], h[:, 1], rcond=None)[0]
            else:
                a, g = d - g * h[-1, 0], g
            have = True
    return out


def served_share(valid, t) -> float:
    """The share of the samples from power-on + SERVED_FROM_S that are ``valid``."""
    s = t >= SERVED_FROM_S
    return float((s & valid).sum() / s.sum())


def score(out, valid, t):
    """(served share, std of the served samples) from power-on + SERVED_FROM_S."""
    ok = (t >= SERVED_FROM_S) & valid
    return served_share(valid, t), float(np.std(out[ok])) if ok.sum() > 1 else float("nan")


def residual_parts(log, model):
    pr = prepare(log, model)
    ones = np.ones_like(pr.mode)
    b1, b2 = model.evaluate(pr.u, pr.v, pr.z, mode=ones), model.evaluate(pr.u, pr.v, pr.z, mode=2 * ones)
    r = pr.y - np.where(pr.mode == 2, b2, b1)
    return pr, r, (b1 - b2) / 2


def one_device(seed: int) -> dict:
    dev = foreign_device(seed)
    rec = {"seed": seed}
    # FTR, own floor
    ftr_model, _ = fit_default([simulate_foreign(dev, 4.0, False, 0, 0)])
    hold = simulate_foreign(dev, 2.0, False, 1, 1)
    ftr_floor = floor_of(simulate_foreign(dev, 2.0, False, 1, 1, thermal=False))
    out = compensate(hold, ftr_model)
    share, std = score(np.asarray(out.rate_dph), np.asarray(out["valid"]) > 0, np.asarray(hold.t_s))
    rec["ftr"] = (share, std / ftr_floor)
    # the paper's schedule
    model, _ = fit_default([simulate_foreign(dev, 4.0, True, 0, 0)])
    hold = simulate_foreign(dev, 2.0, True, 1, 1)
    t = np.asarray(hold.t_s)
    floor = floor_of(simulate_foreign(dev, 2.0, True, 1, 1, thermal=False))
    out = compensate(hold, model)
    share, std = score(np.asarray(out.rate_dph), np.asarray(out["valid"]) > 0, t)
    rec["paper"] = (share, std / floor)
    # perfect damping: the same run in mode 1 and in mode 2 throughout
    n = len(t)
    _, r1, _ = residual_parts(simulate_foreign(dev, 2.0, True, 1, 1, modes=np.ones(n, int)), model)
    _, r2, _ = residual_parts(simulate_foreign(dev, 2.0, True, 1, 1, modes=np.full(n, 2)), model)
    noise = simulate_foreign(dev, 2.0, True, 1, 1, thermal=False, modes=np.ones(n, int)).rate_dph
    ideal = (r1 + r2) / 2 + (noise - np.mean(noise))
    rec["perfect damping"] = (1.0, float(np.std(ideal[t >= SERVED_FROM_S])) / floor)
    eps = ((r1 + r2) / 2)[t >= SERVED_FROM_S]
    rec["perfect damping and slow noise"] = (1.0, float(np.sqrt(np.var(eps) + dev.noise["white_dph"] ** 2)) / floor)
    for p in PERIODS_MIN:
        log = simulate_foreign(dev, 2.0, True, 1, 1, modes=sparse_sequence(t, EXCHANGE_S, WINDOW_S, 60.0 * p))
        pr, r, dm = residual_parts(log, model)
        used = np.asarray(pr.used, bool)
        for label, gain in (("offset", False), ("offset+gain", True)):
            o = sparse_output(pr.mode, r, used, dm, gain)
            share, std = score(np.nan_to_num(o), np.isfinite(o), t)
            rec[f"sparse {p} min {label}"] = (share, std / floor)
        k = used & (pr.mode == 1) & (t >= SERVED_FROM_S)
        A = np.c_[np.ones(k.sum()), dm[k]]
        res = r[k] - A @ np.linalg.lstsq(A, r[k], rcond=None)[0]
        rec[f"hindsight {p} min"] = (served_share(k, t), float(np.std(res)) / floor)
    return rec


def one_startup_device(seed: int) -> dict:
    """The start-up benchmark's protocol (host_tools.bench.startup: its calibration runs, `hdrg fit`,
    STARTUPS power-ons of 45 min at constant ambient), each start-up simulated under the paper's
    schedule and under sparse reversal (the first excursion right after power-on, then every 45
    min): the start-up figures (host_tools.fitting.metrics.start_figures) of both outputs and their
    served shares from power-on + 180 s."""
    dev = foreign_device(seed)
    model, _ = fit_default(calibration_runs(dev))
    rows = []
    for k in range(STARTUPS):
        p = len(TRAIN_RUNS) + k
        amb = ambient_of(dev, p)
        paper = simulate_foreign(dev, 1.0, True, p, p, effect=EFFECT, ambient_c=amb)
        t = np.asarray(paper.t_s)
        out = compensate(paper, model)
        valid = np.asarray(out["valid"]) > 0
        row = {"paper": {**start_figures(t, np.asarray(out.rate_dph), valid), "served": served_share(valid, t)}}
        log = simulate_foreign(dev, 1.0, True, p, p, effect=EFFECT, ambient_c=amb,
                               modes=sparse_sequence(t, EXCHANGE_S, WINDOW_S, 2700.0))
        pr, r, dm = residual_parts(log, model)
        o = sparse_output(pr.mode, r, np.asarray(pr.used, bool), dm, True)
        row["sparse 45 min"] = {**start_figures(t, np.nan_to_num(o), np.isfinite(o)), "served": served_share(np.isfinite(o), t)}
        # the noise floors: the same start-ups without thermal terms, the paper's pairing of the raw
        # output (the start-up benchmark's floor) and one mode's output where sparse reversal serves
        fl = simulate_foreign(dev, 1.0, True, p, p, effect=EFFECT, ambient_c=amb, thermal=False)
        c = combine(fl, "pair")
        row["noise floor, paired"] = {**start_figures(t, c.out_dph, np.asarray(c.valid, bool)), "served": float("nan")}
        fl1 = simulate_foreign(dev, 1.0, True, p, p, effect=EFFECT, ambient_c=amb, thermal=False, modes=log.mode)
        c1 = np.where(fl1.mode == 2, -1.0, 1.0) * fl1.rate_dph
        row["noise floor, one mode"] = {**start_figures(t, c1, np.isfinite(o)), "served": float("nan")}
        rows.append(row)
    return {"seed": seed, "startups": rows}


def startup_table(recs) -> str:
    """Median over devices of the per-device median stability and of the rms of the 0-5 min means
    (repeatability), lowest served share, per schedule; the median per-device ratio sparse / paper."""
    lines = ["| schedule | stability (deg/h) | 0-5 min repeatability (deg/h) | served from 180 s, lowest |", "|---|---|---|---|"]
    per = {}
    for name in ("paper", "sparse 45 min", "noise floor, paired", "noise floor, one mode"):
        stab = [np.median([s[name]["stability"] for s in r["startups"]]) for r in recs]
        rep = [np.sqrt(np.mean([s[name]["turn_on"] ** 2 for s in r["startups"]])) for r in recs]
        served = min(s[name]["served"] for r in recs for s in r["startups"])
        per[name] = np.array(stab)
        cell = "-" if not np.isfinite(served) else f"{100 * served:.1f} %"
        lines.append(f"| {name} | {np.median(stab):.3f} | {np.median(rep):.3f} | {cell} |")
    ratio = per["sparse 45 min"] / per["paper"]
    lines.append(f"\nstability ratio sparse / paper per device: median {np.median(ratio):.2f}, "
                 f"max {np.max(ratio):.2f}, above 1.2 on {int(np.sum(ratio > 1.2))} of {len(ratio)} devices")
    return "\n".join(lines)


def table(recs_by_set) -> str:
    rows = list(recs_by_set[0][1][0].keys())[1:]
    head = "| pipeline | " + " | ".join(f"set {s}: served (lowest) | median | p90" for s, _ in recs_by_set) + " |"
    lines = [head, "|---" * (1 + 3 * len(recs_by_set)) + "|"]
    for row in rows:
        cells = []
        for _, recs in recs_by_set:
            v = np.array([r[row] for r in recs], float)
            cells += [f"{100 * v[:, 0].min():.1f} %", f"{np.median(v[:, 1]):.2f}", f"{np.percentile(v[:, 1], 90):.2f}"]
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sets", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--devices", type=int, default=None, help="per set (default: the accuracy records' 50, 40, 40)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--startup", type=int, default=0, metavar="N",
                    help="instead: the start-up benchmark's first N devices of set 0 under both schedules")
    a = ap.parse_args()
    if a.startup:
        recs = map_ordered(one_startup_device, list(range(a.startup)), a.workers)
        print(f"start-ups, set 0, {a.startup} devices x {STARTUPS} power-ons at constant ambient (45 min), "
              f"`hdrg fit` on the start-up benchmark's calibration runs; figures from power-on + 180 s\n")
        print(startup_table(recs))
        return
    out = []
    for s in a.sets:
        seeds = [s * SEED_STRIDE + i for i in range(a.devices or SET_DEVICES.get(s, 40))]
        out.append((s, map_ordered(one_device, seeds, a.workers)))
    print(", ".join(f"set {s}: {len(r)} devices" for s, r in out) + "; served share and held-out std at 1 s / floor, from power-on + "
          f"{SERVED_FROM_S:g} s (a sample with no valid output counts as not served)\n")
    print(table(out))


if __name__ == "__main__":
    main()
