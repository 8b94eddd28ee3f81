"""`hdrg quantize`: a bias model -> the fixed-point coefficient table (host_tools.api.quantize over
host_tools.fixed.quantize)."""
from __future__ import annotations

import argparse
import sys

from firmware_ref import formats as F
from host_tools import api
from host_tools.cli.options import (distinct_outputs, example, file_argument, file_value, out_option, regular_input,
                                    writable_output)


def configure(parser: argparse.ArgumentParser) -> None:
    file_argument(parser, "model", "MODEL", "bias model JSON (hdrg fit)")
    out_option(parser, "table.json to write", required=True)
    parser.add_argument("--exchange-s", type=float, default=30.0, help="sequencer exchange time [s] (default 30)")
    parser.add_argument("--dwell-s", type=float, default=120.0, help="sequencer mode-1/2 window [s] (default 120)")
    parser.add_argument("--power-on-s", type=float, default=0.0, help="sequencer power-on time [s] (default 0)")
    parser.add_argument("--max-error", type=float, default=None, metavar="DPH",
                        help="refuse if the bound on |fixed - golden| exceeds DPH deg/h")
    parser.add_argument("--memh", metavar="FILE", help="also write a $readmemh memory file")
    parser.add_argument("--header", metavar="FILE", help="also write a C99 header")
    parser.add_argument("--bin", metavar="FILE", help="also write the binary table (little-endian words)")
    example(parser, "hdrg quantize model.json -o table.json", "hdrg quantize --model model.json -o table.json --max-error 0.01")


def run(args) -> int:
    from host_tools.atomic import atomic_open, refuse_overwrite

    args.model = file_value(args, "model")
    outputs = {"-o": args.output, "--memh": args.memh, "--header": args.header, "--bin": args.bin}
    distinct_outputs(outputs)
    refuse_overwrite(list(outputs.values()), args.model)
    regular_input(args.model, "model")
    for opt, path in outputs.items():
        writable_output(path, opt)
    q = api.quantize(args.model, args.output, exchange_s=args.exchange_s, dwell_s=args.dwell_s,
                     power_on_s=args.power_on_s, max_error_dph=args.max_error)
    t = q.table
    if args.memh:
        with atomic_open(args.memh, "w", encoding="utf-8") as fh:
            fh.write(t.to_memh())
    if args.header:
        from host_tools.fixed.export import c_header
        with atomic_open(args.header, "w", encoding="utf-8") as fh:
            fh.write(c_header(t, info=q.to_dict()))
    if args.bin:
        with atomic_open(args.bin, "wb") as fh:
            fh.write(t.to_bytes())
    b, m = q.report["bound_dph"], q.report["measured_dph"]
    print(f"{args.output}: {len(t.to_words())} words, CRC-32 0x{t.crc:08x}; exponents rows "
          f"{list(t.e_row)}, k7 {t.e_7}, E {t.e_acc}"
          + (f"; bank 2 rows {list(t.e_row2)}, k7 {t.e_7_2}, E {t.e_acc2} ({F.ORDERS[t.order]}, "
             f"combiner {F.COMBINERS[t.combiner]})" if t.n_banks == 2 else ""))
    print(f"|fixed - golden| bound: B {b['bias_B']:.3g}, OUT {b['out']:.3g} deg/h; measured B max "
          f"{m['corners']:.3g} (corners), {m['random']:.3g} (random, n={m['n_random']}) deg/h")
    if "aux" in q.report:
        a = q.report["aux"]
        gens = ", ".join(x["gen"] for x in a["terms"])
        words = ", ".join("{word}={column} (AF {frac})".format(**c) for c in a["channels"]) or "none"
        print(f"aux generators: {len(a['terms'])} terms ({gens}), aux words {words}; |z_fixed - z_golden| "
              f"bound {a['z_error']:.3g}, measured {a['measured_z']['z_max']:.3g}")
    sys.stdout.flush()
    for w in q.report["warnings"]:
        print(f"hdrg quantize: warning: {w}", file=sys.stderr)
    return 0
