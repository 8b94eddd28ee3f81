# Measurement script of docs/ACCURACY.md "What the tail needs" (not part of the package).
# Usage: [LEADS=sensor] [LEAD_RULE=flat] PYTHONPATH=. python docs/lag/lead_block.py SET mr|ftr START STOP 2>> rows.jsonl
"""Prototype (float only): LEAD blocks beside the lag-state block's candidates.  A thermal node
upstream of the one a channel sits on is a lead of that channel: one first-order lag a further,
x = (1 + a s) / (1 + c s) T, c = 60 s (a proper filter: the section is L + (a / c)(T - L), L the
first-order low-pass of T with tau c); two lags further, the same section twice (a, b).  Leads of
the temperature sensor (a in LEAD_SENSOR) and of the proxy (pairs (a, b) of LEAD_PROXY) enter the
default fit as lag-block candidates x^1..2 / x^1..3 (tau 0) AFTER the usual lag block
(host_tools.fitting.fit_lag.add_lag_block, unchanged): the leads are screened alone, the top 2
refitted, and the best replaces the usual result only when its cross-validated rms beats the usual
result's by the lag margin (0.1 MR, 0.2 FTR).  One JSON line per device: held-out std / floor of
the default fit and of the fit with lead candidates, and what each chose."""
import json
import os
import sys
import numpy as np
from host_tools.fitting import fit_lag as FL, fit_pipeline as FP
from host_tools.golden.regressors import lowpass, _seg_start
from host_tools.golden.runlog import RunLog
from host_tools.bench.accuracy import device_runs, heldout_ratio, damping_change_dph
from host_tools.simulation.sim_foreign import foreign_device

C = 60.0
LEAD_SENSOR = (120.0, 240.0, 480.0, 960.0, 1920.0)
LEAD_PROXY = [(a, b) for a in (240.0, 480.0, 960.0, 1920.0) for b in (0.0, 240.0, 480.0, 960.0, 1920.0) if b <= a]
if os.environ.get("LEADS") == "sensor":     # LEADS=sensor: leads of the sensor only
    LEAD_PROXY = []
SET_BASE = {0: 0, 1: 100000, 2: 200000}


def section(y, seg, a):
    return y if a == 0 else (a / C) * y + (1.0 - a / C) * lowpass(y, seg, C, 1.0)


def lead_columns(log):
    seg = _seg_start(log)
    f = np.asarray(log.columns["freq_hz"], float)
    u = -(f / np.median(f) - 1.0) / 20.9e-6        # the proxy in degC (offset irrelevant)
    T = np.asarray(log.columns["temp_c"], float)
    out = {f"aux_ls{int(a)}": section(T, seg, a) for a in LEAD_SENSOR}
    out.update({f"aux_lp{int(a)}_{int(b)}": section(section(u, seg, a), seg, b) for a, b in LEAD_PROXY})
    return out


def with_leads(log):
    cols = dict(log.columns); cols.update(lead_columns(log))
    return RunLog.from_arrays(metadata=dict(log.metadata), source=log.source, **cols)


def add_lag_block_flat(logs, model, res, terms=None, *, cv_blocks=8, drop_unidentifiable=True, **_):
    """LEAD_RULE=flat (tried first): the lead candidates in the SAME screen as the usual ones, the
    usual top-2 refit and margin against the base without a lag block."""
    kind = "ftr" if model.config.reversal is None else "mr"
    margin, top, gate = FL.LAG_MARGIN[kind], FL.LAG_REFIT_TOP, FL.LAG_SCREEN_GATE[kind]
    if model.config.aux.generator != "none":
        return model, res
    sc = FL.screen(logs, model, cv_blocks=cv_blocks)
    rows = [dict(r, sensor=sc["sensor"], coefs=sc["coefs"]) for r in sc["rows"]] + _lead_rows(logs, model, cv_blocks)
    base_cv = (res.cv or {}).get("cv_rms")
    if not rows or base_cv is None:
        return model, res
    ranked = sorted(rows, key=lambda r: r["screen_cv_rms"])[:top]
    if gate is not None:
        ranked = [r for r in ranked if r["screen_cv_rms"] < (1.0 - gate) * sc["base"]]
    best = _refit_best(logs, model, ranked, terms, cv_blocks, drop_unidentifiable)
    if best is None or not best[0] < (1.0 - margin) * base_cv:
        return model, res
    return _keep(model, model, best)


def _lead_rows(logs, model, cv_blocks):
    """Screen rows of every lead column (tau 0, orders 2 and 3), each with its source and coefs."""
    rows = []
    orig = FL.sensor_source
    try:
        for col in [c for c in logs[0].columns if c.startswith("aux_l")]:
            x = np.concatenate([np.asarray(lg.columns[col], float) for lg in logs])
            lo, hi = float(x.min()), float(x.max())
            src = (col, 0.5 * (lo + hi), 0.5 * (hi - lo) * (1 + 2 * FL.SENSOR_MARGIN))
            FL.sensor_source = lambda lg, cf, src=src: src
            s2 = FL.screen(logs, model, cv_blocks=cv_blocks, taus=(), sensor_taus=(0.0,))
            rows += [dict(r, block=r["block"].replace("T,", col + ","), sensor=src, coefs=s2["coefs"]) for r in s2["rows"]]
    finally:
        FL.sensor_source = orig
    return rows


def _refit_best(logs, model, ranked, terms, cv_blocks, drop_unidentifiable):
    """(cv rms, label, model, FitResult) of the best refit of the ``ranked`` rows, or None."""
    from host_tools.fitting.fit import fit_logs
    best = None
    for r in ranked:
        cfg2 = FL.lag_config(model.config, r["cand"], r["coefs"](r["cand"]), r["sensor"])
        if cfg2 is None:
            continue
        try:
            m2, r2 = fit_logs(logs, cfg2, terms, cv_blocks=cv_blocks, blocks=True,
                              drop_unidentifiable=drop_unidentifiable, min_gain=0.02)
        except ValueError:
            continue
        if best is None or r2.cv["cv_rms"] < best[0]:
            best = (r2.cv["cv_rms"], r["block"], m2, r2)
    return best


def _keep(model, usual, best):
    m2, r2 = best[2], best[3]
    if "rate_selection" in model.fit:
        m2.fit["rate_selection"] = model.fit["rate_selection"]
    m2.fit["lag_block"] = dict(usual.fit.get("lag_block", {}), chosen=best[1], cv_rms=best[0])
    return m2, r2


def add_lag_block_leads(logs, model, res, terms=None, *, cv_blocks=8, drop_unidentifiable=True, **kw):
    """The usual lag block (FL.add_lag_block), then the lead candidates alone: screened, the top
    LAG_REFIT_TOP refitted, the best kept only when its cross-validated rms beats the USUAL result's
    by the lag margin again (a lead is one more filter in the firmware: it must pay for itself)."""
    kind = "ftr" if model.config.reversal is None else "mr"
    if model.config.aux.generator != "none":
        return model, res
    usual, ures = FL.add_lag_block(logs, model, res, terms, cv_blocks=cv_blocks, drop_unidentifiable=drop_unidentifiable)
    rows = _lead_rows(logs, model, cv_blocks)
    ucv = (ures.cv or {}).get("cv_rms")
    if not rows or ucv is None:
        return usual, ures
    best = _refit_best(logs, model, sorted(rows, key=lambda r: r["screen_cv_rms"])[:FL.LAG_REFIT_TOP], terms,
                       cv_blocks, drop_unidentifiable)
    if best is None or not best[0] < (1.0 - FL.LAG_MARGIN[kind]) * ucv:
        return usual, ures
    return _keep(model, usual, best)


def main():
    st, kind, a, b = int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    for seed in range(SET_BASE[st] + a, SET_BASE[st] + b):
        dev = foreign_device(seed)
        tr, ho, fl = device_runs(dev, kind == "mr")
        m0, r0 = FP.fit_default([tr])
        tr2, ho2 = with_leads(tr), with_leads(ho)
        saved = FP.add_lag_block
        FP.add_lag_block = add_lag_block_flat if os.environ.get("LEAD_RULE") == "flat" else add_lag_block_leads
        try:
            m1, r1 = FP.fit_default([tr2])
        finally:
            FP.add_lag_block = saved
        rec = {"seed": seed, "kind": kind, "dc": damping_change_dph(dev),
               "base": heldout_ratio(m0, ho, fl), "base_cv": r0.cv["cv_rms"], "base_chosen": m0.fit.get("lag_block", {}).get("chosen"),
               "lead": heldout_ratio(m1, ho2, fl), "lead_cv": r1.cv["cv_rms"], "lead_chosen": m1.fit.get("lag_block", {}).get("chosen")}
        print(json.dumps(rec), file=sys.stderr, flush=True)
        print(seed, kind, "%.2f -> %.2f" % (rec["base"], rec["lead"]), rec["base_chosen"], "->", rec["lead_chosen"], flush=True)


if __name__ == "__main__":
    main()
