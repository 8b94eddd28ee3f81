"""``python -m host_tools.vectors ACTION ...``: the same as ``hdrg vectors ACTION ...`` (the
command, its options and its error boundary are host_tools.cli's)."""
import sys

from host_tools.cli import main

sys.exit(main(["vectors", *sys.argv[1:]]))
