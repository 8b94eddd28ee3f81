"""`hdrg paper`: every experiment of Chen et al. 2022 on the simulator (host_tools.simulation.paper)."""
from __future__ import annotations

import argparse
import json


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", "-o", "--out", "--output", default=None, metavar="FILE",
                        help="also write the results as JSON to this file")
    parser.epilog = "example:\n  hdrg paper -o paper.json"


def run(args) -> int:
    from host_tools.simulation.paper import format_results, run_all

    res = run_all()
    print(format_results(res))
    if args.json:
        from host_tools.atomic import atomic_open
        with atomic_open(args.json, "w") as fh:
            json.dump(res, fh, indent=1, default=float)
    return 0
