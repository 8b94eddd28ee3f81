"""`hdrg compensate`: apply a bias model to a run log, float golden or fixed point
(host_tools.api.compensate over host_tools.golden.compensate)."""
from __future__ import annotations

import argparse

from host_tools.cli.options import example, out_option, writable_output
from host_tools.golden.compensate import IMPLS, check_impl


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", metavar="RUN", help="run log to compensate (CSV or .npz)")
    parser.add_argument("--model", required=True, help="bias model JSON (hdrg fit)")
    out_option(parser, "compensated run log to write (CSV or .npz)", required=True)
    parser.add_argument("--impl", choices=IMPLS, default="float",
                        help="float: the float64 golden model (default); fixed: the bit-accurate "
                             "fixed-point firmware reference")
    parser.add_argument("--table", metavar="TABLE",
                        help="with --impl fixed: coefficient table (table.json from hdrg quantize, .bin or "
                             ".memh) instead of quantizing the model on the fly")
    parser.add_argument("--strict", action="store_true",
                        help="refuse (exit 2, nothing written) when the model is extrapolated (> 1 %% of the "
                             "samples proxy/rate clamped), any sample saturates, any input is outside what the "
                             "sensor can report (the count and first row are named; full scale: run-log metadata "
                             "rate_full_scale_dph, freq_range_hz, temp_range_c, docs/RUN_LOG.md) or a proxy is "
                             "stuck, instead of warning")
    example(parser, "hdrg compensate held_out.csv --model model.json -o compensated.csv",
            "hdrg compensate held_out.csv --model model.json --impl fixed --table table.json -o fixed.csv")


def run(args) -> int:
    from host_tools import api
    from host_tools.golden import flags

    check_impl(args.impl)
    writable_output(args.output)
    out = api.compensate(args.run, args.model, impl=args.impl, table=args.table, output=args.output,
                         strict=args.strict)
    print(f"{args.output}: {flags.summary(out)}")
    return 0
