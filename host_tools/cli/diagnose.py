"""`hdrg diagnose`: trace a model's residual to a missing effect and add it (host_tools.api.diagnose over
host_tools.fitting.diagnose)."""
from __future__ import annotations

import argparse
import math
import os
import sys

from host_tools import api
from host_tools.cli.options import OUT_OPTIONS, add_model_options, check_settle, example
from host_tools.fitting.diagnose import CV_BLOCKS, CV_FOLDS, G_MIN, MAX_ITER, N_SURROGATES, fmt_value
from host_tools.fitting.diagnose_scan import TRIES_PER_STEP
from host_tools.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", metavar="RUN", nargs="+", help="training run logs (CSV or .npz)")
    parser.add_argument("--holdout", nargs="+", default=[], metavar="RUN",
                        help="held-out run logs: the errors before/after are reported on them")
    parser.add_argument(*OUT_OPTIONS, dest="out", required=True, metavar="DIR",
                        help="output directory (diagnose.md, diagnose.json, model.json, PNG)")
    parser.add_argument("--json", default=None, metavar="FILE", help="also write the JSON report to FILE")
    add_model_options(parser, "the starting model")
    parser.add_argument("--max-iter", type=int, default=MAX_ITER,
                        help=f"most steps kept per phase (default {MAX_ITER}; a step the held-out runs do not confirm is "
                             f"reverted and counts against --max-tries only)")
    parser.add_argument("--max-tries", type=int, default=None,
                        help=f"most steps tried per phase (default {TRIES_PER_STEP} x --max-iter)")
    parser.add_argument("--surrogates", type=int, default=N_SURROGATES,
                        help=f"surrogate residuals for the significance threshold (default {N_SURROGATES})")
    parser.add_argument("--g-min", type=float, default=G_MIN, help=f"minimum CV gain (default {G_MIN})")
    parser.add_argument("--cv-blocks", type=int, default=CV_BLOCKS, help="single run: contiguous CV blocks")
    parser.add_argument("--cv-folds", type=int, default=CV_FOLDS, help="single run: folds the blocks are dealt into")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the surrogates")
    parser.add_argument("--no-plots", action="store_true", help="no PNG figures")
    example(parser, "hdrg diagnose run.csv --holdout held_out.csv -o diagnose/")


def run(args) -> int:
    from host_tools.golden import runlog as rl
    from host_tools.atomic import atomic_open, refuse_overwrite
    from host_tools.golden.checks import check_fit_inputs

    check_options(args)
    refuse_overwrite([args.json] + [os.path.join(args.out, f) for f in ("model.json", "diagnose.json", "diagnose.md")],
                     list(args.runs) + list(args.holdout))
    train = [rl.read(p) for p in args.runs]
    hold = [rl.read(p) for p in args.holdout]
    check_fit_inputs(train + hold, args.proxy)
    print(f"hdrg diagnose: {len(train)} training run(s), {len(hold)} held-out; fitting and tracing the residual "
          f"(up to {args.max_iter} iteration(s), {args.surrogates} surrogates each; this takes a while) ...",
          file=sys.stderr, flush=True)
    report, model = api.diagnose(train, hold, proxy=args.proxy, rate_estimator=args.rate_estimator,
                                 rate_n=args.rate_n, rate_shift=args.rate_shift, terms=args.terms,
                                 combiner=args.combiner, order=args.order, settle_s=args.settle, proxy_range=args.proxy_range,
                                 rate_range=args.rate_range, max_iter=args.max_iter, max_tries=args.max_tries, n_surrogates=args.surrogates,
                                 g_min=args.g_min, cv_blocks=args.cv_blocks, cv_folds=args.cv_folds,
                                 seed=args.seed, out_dir=args.out, plots=not args.no_plots,
                                 progress=lambda msg: print(f"hdrg diagnose: {msg}", file=sys.stderr, flush=True))
    if args.json:
        with open(os.path.join(args.out, "diagnose.json"), encoding="utf-8") as src, \
                atomic_open(args.json, "w", encoding="utf-8") as dst:
            dst.write(src.read())
    on = "held-out" if hold else "training"
    base = report["baseline"][report["evaluated_on"]]
    print(f"hdrg diagnose: {report['verdict']} ({on} runs; std 1 s / std 100 s in deg/h)")
    print(f"  base model (hdrg fit's): {fmt_value(base['std_dph'])} / {fmt_value(base['std100_dph'])}")
    for k, it in enumerate(report["iterations"], 1):
        params = ", ".join(f"{a}={fmt_value(b) if isinstance(b, float) else b}" for a, b in it["params"].items())
        print(f"  {k}. {it['effect']} ({params}): {fmt_value(it['after']['std_dph'])} / {fmt_value(it['after']['std100_dph'])}"
              f"  [CV gain {it['cv_gain']:.3f} >= {it['threshold']:.3f}; {it['status']}]")
    print(f"  {report['verdict_detail']}")
    if (report.get("taken_from_fit") or {}).get("text"):
        print(f"  note: {report['taken_from_fit']['text']}")
    for m in report.get("not_scanned") or []:
        print(f"  note: not scanned: {m}")
    if report.get("several_runs"):
        print(f"  note: {report['several_runs']}")
    for a in (report.get("artifacts") or {}).get("lines", []):
        print(f"  line at {a['period_s']:.4g} s ({a['at']}): {a['cause']}; fix: {a['structural_fix']}")
    if report.get("stopped"):
        print(f"  stopped: {report['stopped']['reason']}")
        if report["stopped"].get("not_offered"):
            print(f"  firmware capacity: {report['stopped']['not_offered']}")
    vs = report.get("versus_fit") or {}
    if vs.get("on"):
        print(f"  against hdrg fit's model ({vs['on']}): "
              + (f"lost on {vs['why']}" if vs["kept"] == "fit" else f"no figure worse by more than {vs['tolerance']:.0%}"))
    elif vs.get("why"):
        print(f"  against hdrg fit's model: {vs['why']}")
    print(f"  model written: {report['final_is']}")
    print(f"written: {os.path.join(args.out, 'diagnose.md')}, diagnose.json, model.json")
    sys.stdout.flush()      # the warnings (stderr) after the summary above
    for m in summary_warnings(report):
        print(f"hdrg diagnose: warning: {m}", file=sys.stderr)
    return 0


def check_options(args) -> None:
    """UserError naming the first option out of range: --max-iter, --max-tries, --surrogates and
    --seed must be >= 0, --cv-blocks and --cv-folds >= 1, --g-min (a fraction of the residual
    variance) finite in [0, 1), --settle [s] finite and >= 0."""
    for option, value in (("--max-iter", args.max_iter), ("--max-tries", args.max_tries),
                          ("--surrogates", args.surrogates), ("--seed", args.seed)):
        if value is not None and value < 0:
            raise UserError(f"{option} {value}: must be >= 0")
    for option, value in (("--cv-blocks", args.cv_blocks), ("--cv-folds", args.cv_folds)):
        if value < 1:
            raise UserError(f"{option} {value}: must be >= 1")
    if not (math.isfinite(args.g_min) and 0 <= args.g_min < 1):
        raise UserError(f"--g-min {args.g_min:g}: must be a fraction of the residual variance in [0, 1)")
    check_settle(args.settle)


def summary_warnings(report: dict) -> list:
    """The warnings of a diagnose report (host_tools.fitting.diagnose_report), one sentence each, for
    stderr: a held-out error far above the training error, held-out runs also in training, and the
    final model extrapolating on a held-out run.  The report files carry the same texts."""
    out = []
    if (report.get("generalization") or {}).get("warning"):
        out.append(report["generalization"]["warning"])
    out.extend(report.get("holdout_in_training") or [])
    out.extend(f"extrapolation on the held-out run (final model): {m}" for m in report.get("extrapolation") or [])
    return out
