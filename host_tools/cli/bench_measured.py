"""`hdrg bench measured`: the default fit on measured data, held out by leg (host_tools.bench.measured)."""
from __future__ import annotations

import argparse
import json
import sys


def configure(parser: argparse.ArgumentParser) -> None:
    from host_tools.bench.measured import DEFAULT_DATA
    parser.add_argument("--data", metavar="DIR", default=None,
                        help=f"folder of measured sets, one sub-folder each with *.csv run logs (default: the "
                             f"sets shipped in {DEFAULT_DATA.parent.name}/{DEFAULT_DATA.name})")
    parser.add_argument("--only", metavar="TEXT", help="only the logs whose file name contains TEXT")
    parser.add_argument("--json", "-o", "--out", "--output", metavar="F",
                        help="write every split's figures and the summary as JSON")
    parser.epilog = "example: hdrg bench measured --only tofupilot --json measured.json"


def run(args) -> int:
    from host_tools.atomic import atomic_open
    from host_tools.bench.measured import DEFAULT_DATA, run as run_measured, table

    def progress(row):
        print(f"  {row['log']} {' + '.join(row['train'])} -> {row['held_out']}: default / cubic {row['ratio']:.2f}",
              file=sys.stderr, flush=True)

    result = run_measured(args.data or DEFAULT_DATA, args.only, progress)
    print(table(result))
    if args.json:
        with atomic_open(args.json) as f:
            f.write(json.dumps(result, indent=1) + "\n")
    return 0
