"""`hdrg bench NAME ...`: measurement benchmarks that take minutes, kept out of the default tests.

Registry ``BENCHMARKS``: name -> (command module, stage module).  A command module defines
``configure(parser)`` and ``run(args) -> int`` like every command; its help is the first paragraph
of the stage module's docstring.  A benchmark whose stage module is not importable on this branch
(e.g. ``host_tools.bench.loop`` before its branch is merged) is not offered.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util

BENCHMARKS = {"accuracy": ("host_tools.cli.bench_accuracy", "host_tools.bench.accuracy"),
              "measured": ("host_tools.cli.bench_measured", "host_tools.bench.measured"),
              "loop": ("host_tools.cli.bench_loop", "host_tools.bench.loop"),
              "startup": ("host_tools.cli.bench_startup", "host_tools.bench.startup")}


def available() -> dict:
    """name -> (command module, stage module) of the benchmarks importable here."""
    out = {}
    for name, (command, stage) in BENCHMARKS.items():
        try:
            if importlib.util.find_spec(stage) is not None and importlib.util.find_spec(command) is not None:
                out[name] = (command, stage)
        except ModuleNotFoundError:
            pass
    return out


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    sub.required = True
    parser.epilog = ("examples:\n  hdrg bench accuracy --devices 10 -o accuracy.json\n"
                     "  hdrg bench measured --only tofupilot -o measured.json\n  hdrg bench loop --runs 12 -o loop.json\n"
                     "  hdrg bench startup --devices 20 -o startup.json")
    for name, (command, stage) in available().items():
        doc = (importlib.import_module(stage).__doc__ or name).strip().split("\n\n")[0]
        p = sub.add_parser(name, help=doc.split("\n")[0], description=doc)
        importlib.import_module(command).configure(p)
        p.set_defaults(_bench_module=command)


def run(args) -> int:
    return int(importlib.import_module(args._bench_module).run(args) or 0)
