"""`hdrg capture`: record a run log from the controller over a serial port
(host_tools.link.capture)."""
from __future__ import annotations

import argparse
import sys
import time

from host_tools.cli.options import add_port_options, example, out_option, seconds_type, writable_output
from host_tools.link.capture import MAX_DURATION_S, OUTPUT_SUFFIXES, CaptureResult, capture, check_output_path
from host_tools.link.host import check_baud, open_port
from host_tools.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    add_port_options(parser)
    out_option(parser, f"run log to write; its format follows the name: {' or '.join(OUTPUT_SUFFIXES)}",
               required=True)
    parser.add_argument("--duration", type=seconds_type("--duration", MAX_DURATION_S), default=None, metavar="S",
                        help="stop after S seconds of device time, S > 0 (default: until the device stops or Ctrl-C)")
    parser.add_argument("--idle-timeout", type=seconds_type("--idle-timeout", MAX_DURATION_S, zero="never"),
                        default=30.0, metavar="S",
                        help="stop when no new sample (before the device's first INFO: no INFO) arrives for S "
                             "seconds, whatever else it sends (default 30; 0: never stop for silence, wait until "
                             "--duration, the device's end of run or Ctrl-C; --duration then also bounds a stall)")
    parser.add_argument("--flush-every", type=int, default=256, metavar="N", help="flush every N rows (and every second)")
    parser.add_argument("--quiet", action="store_true", help="no live progress line")
    example(parser, "hdrg capture --port /dev/ttyUSB0 --duration 21600 -o run.csv")


class _Progress:
    """The live progress line on ``stream`` (default: sys.stderr as it is when the line is created,
    not when this module was imported)."""

    def __init__(self, stream=None, interval_s: float = 0.25):
        self.stream = sys.stderr if stream is None else stream
        self.interval_s, self._last = interval_s, 0.0

    def __call__(self, res: CaptureResult) -> None:
        now = time.monotonic()
        if now - self._last >= self.interval_s:
            self._last = now
            self.stream.write("\r" + res.progress_line() + "   ")
            self.stream.flush()


def run(args) -> int:
    check_output_path(args.output)
    writable_output(args.output)
    if args.flush_every < 1:
        raise UserError(f"--flush-every {args.flush_every}: must be at least 1 row")
    check_baud(args.baud, "--baud")
    port = open_port(args.port, args.baud, option="--port")
    idle = None if args.idle_timeout == 0 else args.idle_timeout      # 0: never stop for silence
    prog = None if args.quiet else _Progress()
    try:
        res = capture(port, args.output, duration_s=args.duration, idle_timeout_s=idle,
                      flush_every=args.flush_every, progress=prog)
    finally:
        port.close()
    if prog is not None:
        sys.stderr.write("\n")
    print(res.summary())
    if not res.written:
        print(f"hdrg capture: error: nothing recorded: {res.reason}", file=sys.stderr)
    return 0 if res.written else 1
