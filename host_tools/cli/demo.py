"""`hdrg demo`: simulate -> fit -> compensate -> report -> diagnose on embedded defaults
(host_tools.demo)."""
from __future__ import annotations

import argparse


def configure(parser: argparse.ArgumentParser) -> None:
    parser.epilog = ("Takes about 0.5 to 1.5 min (measured: 66 s and 83 s on a 2-core machine shared "
                     "with other work): two 6-h simulations, a fit, a report with figures and a closed-loop diagnosis.")
    parser.add_argument("-o", "--out", default="hdrg-demo", help="output directory (default: ./hdrg-demo)")
    parser.add_argument("--duration", type=float, default=6 * 3600.0, help="length of each simulated run [s]")


def run(args) -> int:
    from host_tools.demo import run_demo

    run_demo(args.out, args.duration)
    return 0
