"""`hdrg fit`: fit the 17-coefficient bias model to run logs (host_tools.fitting.fit)."""
from __future__ import annotations

import argparse

import numpy as np

from firmware_ref.terms import TERM_NAMES
from host_tools.cli.options import add_model_options
from host_tools.fitting.fit import MIN_SAMPLES_PER_TERM, UnidentifiableError, fit_auto_rate, fit_logs
from host_tools.fitting.fit_pipeline import fit_default


# What `hdrg fit` says when it is given several runs (model.json fit.several_runs, and the console).
SEVERAL_RUNS_NOTE = (
    "one coefficient set is fitted to all of them, and the cross-validation leaves one run out. Measured on "
    "foreign devices (docs/ACCURACY.md, 'Several training runs'): runs from DIFFERENT power-ons made the "
    "held-out error worse on average (the power-on damping change is not modelled), runs at ONE chamber "
    "rate too (leaving one out cannot see the extrapolation to another rate); runs at different chamber "
    "rates from ONE power-on made it better. Check the model on a held-out run (hdrg report)")


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
    from host_tools.golden.checks import check_fit_inputs
    from host_tools.golden.compensate import fit_config_from_logs

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
        elif args.rate_estimator == "auto":
            model, res = fit_auto_rate(logs, args.terms, cv_blocks=args.cv_blocks, **kw)
        else:
            cfg = fit_config_from_logs(logs, rate_estimator=args.rate_estimator, n=args.rate_n, shift=args.rate_shift, **kw)
            model, res = fit_logs(logs, cfg, args.terms, drop_unidentifiable=args.drop_unidentifiable,
                                  cv_blocks=args.cv_blocks)
        sel = model.fit.get("rate_selection")
        if sel:
            print(f"rate estimator auto: {sel['chosen']} (" + ", ".join(
                f"{r['estimator']} {r['cv_rms']:.4g}" if "cv_rms" in r else f"{r['estimator']} failed"
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
    if res.dropped:
        print(f"dropped as unidentifiable: {['k%d' % k for k in res.dropped]} (collinear: {res.collinear})")
    weak = model.fit.get("insignificant", [])
    if weak:
        print(f"warning: the data do not identify {['k%d' % k for k in weak]} (|coef| < 2 standard errors); "
              f"they fit noise: consider --terms auto")
    if len(logs) > 1:
        print(f"warning: {len(logs)} training runs: {SEVERAL_RUNS_NOTE}")
    if res.cv:
        print(f"cross-validated rms: {res.cv['cv_rms']:.4g} deg/h over {res.cv['groups']} groups")
    for k in res.terms:
        print(f"  k{k:<2d} {TERM_NAMES[k]:>9s} = {res.coef[k]: .6g} +- {res.stderr[k]:.2g} deg/h"
              + ("" if res.coef_mode2 is None else
                 f"   (mode 2: {res.coef_mode2[k]: .6g} +- {res.stderr_mode2[k]:.2g})"))
    return 0
