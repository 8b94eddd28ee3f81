"""`hdrg upload`: load a coefficient table into the controller, acknowledged, read back and compared
(host_tools.link.host)."""
from __future__ import annotations

import argparse
import sys

from firmware_ref import table as T
from host_tools.cli.options import add_port_options, example, file_argument, file_value
from host_tools.link.codec import table_problems
from host_tools.link.host import HostLink, open_port, upload


def configure(parser: argparse.ArgumentParser) -> None:
    add_port_options(parser)
    file_argument(parser, "table", "TABLE", "coefficient table: table.json (hdrg quantize), .bin or .memh")
    parser.add_argument("--timeout", type=float, default=2.0, metavar="S", help="answer timeout per attempt (default 2)")
    parser.add_argument("--retries", type=int, default=3, help="TABLE attempts without an answer (default 3)")
    example(parser, "hdrg upload table.json --port /dev/ttyUSB0")


def run(args) -> int:
    import serial

    from host_tools.fixed.quantize import read_table

    args.table = file_value(args, "table")
    try:
        table = read_table(args.table)
    except T.TableError as exc:
        raise T.TableError(f"refused before sending: {exc}") from None
    probs = table_problems(table)
    if probs:
        raise T.TableError(f"{args.table}: refused before sending: " + "; ".join(probs))
    try:
        port = open_port(args.port, args.baud)
    except serial.SerialException as exc:
        print(f"hdrg upload: error: cannot open {args.port}: {exc}", file=sys.stderr)
        return 2
    try:
        link = HostLink(port)
        r = upload(link, table, timeout_s=args.timeout, retries=args.retries)
    except serial.SerialException as exc:
        print(f"hdrg upload: error: port error: {exc}", file=sys.stderr)
        return 2
    finally:
        port.close()
    print(f"{args.table}: uploaded to {r.info.name or 'the device'} (protocol {r.info.major}.{r.info.minor}): "
          f"CRC-32 0x{r.crc:08x} acknowledged, applied from sample {r.apply_sample}; read back and compared: "
          f"identical ({len(table.to_bytes())} bytes, {r.attempts} attempt(s))")
    return 0
