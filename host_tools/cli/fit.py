"""`hdrg fit`: fit the 17-coefficient bias model to run logs (host_tools.api.fit: the defaults of
host_tools.fitting.fit_pipeline.fit_policy, the refusals); this module parses and prints."""
from __future__ import annotations

import argparse
import sys

from firmware_ref.terms import TERM_NAMES
from host_tools import api
from host_tools.cli.options import add_model_options, check_settle, example, out_option
from host_tools.fitting.fit import UnidentifiableError
from host_tools.fitting.fit_pipeline import check_terms, fit_policy
from host_tools.golden.reversal import schedule_ages_s


def print_identifiability(fit: dict) -> None:
    """What the training runs identify (model.fit["identifiability"]) and the guard's choice
    (model.fit["guard"]), as `hdrg fit` prints them."""
    ident = fit.get("identifiability")
    if ident:
        legs = ident.get("legs_per_temperature")
        if legs:
            head = (f"{legs['heating']} heating, {legs['cooling']} cooling legs; the {ident['proxy']} proxy rises when "
                    f"the device is {ident['proxy_rises_when']}")
        else:
            legs = ident.get("legs_per_sign", {})
            head = f"{legs.get('rising', 0)} rising, {legs.get('falling', 0)} falling legs of the proxy"
        print(f"what the training runs identify ({head}):")
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
    policy = fit_policy()
    parser.add_argument("runs", metavar="RUN", nargs="+", help="training run logs (CSV or .npz)")
    out_option(parser, "model JSON to write", required=True)
    add_model_options(parser)
    parser.add_argument("--drop-unidentifiable", action="store_true",
                        help="drop terms the data cannot identify (and report them) instead of refusing")
    parser.add_argument("--cv-blocks", type=int, default=policy.cv_blocks,
                        help=f"time blocks for 'auto' on a single run (default {policy.cv_blocks})")
    parser.add_argument("--force", action="store_true",
                        help=f"fit even with fewer than {policy.min_samples_per_term} valid samples per coefficient")
    example(parser, "hdrg fit run.csv -o model.json", "hdrg fit run_2cpm.csv run_4cpm.csv --terms auto -o model.json")


def _warn(message: str) -> None:
    print(f"hdrg fit: warning: {message}", file=sys.stderr)


def run(args) -> int:
    check_terms(args.terms)
    check_settle(args.settle)
    try:
        done = api.fit_with_result(args.runs, args.output, terms=args.terms, proxy=args.proxy,
                                   rate_estimator=args.rate_estimator, rate_n=args.rate_n, rate_shift=args.rate_shift,
                                   order=args.order, combiner=args.combiner, settle_s=args.settle,
                                   proxy_range=args.proxy_range, rate_range=args.rate_range,
                                   drop_unidentifiable=args.drop_unidentifiable, cv_blocks=args.cv_blocks,
                                   force=args.force)
    except UnidentifiableError as exc:
        raise UnidentifiableError(str(exc).replace("drop_unidentifiable=True", "--drop-unidentifiable (or --terms auto / "
                                                   "--terms k0,k1,...)"), exc.collinear) from None
    model, res, logs = done.model, done.result, done.logs
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
    turn = model.fit.get("turn_on")
    said = (model.fit.get("start_up") or {}).get("why", "").startswith("the power-on term")   # by the start-up warning
    if turn and (turn.get("chosen") or not said):
        se = f" +- {turn['size_stderr_dph']:.2g} (100-s means)" if turn.get("size_stderr_dph") is not None else ""
        print(f"power-on transient (time since power-on, k7): {turn['chosen'] or 'not learned'}{se} ({turn.get('why', '')})")
    print(f"{args.output}: {len(res.terms)} terms {['k%d' % k for k in res.terms]}, n={res.n}, "
          f"rms={res.rms:.4g} deg/h, cond={res.cond:.3g}")
    rev = model.config.reversal
    default_stale = fit_policy().max_stale_s
    if rev is not None and rev.max_stale_s != default_stale:
        oldest = max(schedule_ages_s(log.mode, log.segments, model.config.rate.fs).max(initial=0.0) for log in logs)
        print(f"mode reversal: max_stale_s {rev.max_stale_s:g} s (the training runs' windows reach {oldest:g} s "
              f"before the other mode's is renewed; the paper's 30 s / 120 s schedule needs 150 s, the default is "
              f"{default_stale:g} s)")
    if res.dropped:
        print(f"dropped as unidentifiable: {['k%d' % k for k in res.dropped]} (collinear: {res.collinear})")
    sys.stdout.flush()      # the warnings (stderr) after the lines above
    for w in done.warnings:
        _warn(w)
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
