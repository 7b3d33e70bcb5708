"""Output checks every command makes before any work: no output can destroy data.

:func:`check_outputs` refuses (:class:`~xrayraster.core.errors.ConfigError`, exit status 2):

- a main output (``-o``) that does not end in ``.tif``/``.tiff``: the quick-look PNG goes
  beside it as ``OUT.png``, so the two can never be one file;
- an output that is an input (the same path, the same path once links and ``..`` are resolved,
  or the same file by :func:`os.path.samefile`), side outputs (quick-look, fractions) included;
- two outputs that are one file;
- an output that is an existing directory, or an existing file xrayraster did not write
  (:func:`~xrayraster.core.ownership.check_replaceable_files`: only our own earlier outputs are
  replaced; an output that is a link is written where it points);
- an output directory that cannot be written (:func:`~xrayraster.core.files.probe_writable`).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..core.errors import ConfigError
from ..core.files import probe_writable
from ..core.ownership import check_replaceable_files

TIFF_SUFFIXES = (".tif", ".tiff")


def check_main_output(out: Path) -> None:
    if out.suffix.lower() not in TIFF_SUFFIXES:
        raise ConfigError(f"-o {out}: the output must be a .tif or .tiff file (its quick-look PNG goes beside it); "
                          f"use e.g. -o {out.with_suffix('.tif')}")


def _same_file(a: Path, b: Path) -> bool:
    if os.path.abspath(a) == os.path.abspath(b) or os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_outputs(outputs, inputs, *, main_is_tiff: bool = True) -> None:
    """Refuse outputs that would destroy data or cannot be written (module docstring).

    ``outputs``: the main output (``-o``) first, then its side outputs; ``inputs``: every file
    the command reads. ``main_is_tiff``: the main output must be a TIFF (False for a command whose
    outputs are other files, which checks their suffixes itself).
    """
    outputs = [Path(p) for p in outputs]
    inputs = [Path(p) for p in inputs]
    if main_is_tiff:
        check_main_output(outputs[0])
    for out in outputs:
        for source in inputs:
            if _same_file(out, source):
                what = "-o" if out == outputs[0] else f"the output {out} (beside -o {outputs[0]})"
                raise ConfigError(f"{what} would overwrite the input {source}; choose another -o")
        if out.is_dir():
            raise ConfigError(f"cannot write {out}: it is a directory; give a file name"
                              + (" ending in .tif" if main_is_tiff else ""))
    for i, a in enumerate(outputs):
        for b in outputs[i + 1:]:
            if _same_file(a, b):
                raise ConfigError(f"outputs {a} and {b} are one file; choose another -o")
    for directory in dict.fromkeys(out.parent for out in check_replaceable_files(outputs)):
        probe_writable(directory, outputs[0])
