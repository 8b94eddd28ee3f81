"""`hdrg capture` and `hdrg upload`: argument parsing and console output over
host_tools.link.capture and host_tools.link.host.  Both commands are registered on this module
(host_tools/cli.py COMMANDS); the subcommand name (the parser's prog) selects the arguments.
"""
from __future__ import annotations

import argparse
import sys
import time

from firmware_ref import table as T
from host_tools.link.capture import CaptureResult, capture, check_output_path
from host_tools.link.codec import table_problems
from host_tools.link.host import HostLink, open_port, upload
from host_tools.quantize import read_table


def _add_port_args(parser) -> None:
    parser.add_argument("--port", required=True, help="serial port or pyserial URL (/dev/ttyUSB0, /dev/pts/5, loop://)")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")


def configure_capture_cli(parser: argparse.ArgumentParser) -> None:
    _add_port_args(parser)
    parser.add_argument("-o", "--output", required=True, help="run log (CSV) to write")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds of device time (default: until the device stops or Ctrl-C)")
    parser.add_argument("--idle-timeout", type=float, default=30.0, metavar="S",
                        help="stop when no frame arrives for S seconds (default 30; 0: never)")
    parser.add_argument("--flush-every", type=int, default=256, metavar="N", help="flush every N rows (and every second)")
    parser.add_argument("--quiet", action="store_true", help="no live progress line")


def configure_upload_cli(parser: argparse.ArgumentParser) -> None:
    _add_port_args(parser)
    parser.add_argument("table", metavar="TABLE", help="coefficient table: table.json (hdrg quantize), .bin or .memh")
    parser.add_argument("--timeout", type=float, default=2.0, metavar="S", help="answer timeout per attempt (default 2)")
    parser.add_argument("--retries", type=int, default=3, help="TABLE attempts without an answer (default 3)")


def _command_of(parser) -> str:
    return parser.prog.rsplit(" ", 1)[-1]


def configure_cli(parser: argparse.ArgumentParser) -> None:
    """`hdrg capture` or `hdrg upload`, by the subcommand name (the parser's prog)."""
    if _command_of(parser) == "upload":
        configure_upload_cli(parser)
    else:
        configure_capture_cli(parser)
    parser.set_defaults(_serial_command=_command_of(parser))


class _Progress:
    def __init__(self, stream=sys.stderr, interval_s: float = 0.25):
        self.stream, self.interval_s, self._last = stream, interval_s, 0.0

    def __call__(self, res: CaptureResult) -> None:
        now = time.monotonic()
        if now - self._last >= self.interval_s:
            self._last = now
            self.stream.write("\r" + res.progress_line() + "   ")
            self.stream.flush()


def run_capture_cli(args) -> int:
    import serial

    check_output_path(args.output)
    try:
        port = open_port(args.port, args.baud)
    except serial.SerialException as exc:
        print(f"hdrg capture: error: cannot open {args.port}: {exc}", file=sys.stderr)
        return 2
    idle = None if not args.idle_timeout or args.idle_timeout <= 0 else args.idle_timeout
    prog = None if args.quiet else _Progress()
    try:
        res = capture(port, args.output, duration_s=args.duration, idle_timeout_s=idle,
                      flush_every=args.flush_every, progress=prog)
    finally:
        port.close()
    if prog is not None:
        sys.stderr.write("\n")
    print(res.summary())
    return 0 if res.written else 1


def run_upload_cli(args) -> int:
    import serial

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


def run_cli(args) -> int:
    cmd = getattr(args, "_serial_command", None) or getattr(args, "command", "capture")
    return run_upload_cli(args) if cmd == "upload" else run_capture_cli(args)
