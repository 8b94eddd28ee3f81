"""`hdrg lot`: calibrate a production lot (host_tools.lot: manifest, spec, outputs, resume)."""
from __future__ import annotations

import argparse
import json

from host_tools.cli.options import add_engine_options


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("manifest", metavar="MANIFEST", nargs="?",
                        help="manifest CSV (columns device,train[,holdout][,power_on_s]) or a directory (its "
                             "manifest.csv, else one sub-directory per device with train*/holdout* run logs)")
    parser.add_argument("-o", "--output", "--out", metavar="DIR", help="output directory (created; a second run resumes)")
    parser.add_argument("--spec", metavar="JSON", help="pass/fail spec (default: --print-spec)")
    add_engine_options(parser)
    parser.add_argument("--worst", type=int, default=10, metavar="K", help="rows of the worst-devices table (default 10)")
    parser.add_argument("--no-progress", action="store_true", help="no progress counter on stderr")
    parser.add_argument("--print-spec", action="store_true", help="print the default spec as JSON, then exit")
    parser.epilog = "examples:\n  hdrg lot lot/ -o lot-out/\n  hdrg lot --print-spec"


def run(args) -> int:
    import sys

    from host_tools.lot import DEFAULT_SPEC, run_lot

    if args.print_spec:
        print(json.dumps(DEFAULT_SPEC, indent=2))
        return 0
    if not args.manifest:
        raise ValueError("MANIFEST is required (a manifest CSV or a directory)")
    if not args.output:
        raise ValueError("-o/--output is required")
    if args.worst < 0:
        raise ValueError(f"--worst must be >= 0, not {args.worst}")
    try:
        res = run_lot(args.manifest, args.output, spec=args.spec, workers=args.workers, scheduler=args.scheduler,
                      progress=not args.no_progress, worst=args.worst)
    except KeyboardInterrupt:
        print(f"\nhdrg lot: interrupted; every device with a done-marker in {args.output}/devices is complete and "
              f"is reused when the same command runs again", file=sys.stderr)
        return 130
    stages = ", ".join(f"{k} {v}" for k, v in res["fail_by_stage"].items())
    print(f"hdrg lot: {res['devices']} devices, {res['passed']} pass, {res['failed']} fail"
          + (f" (failed at: {stages})" if stages else "")
          + f"; {len(res['computed'])} calibrated, {len(res['reused'])} reused from an earlier run")
    for name, path in res["report"].items():
        print(f"  {path}")
    if res["stale"]:
        print(f"hdrg lot: warning: {len(res['stale'])} device folder(s) in {args.output} are not in the manifest "
              f"(left as they are, not in the report): {', '.join(res['stale'][:10])}"
              + (" ..." if len(res["stale"]) > 10 else ""), file=sys.stderr)
    return 0 if res["failed"] == 0 else 1
