"""``python -m panto``: the same command line as the ``panto`` console script."""
import sys

from panto.cli import main

if __name__ == "__main__":
    sys.exit(main())
