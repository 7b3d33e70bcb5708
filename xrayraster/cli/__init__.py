"""The xrayraster command line, one module per command; nothing in the package imports it."""

from __future__ import annotations

import argparse
import logging
import sys

from .. import __version__
from ..core.errors import XrayrasterError
from . import reconstruct, render, voxelize


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="xrayraster", description="X-ray CT simulation from triangle meshes.")
    parser.add_argument("--version", action="version", version=f"xrayraster {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True)
    for command in (render, reconstruct, voxelize):
        command.add_parser(subparsers)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        return args.run(args)
    except XrayrasterError as exc:
        print(f"xrayraster: error: {exc}", file=sys.stderr)
        return 2
