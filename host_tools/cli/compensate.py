"""`hdrg compensate`: apply a bias model to a run log, float golden or fixed point
(host_tools.golden.compensate)."""
from __future__ import annotations

import argparse

from host_tools.cli.options import regular_input, writable_output
from host_tools.golden.compensate import IMPLS, check_impl, compensate
from host_tools.link.capture import meta_text


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", metavar="RUN", help="run log to compensate (CSV or .npz)")
    parser.add_argument("--model", required=True, help="bias model JSON (hdrg fit)")
    parser.add_argument("-o", "--output", required=True, help="compensated run log to write (CSV or .npz)")
    parser.add_argument("--impl", choices=IMPLS, default="float",
                        help="float: the float64 golden model (default); fixed: the bit-accurate "
                             "fixed-point firmware reference")
    parser.add_argument("--table", metavar="TABLE",
                        help="with --impl fixed: coefficient table (table.json from hdrg quantize, .bin or "
                             ".memh) instead of quantizing the model on the fly")
    parser.add_argument("--strict", action="store_true",
                        help="refuse (exit 2, nothing written) when the model is extrapolated (> 1 %% of the "
                             "samples proxy/rate clamped) or any sample saturates, instead of warning")


def run(args) -> int:
    from host_tools.golden import flags
    from host_tools.golden import runlog as rl
    from host_tools.atomic import refuse_overwrite
    from host_tools.golden.model import BiasModel

    check_impl(args.impl)
    refuse_overwrite(args.output, [args.run, args.model, args.table])
    for path, what in ((args.run, "run log"), (args.model, "model"), (args.table, "table")):
        regular_input(path, what)       # /dev/zero, a FIFO: refused before anything reads them
    writable_output(args.output)
    model = BiasModel.from_json(args.model)
    table = None
    if args.table:
        if args.impl != "fixed":
            raise ValueError("--table needs --impl fixed")
        from host_tools.fixed.quantize import read_table
        table = read_table(args.table)
    log = rl.read(args.run)
    out = compensate(log, model, impl=args.impl, table=table)
    flags.report(out, strict=args.strict)
    if not args.output.lower().endswith(".npz"):
        # a metadata value with a newline (an NPZ's, a file name's) must not end its '# key: value' line
        out.metadata = {meta_text(k, key=True): meta_text(v) for k, v in out.metadata.items()}
    rl.write(out, args.output)
    print(f"{args.output}: {flags.summary(out)}")
    return 0
