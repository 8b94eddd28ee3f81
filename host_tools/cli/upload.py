"""`hdrg upload`: load a coefficient table into the controller, acknowledged, read back and compared
(host_tools.link.host)."""
from __future__ import annotations

import argparse

from firmware_ref import table as T
from host_tools.cli.options import add_port_options, example, file_argument, file_value, seconds_type
from host_tools.link.codec import printable, table_problems
from host_tools.link.host import MAX_RETRIES, MAX_TIMEOUT_S, HostLink, PortError, check_baud, check_retries, \
    check_timeout, open_port, upload


def configure(parser: argparse.ArgumentParser) -> None:
    add_port_options(parser)
    file_argument(parser, "table", "TABLE", "coefficient table: table.json (hdrg quantize), .bin or .memh")
    parser.add_argument("--timeout", type=seconds_type("--timeout", MAX_TIMEOUT_S), default=2.0, metavar="S",
                        help=f"answer timeout per attempt [s], in (0, {MAX_TIMEOUT_S:g}] (default 2)")
    parser.add_argument("--retries", type=int, default=3,
                        help=f"TABLE attempts without an answer, 1 .. {MAX_RETRIES} (default 3)")
    example(parser, "hdrg upload table.json --port /dev/ttyUSB0")


def run(args) -> int:
    import serial

    from host_tools.fixed.quantize import read_table

    check_baud(args.baud, "--baud")
    check_timeout(args.timeout, "--timeout")
    check_retries(args.retries, "--retries")
    args.table = file_value(args, "table")
    try:
        table = read_table(args.table)
    except T.TableError as exc:
        raise T.TableError(f"refused before sending: {exc}") from None
    probs = table_problems(table)
    if probs:
        raise T.TableError(f"{args.table}: refused before sending: " + "; ".join(probs))
    port = open_port(args.port, args.baud, option="--port")
    try:
        link = HostLink(port)
        r = upload(link, table, timeout_s=args.timeout, retries=args.retries)
    except serial.SerialException as exc:
        raise PortError(f"--port {args.port}: port error: {exc}") from None
    finally:
        port.close()
    name = printable(r.info.name) or "the device"
    print(f"{args.table}: uploaded to {name} (protocol {r.info.major}.{r.info.minor}, {r.info.fs_hz:g} Hz): "
          f"CRC-32 0x{r.crc:08x} acknowledged, applied from sample {r.apply_sample}; read back and compared: "
          f"identical ({len(table.to_bytes())} bytes, {r.attempts} attempt(s))")
    return 0
