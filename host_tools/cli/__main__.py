"""``python -m host_tools.cli ...``: the same as ``hdrg ...``."""
import sys

if __name__ == "__main__":
    from host_tools.cli import main
    sys.exit(main())
