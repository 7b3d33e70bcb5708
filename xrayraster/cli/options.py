"""Options several commands share: ``--grid`` (with its deprecated spellings) and integer checks."""

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


def note_deprecated(old: str, new: str) -> None:
    """One line on stderr: ``old`` still works, ``new`` is its name now."""
    print(f"xrayraster: note: {old} is deprecated; use {new}", file=sys.stderr)


class _DeprecatedGrid(argparse.Action):
    """An older spelling of ``--grid`` (``--scan-file``, and before it ``--geometry`` or ``--volume``):
    still works, and says so on stderr, once a command."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest, None) is None:
            note_deprecated(option_string, f"--grid {values}")
        setattr(namespace, self.dest, values)


def add_grid(parser, help: str, *, deprecated: str) -> None:
    """``--grid GRID.json`` (required; io/grid_file.py), and its hidden older spellings: ``--scan-file``
    (the grid file's name until the TOML input of ``xrayraster scan`` took it) and ``deprecated``
    (e.g. ``--geometry``)."""
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--grid", dest="grid", metavar="GRID.json", type=Path, help=help)
    for old in ("--scan-file", deprecated):
        group.add_argument(old, dest="grid", metavar="GRID.json", type=Path, action=_DeprecatedGrid,
                           help=argparse.SUPPRESS)
