"""`hdrg cost`: build and run the pipeline on a target, cycles and size (host_tools.bench.cost)."""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from host_tools.bench.cost import TARGETS


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--target", required=True, choices=TARGETS)
    parser.add_argument("--json", "-o", "--out", "--output", default=None, metavar="FILE",
                        help="write the figures as JSON to this file")
    parser.epilog = "examples:\n  hdrg cost --target host\n  hdrg cost --target cortex-m4 -o cost.json"
    parser.add_argument("--keep", default=None, help="build directory to keep (default: a temporary one)")


def run(args) -> int:
    from host_tools.bench.cost import measure, summary

    if args.keep:
        r = measure(args.target, Path(args.keep), log=print)
    else:
        with tempfile.TemporaryDirectory(prefix="hdrg-cost-") as d:
            r = measure(args.target, Path(d), log=print)
    print(summary(r))
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1, default=str) + "\n")
    return 0 if r["bit_exact"] else 1
