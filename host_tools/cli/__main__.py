"""``python -m host_tools.cli ...``: the same as ``hdrg ...``."""
import sys

from host_tools.cli import main

sys.exit(main())
