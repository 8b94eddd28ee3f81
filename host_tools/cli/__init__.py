"""`hdrg`: the command-line entry point, the registry of commands and the error boundary.

The commands layer: each subcommand is one small module of this package (``host_tools.cli.fit``,
...) that defines ``configure(parser)`` (adds its arguments) and ``run(args) -> int`` (exit code);
it parses and checks the arguments and calls plain functions of the stage modules, which hold no
argparse.  Shared option groups are in ``host_tools.cli.options``.  Errors that the user can fix
(bad input files, refused models: every ValueError subclass of the project) and every OSError
(missing, unreadable or directory paths, a full disk) are printed as one line
``hdrg <cmd>: error: ...`` with exit code 2 and no traceback; ``hdrg --debug CMD ...`` shows the
traceback instead.  Ctrl-C exits with 130; a closed stdout (``hdrg ... | head``) exits quietly
with 141 (128 + SIGPIPE), as Unix tools do.  Warnings go to stderr as ``hdrg <cmd>: warning: ...``.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import threading
import sys
import warnings

# command -> (module, one-line help); the order is the order of the data flow
COMMANDS = {
    "simulate": ("host_tools.cli.simulate", "generate a simulated run log (virtual gyroscope in a chamber)"),
    "metrics": ("host_tools.cli.metrics", "the paper's figures of merit of run logs or compensated outputs"),
    "fit": ("host_tools.cli.fit", "fit the 17-coefficient bias model to run logs"),
    "diagnose": ("host_tools.cli.diagnose", "trace a model's residual to a missing effect, add it through k7, report before/after"),
    "quantize": ("host_tools.cli.quantize", "quantize a bias model into the fixed-point coefficient table (table.json)"),
    "export": ("host_tools.cli.export", "export a coefficient table as a C header, table.json and a $readmemh memory file"),
    "compensate": ("host_tools.cli.compensate", "apply a bias model to a run log (float golden or fixed point)"),
    "report": ("host_tools.cli.report", "before/after tables and figures of a model on run logs"),
    "paper": ("host_tools.cli.paper", "reproduce every experiment of Chen et al. 2022 on the simulator"),
    "vectors": ("host_tools.cli.vectors", "deterministic test vectors: generate, verify, check an external implementation"),
    "capture": ("host_tools.cli.capture", "record a run log from the gyroscope's controller over a serial port"),
    "upload": ("host_tools.cli.upload", "load a coefficient table into the controller (ack, read back, compare)"),
    "device": ("host_tools.cli.device", "virtual gyroscope controller on a pseudo-terminal or a pyserial URL"),
    "demo": ("host_tools.cli.demo", "simulate -> fit -> compensate -> report on embedded defaults"),
    "bench": ("host_tools.cli.bench", "measurement benchmarks: accuracy on random foreign devices, the closed loop"),
    "cost": ("host_tools.cli.cost", "build and run the pipeline on Cortex-M4/M7 (QEMU), iCE40/7-series (Yosys) or the host: cycles, size"),
}


def _available():
    out = {}
    for name, (module, helptext) in COMMANDS.items():
        try:
            importlib.util.find_spec(module)
        except ModuleNotFoundError:
            continue
        if importlib.util.find_spec(module) is not None:
            out[name] = (module, helptext)
    return out


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("hdrg")
    except PackageNotFoundError:  # pragma: no cover - run from a source tree without install
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hdrg",
        description="Temperature-drift compensation toolchain for mode-reversal MEMS gyroscopes "
                    "(Chen et al., Micromachines 2022, 13, 1557).")
    parser.add_argument("--version", action="version", version=f"hdrg {_version()}")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, helptext) in _available().items():
        mod = importlib.import_module(module)
        p = sub.add_parser(name, help=helptext, description=helptext[0].upper() + helptext[1:] + ".")
        mod.configure(p)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show the Python traceback of an error")
        p.set_defaults(_module=module)
    return parser


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that cleanups run."""


def _terminate(signum, frame):
    raise _Terminated()


def _describe(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        name = exc.filename if exc.filename2 is None else f"{exc.filename} -> {exc.filename2}"
        return f"{name}: {exc.strerror}"
    return str(exc) or type(exc).__name__


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    mod = importlib.import_module(args._module)
    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread:
        # SIGTERM unwinds like Ctrl-C, so atomic writers remove their temporary files
        old_term = signal.signal(signal.SIGTERM, _terminate)
    try:
        return _run(args, mod)
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, old_term)


def _completed_note(first: int) -> str:
    """For an interrupted command: the outputs it had already written complete (atomic writers:
    every other output is absent), so a stop after the last rename is not read as a lost file.
    ``first``: the length of atomic.COMPLETED when the command started."""
    from host_tools import atomic
    done = atomic.COMPLETED[first:]
    if not done:
        return " (no output written)"
    return "; written complete before the stop: " + ", ".join(done)


def _run(args, mod) -> int:
    from host_tools import atomic
    first = len(atomic.COMPLETED)
    try:
        with warnings.catch_warnings():     # restores the warning machinery after the command
            warnings.simplefilter("default")
            warnings.showwarning = lambda message, category, *a, **k: print(
                f"hdrg {args.command}: warning: {message}", file=sys.stderr)
            rc = int(mod.run(args) or 0)
        sys.stdout.flush()      # a closed pipe shows here, not at interpreter exit
        return rc
    except BrokenPipeError:
        # the reader of stdout went away (`hdrg ... | head`): quiet exit, as Unix tools do
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except KeyboardInterrupt:
        print(f"hdrg {args.command}: interrupted{_completed_note(first)}", file=sys.stderr)
        return 130
    except _Terminated:
        print(f"hdrg {args.command}: terminated{_completed_note(first)}", file=sys.stderr)
        return 128 + signal.SIGTERM
    except (ValueError, OSError, LookupError) as exc:
        if args.debug:
            raise
        print(f"hdrg {args.command}: error: {_describe(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
