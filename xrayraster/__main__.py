"""``python -m xrayraster``: the same command line as the ``xrayraster`` console script."""

import sys

from .cli import run

sys.exit(run())
