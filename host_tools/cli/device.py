"""`hdrg device`: the virtual gyroscope controller on a pseudo-terminal or a pyserial URL
(host_tools.link.device)."""
from __future__ import annotations

import argparse
import math
import sys

from host_tools.cli.options import seconds_type
from host_tools.link.capture import MAX_DURATION_S

MAX_SPEED = 1e6             # times real time; 0 already means "as fast as the link takes"
MAX_RATE_HZ = 65536.0       # the INFO's and the table's fs_q16 word: up to 2^16 Hz


def number_type(option: str, lo: float, hi: float, lo_open: bool, what: str):
    """An argparse ``type``: a finite number in (lo, hi] (``lo_open``) or [lo, hi]; anything else
    (NaN, inf, out of range, not a number) is a usage error naming ``option``, the value and the range."""
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} {text!r}: not a number") from None
        if not (math.isfinite(value) and (lo < value if lo_open else lo <= value) and value <= hi):
            raise argparse.ArgumentTypeError(f"{option} {text}: must be {what} in {'(' if lo_open else '['}{lo:g}, "
                                             f"{hi:g}]")
        return value
    parse.__name__ = "number"
    return parse


def configure(parser: argparse.ArgumentParser) -> None:
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="serve on a new pseudo-terminal (prints its name)")
    where.add_argument("--port", help="serve on a serial port or pyserial URL (loop://, /dev/ttyUSB1, ...)")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate with --port (default 115200)")
    parser.add_argument("--scenario", default="paper-mr-cycle-4dpm",
                        help="simulator scenario (hdrg simulate --list; default paper-mr-cycle-4dpm)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    parser.add_argument("--duration", type=seconds_type("--duration", MAX_DURATION_S), default=None, metavar="S",
                        help="run length [s] (default: the scenario's)")
    parser.add_argument("--rate", type=number_type("--rate", 0.0, MAX_RATE_HZ, True, "a sample rate [Hz]"),
                        default=1.0, metavar="HZ", help="sample rate [Hz] (default 1)")
    parser.add_argument("--speed", type=number_type("--speed", 0.0, MAX_SPEED, False, "a speed-up factor"),
                        default=1.0, metavar="X",
                        help=f"X times real time, up to {MAX_SPEED:g} (default 1; 0: as fast as the link takes "
                             f"frames)")
    parser.add_argument("--table", metavar="FILE", help="initial coefficient table (table.json, .bin, .memh); "
                                                        "default: the run's identity table (coefficients 0)")
    parser.add_argument("--name", default=None, help="device name reported in INFO")
    parser.add_argument("--exit-at-end", action="store_true", help="exit when the simulated run has been sent")
    parser.epilog = ("examples:\n  hdrg device --pty --speed 0 --exit-at-end\n"
                     "  hdrg device --port loop:// --table table.json")


def run(args) -> int:
    from host_tools.link import frame as FR
    from host_tools.link.codec import printable
    from host_tools.link.device import make_device, serve
    from host_tools.link.host import check_baud, open_port
    from host_tools.link.transport import PortLink
    from host_tools.fixed.quantize import read_table

    check_baud(args.baud, "--baud")
    table = read_table(args.table) if args.table else None
    link = None
    if args.port:
        link = PortLink(open_port(args.port, args.baud, timeout=0, write_timeout=1.0, option="--port"))
    kw = {} if args.name is None else {"name": args.name}
    try:
        dev, name, log = make_device(args.scenario, args.seed, args.duration, args.rate, table, link,
                                     speed=args.speed, **kw)
    except BaseException:
        if link is not None:
            link.close()
        raise
    speed = "as fast as the link takes" if args.speed == 0 else f"{args.speed:g}x real time"
    print(f"hdrg device: virtual gyroscope on {name or args.port}", flush=True)
    print(f"  {printable(dev.name)}: {len(log)} samples at {dev.run.fs_hz:g} Hz, {speed}; table CRC-32 0x{dev.table.crc:08x}; "
          f"protocol {FR.PROTO_MAJOR}.{FR.PROTO_MINOR}; Ctrl-C stops", flush=True)
    serve(dev, args.exit_at_end)
    s = dev.stats
    print(f"hdrg device: sent {s.samples_sent} samples ({s.frames_dropped} frames dropped, link not ready); "
          f"uploads accepted {s.uploads_accepted}, refused {s.uploads_refused}"
          + (f"; link closed: {dev.closed_reason}" if dev.closed_reason else ""))
    if dev.error is not None:
        print(f"hdrg device: error: {dev.error!r}", file=sys.stderr)
        return 1
    return 0
