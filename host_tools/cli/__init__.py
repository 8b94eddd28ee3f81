"""`hdrg`: the command-line entry point, the registry of commands and the error boundary.

The commands layer: each subcommand is one small module of this package (``host_tools.cli.fit``,
...) that defines ``configure(parser)`` (adds its arguments) and ``run(args) -> int`` (exit code);
it parses and checks the arguments and calls the Python API (host_tools.api) or plain functions
of the stage modules, which hold no argparse.  Shared option groups are in ``host_tools.cli.options``.
The parser imports only the module of the command named (`hdrg --help` and `--version` import none).
Errors that the user can fix (:func:`user_error`: host_tools.errors.HdrgError, the project's other
ValueError classes, a ValueError raised by the project's own checks) and every OSError (missing,
unreadable or directory paths, a full disk) are printed as one line ``hdrg <cmd>: error: ...`` with
exit code 2 and no traceback; ``hdrg --debug CMD ...`` shows the traceback instead.  Any other
exception is a bug: it keeps its traceback (exit 1).  Ctrl-C exits with 130; a closed stdout
(``hdrg ... | head``) exits quietly with 141 (128 + SIGPIPE), as Unix tools do.  Warnings go to
stderr as ``hdrg <cmd>: warning: ...``.
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

# command -> (module, one-line help); the order is the workflow's: make or record a run, fit, apply and
# check, quantize and export, load into the controller; then the tools around it
COMMANDS = {
    "simulate": ("host_tools.cli.simulate", "generate a simulated run log (virtual gyroscope in a chamber)"),
    "capture": ("host_tools.cli.capture", "record a run log from the gyroscope's controller over a serial port"),
    "fit": ("host_tools.cli.fit", "fit the 17-coefficient bias model to run logs"),
    "compensate": ("host_tools.cli.compensate", "apply a bias model to a run log (float golden or fixed point)"),
    "report": ("host_tools.cli.report", "before/after tables and figures of a model on run logs"),
    "metrics": ("host_tools.cli.metrics", "the paper's figures of merit of run logs or compensated outputs"),
    "diagnose": ("host_tools.cli.diagnose", "trace a model's residual to a missing effect, add it through k7, report before/after"),
    "quantize": ("host_tools.cli.quantize", "quantize a bias model into the fixed-point coefficient table (table.json)"),
    "export": ("host_tools.cli.export", "export a coefficient table as a C header, table.json and a $readmemh memory file"),
    "upload": ("host_tools.cli.upload", "load a coefficient table into the controller (ack, read back, compare)"),
    "device": ("host_tools.cli.device", "virtual gyroscope controller on a pseudo-terminal or a pyserial URL"),
    "vectors": ("host_tools.cli.vectors", "deterministic test vectors: generate, verify, check an external implementation"),
    "cost": ("host_tools.cli.cost", "build and run the pipeline on Cortex-M4/M7 (QEMU), iCE40/7-series (Yosys) or the host: cycles, size"),
    "lot": ("host_tools.cli.lot", "calibrate a production lot: fit, check, quantize, export every device; report, resume"),
    "paper": ("host_tools.cli.paper", "reproduce every experiment of Chen et al. 2022 on the simulator"),
    "bench": ("host_tools.cli.bench", "measurement benchmarks: accuracy on random foreign devices, the closed loop"),
    "demo": ("host_tools.cli.demo", "simulate -> fit -> compensate -> report on embedded defaults"),
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


_ALL = "*"      # build_parser(): every command's options


class _HelpFormatter(argparse.HelpFormatter):
    """Fills the paragraphs of a description or epilog as argparse does, but keeps a paragraph of
    indented lines (the examples) line by line."""

    def _fill_text(self, text, width, indent):
        paragraphs = text.split("\n\n")
        return "\n\n".join("\n".join(indent + line for line in par.splitlines())
                             if any(line.startswith("  ") for line in par.splitlines())
                             else super(_HelpFormatter, self)._fill_text(par, width, indent) for par in paragraphs)


def build_parser(command: str | None = _ALL) -> argparse.ArgumentParser:
    """The parser of `hdrg`.  ``command``: the one command whose module is imported and whose options
    are built; the other commands are listed by name and help only, so that `hdrg --version`,
    `hdrg --help` and `hdrg CMD ...` import one command module at most (None: none; the default:
    every command, for documentation and tests).  A command's examples are its parser's epilog."""
    parser = argparse.ArgumentParser(
        prog="hdrg",
        description="Temperature-drift compensation toolchain for mode-reversal MEMS gyroscopes "
                    "(Chen et al., Micromachines 2022, 13, 1557).",
        epilog="workflow: hdrg simulate -o run.csv (or hdrg capture), hdrg fit run.csv -o model.json, "
               "hdrg report held_out.csv --model model.json --out report/, hdrg quantize model.json -o table.json, "
               "hdrg export table.json -o out/, hdrg upload table.json --port PORT; "
               "'hdrg COMMAND --help' shows a command's options and an example.")
    parser.add_argument("--version", action="version", version=f"hdrg {_version()}")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, helptext) in _available().items():
        p = sub.add_parser(name, help=helptext, description=helptext[0].upper() + helptext[1:] + ".",
                           formatter_class=_HelpFormatter)
        if command == _ALL or command == name:
            importlib.import_module(module).configure(p)
            if name in _EXAMPLES and f"hdrg {name}" not in (p.epilog or ""):
                p.epilog = (p.epilog + "\n\n" if p.epilog else "") + _EXAMPLES[name]
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show the Python traceback of an error")
        p.set_defaults(_module=module)
    return parser


# examples of the commands whose module's epilog has none
_EXAMPLES = {
    "report": "example:\n  hdrg report held_out.csv --model model.json --out report/",
    "demo": "example:\n  hdrg demo --out demo/",
}


def _command_word(argv) -> str | None:
    """The command named in ``argv`` (the first word that is not an option: the top-level options
    take no value), or None."""
    for word in argv:
        if word == "--":
            return None
        if not word.startswith("-"):
            return word
    return None


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that cleanups run."""


_HANDLER_PID = [None]    # the process that installed _terminate (main)


def _terminate(signum, frame):
    """SIGTERM in the command: unwind (cleanups run).  In a process forked from it (a pool worker
    before its own set-up) the default action instead: the process ends at once, without
    unwinding into queues or pipes that nobody reads any more."""
    if os.getpid() != _HANDLER_PID[0]:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTERM)
        return
    raise _Terminated()


def _describe(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        name = exc.filename if exc.filename2 is None else f"{exc.filename} -> {exc.filename2}"
        return f"{name}: {exc.strerror}"
    return str(exc) or type(exc).__name__


def startup_problem() -> str | None:
    """Why no command can run here, or None: standard output closed (``>&-``: what the command
    prints would be lost), or NUMBA_NUM_THREADS an integer below 1 (numba refuses to import; a
    value that is not an integer numba ignores with its own warning)."""
    if sys.stdout is None:
        return ("standard output is closed (>&-): what hdrg prints would be lost; redirect it instead "
                "(e.g. >/dev/null)")
    text = os.environ.get("NUMBA_NUM_THREADS")
    if text is not None:
        try:
            n = int(text)
        except ValueError:
            n = None
        if n is not None and n < 1:
            return f"NUMBA_NUM_THREADS={text.strip()}: must be a number of threads >= 1 (or unset)"
    return None


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    problem = startup_problem()      # stdout closed, NUMBA_NUM_THREADS < 1: before any command module is imported
    if problem is not None:
        if sys.stderr is not None:
            print(f"hdrg: error: {problem}", file=sys.stderr)
        return 2
    word = _command_word(argv)
    parser = build_parser(word if word in COMMANDS else None)
    args = parser.parse_args(argv)
    mod = importlib.import_module(args._module)
    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread:
        # SIGTERM unwinds like Ctrl-C, so atomic writers remove their temporary files
        _HANDLER_PID[0] = os.getpid()
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
    except Exception as exc:
        if args.debug or not user_error(exc):
            raise       # a bug: its traceback, exit 1
        print(f"hdrg {args.command}: error: {_describe(exc)}", file=sys.stderr)
        return 2


_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # holds host_tools/, firmware_ref/
_OWN = tuple(os.path.join(_ROOT, pkg) + os.sep for pkg in ("host_tools", "firmware_ref"))


def user_error(exc: BaseException) -> bool:
    """True for an error the user can fix, printed as one line: an HdrgError, an OSError, a
    ValueError subclass defined in this project (firmware_ref.table.TableError,
    host_tools.vectors.spec.VectorsError, ...) or a plain ValueError raised by this project's code
    (the last frame of its traceback in host_tools/ or firmware_ref/: an argument check).  Anything
    else (TypeError, KeyError, IndexError, AttributeError, a ValueError from a library) is a bug."""
    from host_tools.errors import HdrgError
    if isinstance(exc, (HdrgError, OSError)):
        return True
    if not isinstance(exc, ValueError):
        return False
    if type(exc).__module__.split(".")[0] in ("host_tools", "firmware_ref"):
        return True
    if type(exc) is not ValueError or exc.__traceback__ is None:
        return False
    tb = exc.__traceback__
    while tb.tb_next is not None:
        tb = tb.tb_next
    return os.path.abspath(tb.tb_frame.f_code.co_filename).startswith(_OWN)
