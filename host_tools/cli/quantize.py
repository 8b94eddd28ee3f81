"""`hdrg quantize`: a bias model -> the fixed-point coefficient table (host_tools.api.quantize over
host_tools.fixed.quantize).

The options are checked before anything is quantized (one-line errors naming the option): the
times [s] must be finite and >= 0 (``--dwell-s`` > 0), and a time > 0 must be at least one sample
and at most the timing fields' 2^31 - 2 samples at the model's sample rate (a time that rounds to
0 samples would silently switch the blanking off); ``--max-error`` [deg/h] must be finite and >= 0.
A time that is not a whole number of samples is rounded to the nearest (the table's timing fields
count samples) with a note on stderr naming the option and the samples kept.
"""
from __future__ import annotations

import argparse
import math
import sys

from firmware_ref import formats as F
from host_tools import api
from host_tools.cli.options import (distinct_outputs, example, file_argument, file_value, out_option, regular_input,
                                    writable_output)
from host_tools.errors import UserError
from host_tools.golden.checks import shorter_than_a_sample, whole_samples

TIMER_LIMIT_N = F.TIMER_MAX - 1     # largest sequencer time in samples (the table's timing fields)


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
    check_number("--max-error", args.max_error, "deg/h")
    from host_tools.golden.model import BiasModel
    model = BiasModel.from_json(args.model)
    fs = model.config.rate.fs
    check_samples("--power-on-s", args.power_on_s, fs)
    check_samples("--exchange-s", args.exchange_s, fs)
    check_samples("--dwell-s", args.dwell_s, fs, zero=False)
    q = api.quantize(model, args.output, exchange_s=args.exchange_s, dwell_s=args.dwell_s,
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
    for option, value_s in (("--power-on-s", args.power_on_s), ("--exchange-s", args.exchange_s),
                            ("--dwell-s", args.dwell_s)):
        note = rounding_note(option, value_s, fs)
        if note:
            print(f"hdrg quantize: note: {note}", file=sys.stderr)
    for w in q.report["warnings"]:
        print(f"hdrg quantize: warning: {w}", file=sys.stderr)
    return 0


def check_number(option: str, value, unit: str) -> None:
    """UserError naming ``option`` unless ``value`` (None: not given) is a finite number >= 0 [``unit``]."""
    if value is not None and not (math.isfinite(value) and value >= 0):
        raise UserError(f"{option} {value:g}: must be a finite number of {unit} >= 0")


def check_samples(option: str, value_s: float, fs: float, zero: bool = True) -> None:
    """UserError naming ``option`` unless the time ``value_s`` [s] is finite, >= 0 (> 0 unless
    ``zero``) and, when > 0, rounds to 1 .. TIMER_LIMIT_N samples at the sample rate ``fs`` [Hz]."""
    if not (math.isfinite(value_s) and (value_s > 0 or (zero and value_s == 0))):
        raise UserError(f"{option} {value_s:g}: must be a finite number of seconds " + (">= 0" if zero else "> 0"))
    if value_s == 0:
        return
    n = round(value_s * fs)
    if shorter_than_a_sample(value_s, fs):
        raise UserError(f"{option} {value_s:g}: shorter than one sample at the model's sample rate {fs:g} Hz "
                        f"(one sample is {1 / fs:g} s); give at least {1 / fs:g} s"
                        + (" or 0 for none" if zero else ""))
    if n > TIMER_LIMIT_N:
        raise UserError(f"{option} {value_s:g}: more than the {TIMER_LIMIT_N} samples the table's timing fields "
                        f"hold at the model's sample rate {fs:g} Hz (at most {TIMER_LIMIT_N / fs:.6g} s)")


def rounding_note(option: str, value_s: float, fs: float) -> str | None:
    """The note for a time ``value_s`` [s] that is not a whole number of samples at ``fs`` [Hz] (the
    table holds it rounded), or None."""
    if whole_samples(value_s, fs):
        return None
    n = value_s * fs
    return (f"{option} {value_s:g} s is {n:.6g} samples at the model's sample rate {fs:g} Hz: the table holds "
            f"{round(n)} samples ({round(n) / fs:g} s)")
