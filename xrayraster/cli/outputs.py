"""Output checks every command makes before any work: no output can destroy data.

:func:`check_outputs` refuses (:class:`~xrayraster.core.errors.ConfigError`, exit status 2):

- a main output (``-o``) that does not end in ``.tif``/``.tiff``: the quick-look PNG goes
  beside it as ``OUT.png``, so the two can never be one file;
- an output that is an input (the same path, the same path once links and ``..`` are resolved,
  or the same file by :func:`os.path.samefile`), side outputs (quick-look, fractions) included;
- two outputs that are one file;
- an output that is an existing directory;
- an output directory that cannot be written: it is probed by creating it (and any missing
  parents) and a temporary file in it, then removing both, as permission bits alone do not say
  (root ignores them; read-only mounts, ``/proc`` and a parent that is a regular file do not).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..core.errors import ConfigError

TIFF_SUFFIXES = (".tif", ".tiff")


def quicklook_path(out: Path) -> Path:
    """The quick-look PNG beside the TIFF ``out``."""
    return out.with_suffix(".png")


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


def _probe_directory(directory: Path, out: Path) -> None:
    """Create ``directory`` (and missing parents) and a file in it, then remove what was created."""
    missing = []
    d = directory
    while not d.exists() and d != d.parent:
        missing.append(d)
        d = d.parent
    created = []
    try:
        for m in reversed(missing):
            m.mkdir()
            created.append(m)
        if not directory.is_dir():
            raise NotADirectoryError(20, "not a directory")
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".xrayraster-probe.")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise ConfigError(f"cannot write {out}: its directory {directory} cannot be created or written ({reason}); "
                          "choose another -o") from None
    finally:
        for m in reversed(created):
            try:
                m.rmdir()
            except OSError:  # another process put something there meanwhile: leave it
                pass


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
    for directory in dict.fromkeys(out.parent for out in outputs):
        _probe_directory(directory, outputs[0])
