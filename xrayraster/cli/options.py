"""Options several commands share: ``--scan-file`` (with its deprecated spellings) and integer checks."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _int_at_least(lowest: int):
    """An argparse type: an integer >= ``lowest``."""

    def check(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lowest}, got {text!r}") from None
        if value < lowest:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lowest}, got {value}")
        return value

    return check


nonnegative_int = _int_at_least(0)
positive_int = _int_at_least(1)


class _DeprecatedScanFile(argparse.Action):
    """An older spelling of ``--scan-file``: still works, and says so on stderr (one line)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"xrayraster: note: {option_string} is deprecated; use --scan-file {values}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_scan_file(parser, help: str, *, deprecated: str) -> None:
    """``--scan-file SCAN.json`` (required), and ``deprecated`` (e.g. ``--geometry``), its hidden older spelling."""
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--scan-file", dest="scan_file", metavar="SCAN.json", type=Path, help=help)
    group.add_argument(deprecated, dest="scan_file", metavar="SCAN.json", type=Path, action=_DeprecatedScanFile,
                       help=argparse.SUPPRESS)
