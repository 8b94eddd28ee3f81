"""`hdrg bench NAME ...`: measurement benchmarks that take minutes, kept out of the default tests.

Registry ``BENCHMARKS``: name -> module.  A benchmark module defines ``configure_cli(parser)`` and
``run_cli(args) -> int`` like every stage module; a module that is not importable on this branch
(e.g. ``host_tools.bench_loop`` before its branch is merged) is not offered.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util

BENCHMARKS = {"accuracy": "host_tools.bench_accuracy", "loop": "host_tools.bench_loop"}


def available() -> dict:
    """name -> module of the benchmarks importable here."""
    out = {}
    for name, module in BENCHMARKS.items():
        try:
            if importlib.util.find_spec(module) is not None:
                out[name] = module
        except ModuleNotFoundError:
            pass
    return out


def configure_cli(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    sub.required = True
    for name, module in available().items():
        mod = importlib.import_module(module)
        doc = (mod.__doc__ or name).strip().split("\n\n")[0]
        p = sub.add_parser(name, help=doc.split("\n")[0], description=doc)
        mod.configure_cli(p)
        p.set_defaults(_bench_module=module)


def run_cli(args) -> int:
    return int(importlib.import_module(args._bench_module).run_cli(args) or 0)
