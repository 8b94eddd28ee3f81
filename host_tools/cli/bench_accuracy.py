"""`hdrg bench accuracy`: the pipeline's options on random foreign devices (host_tools.bench.accuracy)."""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from host_tools.cli.options import add_engine_options


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--devices", type=int, default=50, help="number of random devices (default 50)")
    parser.add_argument("--seed", type=int, default=0, help="device set: seeds S*100000 + i (default 0)")
    parser.add_argument("--start", type=int, default=0, metavar="I",
                        help="first device index (devices I .. I+N-1; default 0), to split a run over machines "
                             "without Dask (then --merge)")
    add_engine_options(parser, "device order")
    parser.add_argument("--merge", nargs="+", metavar="JSON", default=None,
                        help="instead: merge --json files of split runs (same options, disjoint devices) and "
                             "print their tables (with --json: write the merged result)")
    parser.add_argument("--json", "-o", "--out", "--output", metavar="F",
                        help="write config, per-device records and summary as JSON")
    parser.add_argument("--pipelines", nargs="+", metavar="PATTERN",
                        help="options to run (fnmatch patterns, e.g. 'ftr/*' 'mr-trend/iir9'; default all)")
    parser.add_argument("--train-rate", type=float, default=4.0, metavar="CPM", help="training chamber rate (4)")
    parser.add_argument("--holdout-rate", type=float, default=2.0, metavar="CPM", help="held-out chamber rate (2)")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="cut every run to S seconds (default: the whole chamber profile)")
    parser.add_argument("--ablation", action="store_true",
                        help="instead: the selected options with one piece of the physics removed at a time, then exit")
    parser.add_argument("--effect-sizes", action="store_true",
                        help="instead: std of every effect kind's term at strength 1 / floor (MR, 2 degC/min), then exit")
    parser.add_argument("--plausibility", nargs="*", metavar="RUN", default=None,
                        help="instead: compare the family's FTR runs (3 degC/min) with measured FTR run logs "
                             "(cubic-in-temp_c residual / white floor), then exit")


def run(args) -> int:
    from host_tools.bench.accuracy import (ablation, effect_sizes, format_pivot, format_table, merge, plausibility,
                                          run_benchmark)

    if args.ablation:
        print(ablation(args.devices, args.seed, args.pipelines, args.duration))
        return 0
    if args.effect_sizes:
        for k, v in effect_sizes(args.devices, args.seed).items():
            print(f"{k:20s} median {np.median(v):.1f}, 10..90 % {np.percentile(v, 10):.1f}..{np.percentile(v, 90):.1f}")
        return 0
    if args.plausibility is not None:
        print(plausibility(args.devices, args.seed, args.plausibility))
        return 0
    if args.merge:
        parts = []
        for path in args.merge:
            with open(path) as fh:
                parts.append(json.load(fh))
        res = merge(parts)
    else:
        from host_tools.lot.parallel import check_workers

        res = run_benchmark(args.devices, args.seed, args.pipelines, args.train_rate, args.holdout_rate,
                            args.duration, progress=lambda msg: print(f"hdrg bench accuracy: {msg}", file=sys.stderr),
                            start=args.start, workers=check_workers(args.workers), scheduler=args.scheduler)
    cfg = res["config"]
    print(f"held-out std at 1 s / noise floor; {cfg['devices']} foreign devices (set {cfg['seed']}, from index "
          f"{cfg['start']}), train {cfg['train']['rate_c_per_min']:g} degC/min power-on 0, hold out "
          f"{cfg['holdout']['rate_c_per_min']:g} degC/min power-on 1; {cfg['elapsed_s']} s")
    print(format_table(res))
    print("\nmedian / p90, all devices:")
    print(format_pivot(res))
    print("\nmedian / p90, damping-change subset:")
    print(format_pivot(res, "damping_change"))
    nerr = sum(len(r["errors"]) for r in res["records"])
    if nerr:
        print(f"{nerr} option runs failed (see the JSON 'errors'); e.g. "
              + "; ".join(f"seed {r['seed']} {k}: {v}" for r in res["records"] for k, v in r["errors"].items())[:300])
    if args.json:
        from host_tools.golden.model import jsonable
        with open(args.json, "w") as fh:
            json.dump(jsonable(res), fh, indent=1)
    return 0
