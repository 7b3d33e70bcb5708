"""The xrayraster command line, one module per command; nothing in the package imports it.

Exit status: 0 done; 2 bad input (the message names the file, field or flag and the fix);
130 interrupted (Ctrl-C); 1 anything else: a file-system failure during the work (disk full), or
a bug. Every failure is one line on stderr; a bug's traceback is printed with ``-v``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import traceback
import warnings

from .. import __version__
from ..core.errors import XrayrasterError, XrayrasterWarning
from . import compare, reconstruct, render, scan, voxelize, weave

EXIT_OK, EXIT_UNEXPECTED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


def one_line(text) -> str:
    """``text`` on one line (its lines joined with '; ')."""
    return "; ".join(line.strip() for line in str(text).splitlines() if line.strip())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="xrayraster", description="X-ray CT simulation from triangle meshes.")
    parser.add_argument("--version", action="version", version=f"xrayraster {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True)
    for command in (scan, weave, render, reconstruct, voxelize, compare):
        command.add_parser(subparsers)
    try:
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        print("xrayraster: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        with warnings.catch_warnings():  # restores showwarning for a caller of main (tests)
            warnings.showwarning = _show_warning
            warnings.simplefilter("always", XrayrasterWarning)  # each run says it, not only a process's first
            return args.run(args)
    except XrayrasterError as exc:
        print(f"xrayraster: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("xrayraster: interrupted; no output written under its final name", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:  # the file system during the work: disk full, a directory removed meanwhile
        if args.verbose:
            traceback.print_exc()
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"xrayraster: error: {one_line(exc.strerror or exc)}{where}", file=sys.stderr)
        return EXIT_UNEXPECTED
    except Exception as exc:  # a bug
        if args.verbose:
            traceback.print_exc()
        hint = "" if args.verbose else "; run with -v for the traceback"
        print(f"xrayraster: unexpected error (a bug, please report it): {type(exc).__name__}: {one_line(exc)}{hint}",
              file=sys.stderr)
        return EXIT_UNEXPECTED


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """xrayraster's own warnings as one line on stderr, like its errors; others as Python prints them."""
    if issubclass(category, XrayrasterWarning):
        print(f"xrayraster: warning: {one_line(message)}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))
