"""`hdrg`: the command-line entry point.

Each subcommand lives in the module of its stage; that module defines ``configure_cli(parser)``
(adds its arguments) and ``run_cli(args) -> int`` (exit code).  Errors that the user can fix
(bad input files, refused models) are printed as one line ``hdrg <cmd>: error: ...`` with exit
code 2; nothing else is caught.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import warnings

# command -> (module, one-line help); the order is the order of the data flow
COMMANDS = {
    "simulate": ("host_tools.sim", "generate a simulated run log (virtual gyroscope in a chamber)"),
    "metrics": ("host_tools.metrics", "the paper's figures of merit of run logs or compensated outputs"),
    "fit": ("host_tools.fit", "fit the 17-coefficient bias model to run logs"),
    "diagnose": ("host_tools.diagnose", "trace a model's residual to a missing effect, add it through k7, report before/after"),
    "quantize": ("host_tools.quantize", "quantize a bias model into the fixed-point coefficient table (table.json)"),
    "export": ("host_tools.export", "export a coefficient table as a C header, table.json and a $readmemh memory file"),
    "compensate": ("host_tools.compensate", "apply a bias model to a run log (float golden or fixed point)"),
    "report": ("host_tools.report", "before/after tables and figures of a model on run logs"),
    "paper": ("host_tools.paper", "reproduce every experiment of Chen et al. 2022 on the simulator"),
    "vectors": ("host_tools.vectors", "deterministic test vectors: generate, verify, check an external implementation"),
    "capture": ("host_tools.serial_link", "record a run log from the gyroscope's controller over a serial port"),
    "upload": ("host_tools.serial_link", "load a coefficient table into the controller (ack, read back, compare)"),
    "device": ("host_tools.device", "virtual gyroscope controller on a pseudo-terminal or a pyserial URL"),
    "demo": ("host_tools.demo", "simulate -> fit -> compensate -> report on embedded defaults"),
    "bench": ("host_tools.bench", "measurement benchmarks: accuracy on random foreign devices, the closed loop"),
    "cost": ("host_tools.cost", "build and run the pipeline on Cortex-M4/M7 (QEMU), iCE40/7-series (Yosys) or the host: cycles, size"),
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hdrg",
        description="Temperature-drift compensation toolchain for mode-reversal MEMS gyroscopes "
                    "(Chen et al., Micromachines 2022, 13, 1557).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, helptext) in _available().items():
        mod = importlib.import_module(module)
        if not hasattr(mod, "configure_cli"):
            continue
        p = sub.add_parser(name, help=helptext, description=(mod.__doc__ or helptext).strip().split("\n\n")[0])
        mod.configure_cli(p)
        p.set_defaults(_module=module)
    return parser


def main(argv=None) -> int:
    from host_tools.runlog import RunLogError

    parser = build_parser()
    args = parser.parse_args(argv)
    mod = importlib.import_module(args._module)
    warnings.simplefilter("default")
    warnings.showwarning = lambda message, category, *a, **k: print(
        f"hdrg {args.command}: warning: {message}", file=sys.stderr)
    try:
        return int(mod.run_cli(args) or 0)
    except (RunLogError, ValueError, FileNotFoundError) as exc:
        print(f"hdrg {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
