"""``python -m host_tools.vectors ACTION ...``: the same as ``hdrg vectors``."""
import argparse
import sys

from host_tools.vectors import __doc__ as _doc
from host_tools.vectors.cli import configure_cli, run_cli

_parser = argparse.ArgumentParser(prog="hdrg vectors", description=_doc.split("\n\n")[0])
configure_cli(_parser)
try:
    sys.exit(run_cli(_parser.parse_args()))
except ValueError as _exc:
    print(f"hdrg vectors: error: {_exc}", file=sys.stderr)
    sys.exit(2)
