"""`hdrg fit`: fit the 17-coefficient bias model to run logs (host_tools.fitting.fit)."""
from __future__ import annotations

import argparse

import numpy as np

from firmware_ref.terms import TERM_NAMES
from host_tools.cli.options import add_model_options
from host_tools.fitting.fit import MIN_SAMPLES_PER_TERM, UnidentifiableError, fit_logs
from host_tools.fitting.fit_rate import fit_auto_rate
from host_tools.fitting.fit_pipeline import fit_default, fit_without_run_offsets
from host_tools.golden.reversal import DEFAULT_MAX_STALE_S, schedule_ages_s


# What `hdrg fit` says when it is given several runs (model.json fit.several_runs, and the console).
SEVERAL_RUNS_NOTE = (
    "one coefficient set is fitted to all of them. The offset of each run (per coefficient bank: what a "
    "power-on changes in the turn-on and damping offsets) is removed first (model.json fit.run_offsets); "
    "its change of the damping SCALE is not modelled, and the cross-validation leaves one run out. Measured "
    "on foreign devices (docs/ACCURACY.md, 'Several training runs'): a second run at ANOTHER chamber rate "
    "made the held-out error smaller (MR x0.89 .. x0.93, FTR x0.75 .. x0.86), one at the SAME rate larger for mode "
    "reversal (x1.14 .. x1.43). Record the runs at different chamber rates, and check the model on a "
    "held-out run (hdrg report)")


def print_identifiability(fit: dict) -> None:
    """What the training runs identify (model.fit["identifiability"]) and the guard's choice
    (model.fit["guard"]), as `hdrg fit` prints them."""
    ident = fit.get("identifiability")
    if ident:
        legs = ident.get("legs_per_sign", {})
        print(f"what the training runs identify ({legs.get('rising', 0)} rising, {legs.get('falling', 0)} falling legs of "
              f"the proxy):")
        for group, g in ident["groups"].items():
            print(f"  {group:15s} {'identified' if g['identified'] else 'NOT identified'}: {g['why']}"
                  + (f"; to identify it, record {g['record']}" if g["record"] else ""))
    guard = fit.get("guard")
    if guard:
        cv = guard.get("cv_rms")
        scores = (" (leave-one-leg-out rms: " + ", ".join(f"{k} {v:.4g}" for k, v in cv.items()) + " deg/h; "
                  f"{guard.get('out_of_range', 0)} held-out samples beyond the other legs' range not scored)") if cv else ""
        print(f"model kept: {guard['chosen']}: {guard['why']}{scores}")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", metavar="RUN", nargs="+", help="training run logs (CSV or .npz)")
    parser.add_argument("-o", "--output", required=True, help="model JSON to write")
    add_model_options(parser)
    parser.add_argument("--drop-unidentifiable", action="store_true",
                        help="drop terms the data cannot identify (and report them) instead of refusing")
    parser.add_argument("--cv-blocks", type=int, default=8, help="time blocks for 'auto' on a single run")
    parser.add_argument("--force", action="store_true",
                        help=f"fit even with fewer than {MIN_SAMPLES_PER_TERM} valid samples per coefficient")


def run(args) -> int:
    from host_tools.golden import runlog
    from host_tools.atomic import refuse_overwrite
    from host_tools.golden.checks import check_fit_inputs, coverage_warnings
    from host_tools.golden.compensate import compensate, fit_config_from_logs
    from host_tools.golden.flags import problems

    refuse_overwrite(args.output, args.runs)
    logs = [runlog.read(p) for p in args.runs]
    check_fit_inputs(logs, args.proxy)
    reversal = ({"combiner": args.combiner, "settle_s": args.settle, "order": args.order}
                if any(log.reversal for log in logs) else None)
    kw = dict(proxy_kind=args.proxy, proxy_range=args.proxy_range, rate_range=args.rate_range, reversal=reversal)
    default = args.rate_estimator is None and args.rate_n is None and args.rate_shift is None
    try:
        if default:
            # what the benchmark picked (host_tools.fitting.fit_pipeline.fit_default): rate auto for mode-reversal logs,
            # the lag-state block of the proxy or the sensor when cross-validation supports it
            model, res = fit_default(logs, args.terms, drop_unidentifiable=args.drop_unidentifiable,
                                     cv_blocks=args.cv_blocks, **kw)
        else:
            if args.rate_estimator == "auto":
                def fit(lg):
                    return fit_auto_rate(lg, args.terms, cv_blocks=args.cv_blocks, **kw)
            else:
                cfg = fit_config_from_logs(logs, rate_estimator=args.rate_estimator, n=args.rate_n,
                                           shift=args.rate_shift, **kw)

                def fit(lg):
                    return fit_logs(lg, cfg, args.terms, drop_unidentifiable=args.drop_unidentifiable,
                                    cv_blocks=args.cv_blocks)
            # several runs: per-run offsets removed as fit_default does
            model, res = fit_without_run_offsets(logs, fit)
        sel = model.fit.get("rate_selection")
        if sel:
            print(f"rate estimator auto: {sel['chosen']} (" + ", ".join(
                f"{r['estimator']} {r['cv_rms']:.4g}" if "cv_rms" in r else f"{r['estimator']} failed: {r.get('error', '?')}"
                for r in sel["candidates"]) + " deg/h cross-validated rms)")
        lag = model.fit.get("lag_block")
        if lag and lag.get("chosen"):
            print(f"lag-state block (u: proxy, T: sensor): {lag['chosen']} (cross-validated rms "
                  f"{lag['base_cv_rms']:.4g} -> {lag['cv_rms']:.4g} deg/h)")
        elif lag:
            why = lag.get("error") or f"no candidate lowered the cross-validated rms by {100 * lag['margin']:.0f} %"
            print(f"lag-state block (u: proxy, T: sensor): not kept ({why})")
    except UnidentifiableError as exc:
        raise ValueError(str(exc).replace("drop_unidentifiable=True", "--drop-unidentifiable (or --terms auto / "
                                          "--terms k0,k1,...)")) from None
    if res.dof <= 0 or not np.all(np.isfinite(res.stderr)):
        raise ValueError(f"{res.n} valid samples for {len(res.terms)} coefficients: no degrees of freedom left, "
                         f"the error bars are undefined; record more data or fit fewer terms (--terms)")
    if res.n < MIN_SAMPLES_PER_TERM * len(res.terms) and not args.force:
        raise ValueError(f"{res.n} valid samples for {len(res.terms)} coefficients (fewer than "
                         f"{MIN_SAMPLES_PER_TERM} per coefficient): the fit would follow the noise; record more "
                         f"data, fit fewer terms (--terms), or pass --force")
    if len(logs) > 1:
        model.fit["several_runs"] = SEVERAL_RUNS_NOTE
    model.to_json(args.output)
    print(f"{args.output}: {len(res.terms)} terms {['k%d' % k for k in res.terms]}, n={res.n}, "
          f"rms={res.rms:.4g} deg/h, cond={res.cond:.3g}")
    rev = model.config.reversal
    if rev is not None and rev.max_stale_s != DEFAULT_MAX_STALE_S:
        oldest = max(schedule_ages_s(log.mode, log.segments, model.config.rate.fs).max(initial=0.0) for log in logs)
        print(f"mode reversal: max_stale_s {rev.max_stale_s:g} s (the training runs' windows reach {oldest:g} s "
              f"before the other mode's is renewed; the paper's 30 s / 120 s schedule needs 150 s, the default is "
              f"{DEFAULT_MAX_STALE_S:g} s)")
    if res.dropped:
        print(f"dropped as unidentifiable: {['k%d' % k for k in res.dropped]} (collinear: {res.collinear})")
    weak = model.fit.get("insignificant", [])
    if weak:
        print(f"warning: the data do not identify {['k%d' % k for k in weak]} (|coef| < 2 standard errors); "
              f"they fit noise: consider --terms auto")
    if len(logs) > 1:
        print(f"warning: {len(logs)} training runs: {SEVERAL_RUNS_NOTE}")
    for w in coverage_warnings(logs, args.proxy):
        print(f"warning: {w}")
    for log in logs:   # e.g. --proxy-range / --rate-range narrower than the data: the fit saw clamped inputs
        for m in problems(compensate(log, model)):
            print(f"warning: training run {log.source}: {m}")
    if tuple(res.terms) == (0,) and args.terms in (None, "auto"):
        print("warning: term selection kept only the offset k0: no temperature term held out in the "
              "cross-validation; the model does not compensate temperature (see the warnings above, or fix the "
              "terms with --terms)")
    print_identifiability(model.fit)
    offs = model.fit.get("run_offsets")
    if offs and "why" in offs:
        print(f"per-run offsets: not removed ({offs['why']})")
    elif offs:
        print("per-run offsets removed before the fit [deg/h" + (", mode 1 / mode 2" if len(offs["offsets_dph"][0]) == 2
                                                               else "") + "]: " + "; ".join(
            f"{src} " + " / ".join(f"{o:+.4g}" for o in per) for src, per in zip(offs["runs"], offs["offsets_dph"])))
    if res.cv:
        print(f"cross-validated rms: {res.cv['cv_rms']:.4g} deg/h over {res.cv['groups']} groups")
    for k in res.terms:
        print(f"  k{k:<2d} {TERM_NAMES[k]:>9s} = {res.coef[k]: .6g} +- {res.stderr[k]:.2g} deg/h"
              + ("" if res.coef_mode2 is None else
                 f"   (mode 2: {res.coef_mode2[k]: .6g} +- {res.stderr_mode2[k]:.2g})"))
    return 0
