"""Option groups shared by several commands: the output option ``-o/--out/--output`` of every
command that writes (:func:`out_option`), an input given as a positional or as an option (the
model of `hdrg quantize`, the table of `hdrg export`: :func:`file_argument`), the examples of a
command's help (:func:`example`), the model options (`hdrg fit`, `hdrg diagnose`),
the serial port (`hdrg capture`, `hdrg upload`) and the random simulator family (`hdrg simulate`);
and the checks of values and paths the commands share: durations in seconds (:func:`seconds_type`:
negative, NaN and inf refused with the allowed range), outputs of one command that are one file
(:func:`distinct_outputs`), special files as inputs (:func:`regular_input`: /dev/zero, a FIFO)
and outputs that would block (:func:`writable_output`: a FIFO nobody reads).
"""
from __future__ import annotations

import argparse
import atexit

from firmware_ref.vocabulary import ESTIMATORS, PROXY_KINDS
from host_tools.errors import UserError


OUT_OPTIONS = ("-o", "--out", "--output")


def out_option(parser, help: str, required: bool = False, dest: str = "output", metavar: str = "FILE", **kw) -> None:
    """The output of a command that writes: ``-o``, ``--out`` and ``--output`` alike (``args.<dest>``)."""
    parser.add_argument(*OUT_OPTIONS, dest=dest, required=required, metavar=metavar, help=help, **kw)


def example(parser, *commands: str) -> None:
    """The examples shown at the end of the command's --help (working command lines)."""
    parser.epilog = ("example:\n" if len(commands) == 1 else "examples:\n") + "\n".join(f"  {c}" for c in commands)


def file_argument(parser, dest: str, metavar: str, help: str) -> None:
    """An input given as the positional ``METAVAR`` or as the option ``--<dest>`` (as every command
    that takes a model or a table accepts it); :func:`file_value` reads it."""
    parser.add_argument(dest, metavar=metavar, nargs="?", default=None, help=f"{help} (or --{dest} {metavar})")
    parser.add_argument(f"--{dest}", dest=f"{dest}_option", metavar=metavar, default=None,
                        help=f"the same as the positional {metavar}")


def file_value(args, dest: str) -> str:
    """The path given by :func:`file_argument`'s positional or option; UserError if neither or two
    different ones are given."""
    pos, opt = getattr(args, dest), getattr(args, f"{dest}_option")
    if pos is None and opt is None:
        raise UserError(f"the {dest} is required: give it as {dest.upper()} or --{dest} {dest.upper()}")
    if pos is not None and opt is not None and pos != opt:
        raise UserError(f"two {dest}s given ({pos} and --{dest} {opt}): give one")
    return pos if pos is not None else opt


def add_model_options(parser: argparse.ArgumentParser, what: str = "the model") -> None:
    """The options that configure a model (proxy, rate estimator, terms, combiner, ranges), shared by
    `hdrg fit` and `hdrg diagnose` (its starting model); the defaults shown are the fit's policy
    (host_tools.fitting.fit_pipeline.fit_policy)."""
    parser.add_argument("--proxy", choices=PROXY_KINDS, default=None,
                        help="temperature proxy: freq (drive frequency, default when present) or temp (temp_c)")
    from host_tools.fitting.fit_pipeline import fit_policy
    from host_tools.golden.reversal import COMBINERS, ORDERS

    policy = fit_policy()
    DEFAULT_RATE = dict(zip(("estimator", "n", "shift"), policy.rate_default))
    DEFAULT_RATE_SELECTION_MR, DEFAULT_TERMS = policy.rate_selection_mr, policy.terms
    DEFAULT_ORDER, DEFAULT_COMBINER, DEFAULT_SETTLE_S = policy.order, policy.combiner, policy.settle_s
    def short(e, n, s):     # an estimator as the help names it: diff, diffn 16, lsq 32, iir 9
        return e if e == "diff" else f"{e} {s if e == 'iir' else n}"
    preferred = short(*policy.rate_preferred)

    parser.add_argument("--rate-estimator", default=None, choices=ESTIMATORS + ("auto",),
                        help=f"proxy-rate estimator of {what} (default: {DEFAULT_RATE['estimator']}"
                             + ("; hdrg fit on mode-reversal logs: auto" if DEFAULT_RATE_SELECTION_MR == "auto" else "")
                             + f"; diff is the "
                             f"paper's consecutive difference; auto (hdrg fit only): {preferred} unless another of "
                             + ", ".join(short(*c) for c in policy.rate_candidates if c != policy.rate_preferred)
                             + f" has a cross-validated rms below {policy.rate_prefer_margin:g} x {preferred}'s, "
                             f"reported in model.json)")
    parser.add_argument("--rate-n", type=int, default=None,
                        help=f"window length n of diffn/lsq [samples] (default: {DEFAULT_RATE['n']})")
    parser.add_argument("--rate-shift", type=int, default=None,
                        help=f"iir coefficient 2^-shift (default: {DEFAULT_RATE['shift']})")
    parser.add_argument("--terms", default=None,
                        help=f"terms of {what}: all (the paper's 16 terms) | auto (cross-validated selection) "
                             f"| k0,k1,... | groups const,temp,rate,cross (default: {DEFAULT_TERMS})")
    parser.add_argument("--order", choices=ORDERS, default=None,
                        help=f"mode-reversal logs only: regress_first (two coefficient banks by mode, the combiner "
                             f"pairs the residuals) or combine_first (legacy: combine, then one bank) "
                             f"(default: {DEFAULT_ORDER})")
    parser.add_argument("--combiner", choices=COMBINERS, default=None,
                        help=f"mode-reversal combiner (mode-reversal logs only): pair (the paper), trend (ours) or "
                             f"none (regress_first only: joint regression alone) (default: {DEFAULT_COMBINER})")
    parser.add_argument("--settle", type=float, default=None,
                        help=f"mode-reversal logs only: settling time excluded after each exchange [s] "
                             f"(default: {DEFAULT_SETTLE_S:g})")
    parser.add_argument("--proxy-range", default=None, help="declared proxy range LO,HI in proxy units (default: training range +10%%)")
    parser.add_argument("--rate-range", default=None, help="declared largest |d proxy/dt| [proxy units/s] (default: from data)")


def add_engine_options(parser: argparse.ArgumentParser, order: str = "") -> None:
    """``--workers N`` / ``--scheduler ADDRESS`` (exclusive): the engine of host_tools.lot.parallel;
    ``order``: what the records' order is (e.g. "device order"), said in --workers' help."""
    engine = parser.add_mutually_exclusive_group()
    engine.add_argument("--workers", type=int, default=None, metavar="N",
                        help="local worker processes, one thread each (default: all cores; 1: in this process)"
                             + (f"; the records are the serial run's, in {order}" if order else ""))
    engine.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on a Dask distributed cluster (e.g. tcp://host:8786; workers started with "
                             "--nthreads 1) instead of local processes")


def add_port_options(parser: argparse.ArgumentParser) -> None:
    """--port and --baud of the commands that talk to the controller."""
    parser.add_argument("--port", required=True, help="serial port or pyserial URL (/dev/ttyUSB0, /dev/pts/5, loop://)")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")


def add_random_family_options(parser: argparse.ArgumentParser) -> None:
    """Options of the random (foreign) simulator family, added to `hdrg simulate`."""
    from host_tools.simulation.sim_foreign import EFFECT_KINDS

    parser.add_argument("--family", choices=("hdrg", "random"), default="hdrg",
                        help="simulator family: hdrg (the calibrated one, default) or random (the foreign, "
                             "randomized-physics devices of host_tools.simulation.sim_foreign; a device is --seed)")
    parser.add_argument("--chamber-rate", type=float, default=None, metavar="CPM",
                        help="random family: chamber ramp rate [degC/min] (default 4)")
    parser.add_argument("--power-on", type=int, default=0, metavar="K",
                        help="random family: power-on index (selects the damping change; default 0)")
    parser.add_argument("--noise-seed", type=int, default=0, help="random family: noise seed (default 0)")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help=f"random family: undeclared effect, repeatable; one of {', '.join(EFFECT_KINDS)}")
    parser.add_argument("--strength", type=float, default=1.0, help="random family: effect strength (default 1)")
    parser.add_argument("--no-thermal", action="store_true",
                        help="random family: the noise-only floor run (every bias term zeroed)")
    parser.add_argument("--describe", action="store_true",
                        help="random family: print the device's parameters as JSON, then exit")


# -- checked values and paths ------------------------------------------------------------------------

def positive_seconds(text, option: str, upper: float) -> float:
    """``text`` as a number of seconds in (0, upper]; UserError (a ValueError) naming ``option`` and the allowed
    range for anything else (negative, zero, NaN, inf, not a number)."""
    import math
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise UserError(f"{option} {text!r}: not a number of seconds") from None
    if not (math.isfinite(value) and 0 < value <= upper):
        raise UserError(f"{option} {text}: must be a number of seconds in (0, {upper:g}]")
    return value


def check_settle(settle) -> None:
    """UserError unless ``--settle`` (add_model_options; None: the default) is a finite number of
    seconds >= 0."""
    import math
    from host_tools.errors import UserError
    if settle is not None and not (math.isfinite(settle) and settle >= 0):
        raise UserError(f"--settle {settle:g}: must be a finite number of seconds >= 0")


def seconds_type(option: str, upper: float, zero: str | None = None):
    """An argparse ``type`` for a duration option: seconds in (0, upper], or also 0 when ``zero``
    (its meaning, e.g. "never") is given; argparse turns the ValueError into a usage error that names
    the option, the value and the range."""
    def parse(text):
        try:
            if zero is not None and float(text) == 0.0:
                return 0.0
            return positive_seconds(text, option, upper)
        except ValueError as exc:
            extra = f" or 0 ({zero})" if zero is not None else ""
            raise argparse.ArgumentTypeError(f"{exc}{extra}") from None
    parse.__name__ = "seconds"
    return parse


def distinct_outputs(outputs: dict) -> None:
    """ValueError when two outputs of one command (option -> path; None entries ignored) resolve
    to the same file (existing: os.path.samefile; else the resolved real paths): the second would
    overwrite the first."""
    from host_tools.atomic import same_file
    named = [(opt, path) for opt, path in outputs.items() if path is not None]
    for i, (opt_a, a) in enumerate(named):
        for opt_b, b in named[i + 1:]:
            if same_file(a, b):
                raise UserError(f"{opt_a} {a} and {opt_b} {b} are the same file: one output would overwrite "
                                 f"the other (give each its own file)")


def regular_input(path, option: str = "input") -> None:
    """ValueError unless the existing ``path`` is a regular file (a FIFO, a device such as
    /dev/zero, a socket or a directory would block or never end); a missing path is left to the
    reader's own message."""
    from host_tools.jsonread import check_regular
    if path is not None:
        check_regular(path, option)


def writable_output(path, option: str = "-o") -> None:
    """ValueError for an output that would block or is not a file: a directory, a FIFO that no
    process is reading (writing to it would wait forever), a socket.  A regular file, a missing
    path, a terminal or a device such as /dev/null, and a FIFO with a reader are accepted (the
    FIFO's probe stays open until the process exits, so the reader sees one stream)."""
    import os
    import stat
    if path is None:
        return
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except OSError:
        return
    if stat.S_ISDIR(st.st_mode):
        raise UserError(f"{option} {path}: is a directory, not a file to write")
    if stat.S_ISSOCK(st.st_mode):
        raise UserError(f"{option} {path}: is a socket, not a file to write")
    if stat.S_ISFIFO(st.st_mode):
        from host_tools.atomic import FifoWithoutReader, fifo_writer
        try:
            fd = fifo_writer(path)
        except FifoWithoutReader as exc:
            raise UserError(f"{option} {exc}") from None
        _HELD_WRITERS.append(fd)    # kept open until exit: closing it now would end the reader's input
        #                             (EOF) before the real writer opens, which would then wait forever


_HELD_WRITERS: list = []


def _close_held() -> None:
    import os
    while _HELD_WRITERS:
        try:
            os.close(_HELD_WRITERS.pop())
        except OSError:
            pass


atexit.register(_close_held)
