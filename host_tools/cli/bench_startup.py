"""`hdrg bench startup`: the output from power-on at constant ambient on foreign devices (host_tools.bench.startup)."""
from __future__ import annotations

import argparse
import json
import sys


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--devices", type=int, default=20, metavar="N", help="devices (default 20)")
    parser.add_argument("--seed", type=int, default=0, metavar="S", help="device set: seeds S * 100000 + i (default 0)")
    parser.add_argument("--start", type=int, default=0, metavar="I", help="first device index (default 0)")
    parser.add_argument("--startups", type=int, default=4, metavar="K",
                        help="power-ons at constant ambient per device, >= 2 (default 4, the paper's)")
    parser.add_argument("--control", action="store_true",
                        help="devices WITHOUT a turn-on: what the fit learns there is a false discovery")
    parser.add_argument("--loop", action="store_true",
                        help="also the closed loop (hdrg diagnose defaults on the calibration runs; about 10 s per device); "
                             "exits 1 when it ends more than 5 %% worse than hdrg fit on a device")
    parser.add_argument("--json", "-o", "--out", "--output", metavar="F", help="write every device's figures and the summary as JSON")
    parser.epilog = "example: hdrg bench startup --devices 20 -o startup.json"


def run(args) -> int:
    from host_tools.atomic import atomic_open
    from host_tools.bench.startup import EFFECT, format_table, run_benchmark

    result = run_benchmark(args.devices, args.seed, args.startups, start=args.start,
                           effect=None if args.control else EFFECT, loop=args.loop,
                           progress=lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    print(format_table(result))
    if args.json:
        with atomic_open(args.json) as f:
            f.write(json.dumps(result, indent=1) + "\n")
    worse = result["summary"].get("loop_worse_than_fit")
    if worse:
        print(f"FAILED: the loop ends more than 5 % worse than hdrg fit on {len(worse)} device(s)", file=sys.stderr)
        return 1
    return 0
