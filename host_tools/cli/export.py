"""`hdrg export`: a coefficient table as C header, table.json and $readmemh file (host_tools.fixed.export)."""
from __future__ import annotations

import argparse
import os

from host_tools.cli.options import (distinct_outputs, example, file_argument, file_value, out_option, regular_input,
                                    writable_output)
from host_tools.fixed.export import DEFAULT_NAME, EXTENSIONS, FORMATS, LAYOUT_VERSION, check_name, export, load


def configure(parser: argparse.ArgumentParser) -> None:
    file_argument(parser, "table", "TABLE", "table.json (hdrg quantize), .bin or .memh")
    parser.add_argument("--format", choices=FORMATS + ("all",), default="all",
                        help="c: C99 header; json: table.json with the float originals; mem: $readmemh "
                             "words; all (default): the three")
    out_option(parser, "directory to write into", required=True, metavar="DIR")
    parser.add_argument("--name", default=DEFAULT_NAME,
                        help=f"file base name and C symbol (upper-cased) (default {DEFAULT_NAME})")
    example(parser, "hdrg export table.json -o out/", "hdrg export --table table.json --format c --name gyro_x -o out/")


def run(args) -> int:
    from host_tools.atomic import refuse_overwrite

    args.table = file_value(args, "table")
    formats = FORMATS if args.format == "all" else (args.format,)
    check_name(args.name)
    outputs = {f"--format {f}": os.path.join(args.output, args.name + EXTENSIONS[f]) for f in formats}
    distinct_outputs(outputs)
    refuse_overwrite(list(outputs.values()), args.table)
    regular_input(args.table, "table")
    for opt, path in outputs.items():
        writable_output(path, opt)
    table, info = load(args.table)
    paths = export(table, args.output, formats, args.name, info)
    print(f"{args.table}: layout version {LAYOUT_VERSION}, {len(table.to_words())} words, CRC-32 0x{table.crc:08x}")
    for fmt, path in paths.items():
        print(f"  {fmt:4s} {path}")
    return 0
