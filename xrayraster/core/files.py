"""Files written atomically: a reader never sees a half-written file, and a failed write leaves none."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _read_umask() -> int:
    """The process umask. Reading it means setting it, so this is done once, at import."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


# The mode that open(path, "w") gives a new file; mkstemp's temporaries are private (0600).
NEW_FILE_MODE = 0o666 & ~_read_umask()


def atomic_write(path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it into place.

    The file gets the mode of a newly created file, :data:`NEW_FILE_MODE`.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, NEW_FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
