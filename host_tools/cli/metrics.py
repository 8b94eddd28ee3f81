"""`hdrg metrics`: the paper's figures of merit of run logs (host_tools.fitting.metrics)."""
from __future__ import annotations

import argparse
import math
import sys

from host_tools.golden import reversal
from host_tools.fitting.metrics import DEFAULT_TAUS, format_table, load, repeatability, run_metrics, to_json
from host_tools.errors import UserError


def _parse_taus(text: str) -> tuple:
    try:
        taus = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tau must be comma-separated seconds, e.g. 1,10,100, not {text!r}") from None
    if not taus or any(not (t > 0 and math.isfinite(t)) for t in taus):
        raise argparse.ArgumentTypeError(f"--tau values must be finite and > 0 s, not {text!r}")
    return taus


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", metavar="RUN", help="run logs (CSV or NPZ), raw or compensated")
    parser.add_argument("--tau", type=_parse_taus, default=DEFAULT_TAUS, metavar="LIST",
                        help="averaging times in s, comma-separated (default 1,10,100)")
    parser.add_argument("--combiner", choices=reversal.COMBINERS, default=None,
                        help=f"mode-reversal combiner for raw mode-reversal logs (default {reversal.DEFAULT_COMBINER}, "
                             f"as hdrg fit)")
    parser.add_argument("--json", "-o", "--out", "--output", nargs="?", const="-", default=None, metavar="FILE",
                        help="JSON output: '--json' or '--json -' prints it instead of the table; "
                             "'--json FILE' (or -o/--out/--output FILE) writes FILE and prints the table")
    parser.epilog = ("examples:\n  hdrg metrics run.csv compensated.csv\n"
                     "  hdrg metrics compensated.csv --tau 1,10,100,1000 -o metrics.json")


def run(args) -> int:
    from host_tools.atomic import atomic_open, refuse_overwrite

    if args.json not in (None, "-"):
        refuse_overwrite(args.json, args.runs)
    if args.json not in (None, "-") and args.json.lower().endswith((".csv", ".npz")):
        raise UserError(f"--json {args.json}: refusing to write JSON over a run-log name (.csv/.npz); "
                         f"put --json after the RUN paths or use --json -")
    from host_tools.golden.checks import warn_mode_swaps

    logs = [load(p) for p in args.runs]
    warn_mode_swaps(logs)           # modes 1 and 2 swapped: against the other runs, or the model's bias
    runs = [run_metrics(log, taus=args.tau, combiner=args.combiner) for log in logs]
    rep = repeatability(runs) if len(runs) >= 2 else None
    if args.json == "-":
        sys.stdout.write(to_json(runs, rep) + "\n")
        return 0
    if args.json is not None:
        with atomic_open(args.json, "w", encoding="utf-8") as fh:
            fh.write(to_json(runs, rep) + "\n")
    sys.stdout.write(format_table(runs, rep))
    return 0
