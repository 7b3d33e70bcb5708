"""Files written atomically: a reader never sees a half-written file, and a failed write leaves none.

The temporary is a hidden file beside the output, ``.NAME.<host>.<pid>.<random><suffix>``: the
writer's host tag (:data:`HOST_TAG`) and process id are in its name. A process killed mid-write
(SIGKILL, power loss) cannot remove its temporary, so every write of ``NAME`` first removes the
*stale* temporaries of ``NAME``: those written on this host by a process that no longer exists.
A temporary whose writer is alive (or may be: another user's process, or a process id the system
has since reused) is never touched, nor is one from another host (a shared file system) or one
in the older unnamed form (``.NAME.<random><suffix>``, written before the pid was in the name):
those are left for a person to remove.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import tempfile
import zlib
from contextlib import contextmanager
from pathlib import Path

from .errors import ConfigError


def _read_umask() -> int:
    """The process umask. Reading it means setting it, so this is done once, at import."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


# The mode that open(path, "w") gives a new file; mkstemp's temporaries are private (0600).
_UMASK = _read_umask()
NEW_FILE_MODE = 0o666 & ~_UMASK
NEW_DIR_MODE = 0o777 & ~_UMASK  # what mkdir gives; mkdtemp's are private (0700)

# Eight hex digits naming this host in temporaries' names (a CRC of the host name): process ids
# are only meaningful on the host (and in the process namespace) that issued them.
HOST_TAG = f"{zlib.crc32(socket.gethostname().encode()):08x}"


def _temporary_pattern(path: Path) -> re.Pattern:
    return re.compile(rf"\.{re.escape(path.name)}\.{HOST_TAG}\.(\d+)\.[A-Za-z0-9_]+{re.escape(path.suffix)}")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (on this host; a process of another user counts as alive)."""
    if pid <= 0:
        return True  # not a pid a writer can have: never treat it as dead
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: it exists, as another user's
        return True
    return True


def stale_temporaries(path) -> list[Path]:
    """The temporaries of ``path`` left by dead writers on this host (module docstring)."""
    path = Path(path)
    pattern = _temporary_pattern(path)
    try:
        names = os.listdir(path.parent)
    except OSError:
        return []
    stale = []
    for name in names:
        match = pattern.fullmatch(name)
        if match and int(match.group(1)) != os.getpid() and not _alive(int(match.group(1))):
            stale.append(path.parent / name)
    return sorted(stale)


def remove_stale_temporaries(path) -> list[Path]:
    """Remove :func:`stale_temporaries` of ``path``; returns those removed."""
    removed = []
    for tmp in stale_temporaries(path):
        try:
            tmp.unlink()
            removed.append(tmp)
        except FileNotFoundError:  # another writer of the same output removed it first
            pass
    return removed


def atomic_write(path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it into place.

    The file gets the mode of a newly created file, :data:`NEW_FILE_MODE`. Stale temporaries of
    ``path`` (module docstring) are removed first.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{HOST_TAG}.{os.getpid()}.", suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, NEW_FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path



def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` with :func:`atomic_write`."""
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))

@contextmanager
def atomic_directory(path, *, replaceable):
    """Build a directory of outputs under a temporary name beside ``path``, then move it into place.

    Yields the temporary directory (a ``Path``) to write into. On success an existing ``path`` is
    replaced only if ``replaceable(path)`` says it holds an earlier output of the same command
    (else :class:`~xrayraster.core.errors.ConfigError`, checked before any work); readers see the
    old directory or the new one, never a mix. On failure the temporary is removed and ``path`` is
    untouched. The swap is two renames (old aside, new in); a crash between them leaves the old
    output under ``.NAME.old.<host>.<pid>`` and no ``path``, never a half-written one.
    """
    path = Path(path)
    if path.exists() and not (path.is_dir() and (not any(path.iterdir()) or replaceable(path))):
        what = "a file" if not path.is_dir() else "a directory that holds other files"
        raise ConfigError(f"{path} is {what}, not an earlier output of this command; choose another output "
                          "directory or remove it")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.{HOST_TAG}.{os.getpid()}."))
    try:
        yield tmp
        os.chmod(tmp, NEW_DIR_MODE)
        if path.exists():
            old = path.parent / f".{path.name}.old.{HOST_TAG}.{os.getpid()}"
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
