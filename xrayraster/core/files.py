"""Files and directories written atomically: a reader never sees a half-written output, and a
failed write leaves none. What an output may replace is :mod:`~xrayraster.core.ownership`'s rule.

The temporary is hidden beside the output, ``.NAME.<host>.<pid>.<random><suffix>`` (a directory
for :func:`atomic_directory`): the writer's host tag (:data:`HOST_TAG`) and process id are in its
name. A process killed mid-write (SIGKILL, power loss) cannot remove its temporary, so every
write of ``NAME`` first removes the *stale* temporaries of ``NAME``: those written on this host by
a process that no longer exists. A temporary whose writer is alive (or may be: another user's
process, or a process id the system has since reused) is never touched, nor is one from another
host (a shared file system) or one in the older unnamed form (``.NAME.<random><suffix>``, written
before the pid was in the name): those are left for a person to remove.
"""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import socket
import tempfile
import zlib
from contextlib import contextmanager
from pathlib import Path

from .errors import ConfigError
from .ownership import FILE_SUFFIXES, directory_entries, recorded_names, resolved_output


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
    return _stale(path.parent, _temporary_pattern(path))


def remove_stale_temporaries(path) -> list[Path]:
    """Remove :func:`stale_temporaries` of ``path``; returns those removed."""
    return _remove_temporaries(stale_temporaries(path))


def remove_stale_temporaries_in(directory) -> list[Path]:
    """Remove the stale temporaries of every output in ``directory``, not only one name's: what a
    killed pool of writers leaves, e.g. a dataset's half-built samples (the rule of
    :func:`stale_temporaries`)."""
    return _remove_temporaries(_stale(directory, _ANY_TEMPORARY))


# Any output's temporary: .NAME.<host>.<pid>.<random>[.suffix]
_ANY_TEMPORARY = re.compile(rf"\..+\.{HOST_TAG}\.(\d+)\.[A-Za-z0-9_]+(\.[A-Za-z0-9]+)?")


def _stale(directory, pattern: re.Pattern) -> list[Path]:
    """The entries of ``directory`` that ``pattern`` (group 1: the writer's pid) names as
    temporaries of a writer on this host that no longer exists."""
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    stale = []
    for name in names:
        match = pattern.fullmatch(name)
        if match and int(match.group(1)) != os.getpid() and not _alive(int(match.group(1))):
            stale.append(Path(directory) / name)
    return sorted(stale)


def _remove_temporaries(paths) -> list[Path]:
    removed = []
    for tmp in paths:
        try:
            remove_entry(tmp)  # a file, or an atomic_directory's folder
            removed.append(tmp)
        except FileNotFoundError:  # another writer of the same output removed it first
            pass
    return removed


def atomic_write(path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it into place.

    The file gets the mode of a newly created file, :data:`NEW_FILE_MODE`. Stale temporaries of
    ``path`` (module docstring) are removed first.
    """
    return atomic_writes([(path, write)])[0]


def atomic_writes(writes) -> list[Path]:
    """:func:`atomic_write` for several files, ``writes`` being (path, write) pairs: every
    temporary is written first, then they are renamed into place in the order given, so a failure
    while writing leaves none of the files. (A kill during the renames, a few system calls, can
    leave the first ones: a reader that needs all of them looks for the last.) Returns the paths."""
    temporaries = []
    try:
        for path, write in writes:
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            remove_stale_temporaries(path)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{HOST_TAG}.{os.getpid()}.",
                                       suffix=path.suffix)
            os.close(fd)
            temporaries.append((tmp, path))
            write(tmp)
            os.chmod(tmp, NEW_FILE_MODE)
        for tmp, path in temporaries:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in temporaries:
            Path(tmp).unlink(missing_ok=True)
        raise
    return [path for _, path in temporaries]


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` with :func:`atomic_write`."""
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def probe_writable(directory: Path, out: Path) -> None:
    """Refuse (:class:`~xrayraster.core.errors.ConfigError`, naming ``out``) a ``directory`` that
    cannot be written. It is probed by creating it (and missing parents) and a temporary file in it,
    then removing what was created, as permission bits alone do not say (root ignores them;
    read-only mounts, ``/proc`` and a parent that is a regular file do not)."""
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
                          "choose another output") from None
    finally:
        for m in reversed(created):
            try:
                m.rmdir()
            except OSError:  # another process put something there meanwhile: leave it
                pass


def directory_target(path, generator: str) -> Path:
    """Where an output directory named ``path`` goes (links resolved), refusing, before any work, a
    name with a file suffix (``-o out.tif``), a parent that cannot be written (:func:`probe_writable`)
    and an existing file."""
    path = Path(path)
    if path.suffix.lower() in FILE_SUFFIXES:
        raise ConfigError(f"{path}: {generator} writes a directory, and this name ends in {path.suffix} like a file; "
                          f"give a directory name such as {path.with_suffix('')}")
    target = resolved_output(path)
    probe_writable(target.parent, path)
    if target.exists() and not target.is_dir():
        raise ConfigError(f"{path} is a file, not a directory; {generator} writes a directory: choose another name")
    return target


def check_output_directory(path, *, marker: str, generator: str, overwrite: bool = False,
                           names=()) -> Path:
    """Refuse, before any work, an output directory ``generator`` may not write
    (:mod:`~xrayraster.core.ownership`). Returns ``path`` with links resolved.

    Refused: what :func:`directory_target` refuses; a directory holding foreign entries, unless
    ``overwrite``; with ``overwrite``, a foreign entry named as one of ``names`` (the files the
    command will write, as far as known). The message names the entries, clashes first.
    """
    target = directory_target(path, generator)
    if not target.exists():
        return target
    _, foreign = directory_entries(target, marker, generator)
    if not foreign:
        return target
    clashes = sorted(set(foreign) & set(names))
    named = clashes + [name for name in foreign if name not in clashes]  # what it would replace first
    shown = ", ".join(named[:3]) + (f" and {len(named) - 3} more" if len(named) > 3 else "")
    if not overwrite:
        raise ConfigError(f"{path} holds files that {generator} did not write ({shown}); they are never removed: "
                          "choose another directory, or pass --force (overwrite=True) to replace only this "
                          "command's earlier outputs and keep them")
    if clashes:
        raise ConfigError(f"{path}: {', '.join(clashes)} not written by {generator} would be replaced; "
                          "move it away or choose another directory")
    return target


@contextmanager
def atomic_directory(path, *, marker: str, generator: str, overwrite: bool = False, names=()):
    """Build a directory of outputs under a temporary name beside ``path``, then move it into place.

    Yields the temporary directory (a ``Path``) to write into; the body must write ``marker``, a
    JSON object with ``"generator": generator``, to which the names written are added as
    ``"files"`` (the record :mod:`~xrayraster.core.ownership` reads). What ``path`` may be is
    checked on entry (:func:`check_output_directory`: links resolved,
    a directory with foreign entries refused unless ``overwrite``) and again before the move.

    - ``path`` missing, empty, or holding only what an earlier output recorded: the new directory
      replaces it by two renames (old aside, new in), so readers see the old output or the new,
      never a mix; the old output's recorded files are then removed, and nothing else. A crash
      between the renames leaves the old output under ``.NAME.old.<host>.<pid>`` and no ``path``.
    - ``overwrite`` and foreign entries: each new file is renamed into ``path`` (atomic one by
      one), recorded files the new output lacks are removed, the marker comes last; the foreign
      entries stay as they were.

    On failure the temporary is removed and ``path`` is untouched. Stale temporaries of ``path``
    (a killed run's) are removed first, as :func:`atomic_write` does for files.
    """
    target = check_output_directory(path, marker=marker, generator=generator, overwrite=overwrite, names=names)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(target)
    tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.{HOST_TAG}.{os.getpid()}."))
    try:
        yield tmp
        written = _record_files(tmp, marker)
        os.chmod(tmp, NEW_DIR_MODE)
        # Again: the directory may have changed while the work ran.
        check_output_directory(target, marker=marker, generator=generator, overwrite=overwrite, names=written)
        if not target.exists():
            os.replace(tmp, target)
        elif not directory_entries(target, marker, generator)[1]:
            _swap(tmp, target, marker, generator)
        else:
            _merge(tmp, target, written, marker, generator)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _record_files(directory: Path, marker: str) -> list[str]:
    """Add the sorted names in ``directory`` to its JSON ``marker`` as ``"files"``; returns them."""
    names = sorted(os.listdir(directory))
    if marker not in names:
        raise RuntimeError(f"an output directory must hold its record {marker}")  # a bug of the command
    record = json.loads((directory / marker).read_text(encoding="utf-8"))
    atomic_write_text(directory / marker, json.dumps({**record, "files": names}, indent=2) + "\n")
    return names


def _swap(tmp: Path, target: Path, marker: str, generator: str) -> None:
    """Replace ``target``, which holds only recorded names, by ``tmp``; remove just those names."""
    old = target.parent / f".{target.name}.old.{HOST_TAG}.{os.getpid()}"
    os.replace(target, old)
    os.replace(tmp, target)
    recorded, _ = directory_entries(old, marker, generator)
    for name in recorded:  # those the directory holds
        remove_entry(old / name)
    try:
        old.rmdir()
    except OSError:  # something appeared in the old directory meanwhile: it is not ours to delete
        logging.getLogger(__name__).warning("kept %s: it holds files written there during the run", old)


def _merge(tmp: Path, target: Path, written: list[str], marker: str, generator: str) -> None:
    """Move ``tmp``'s files into ``target`` beside its foreign entries, the marker last."""
    before = recorded_names(target, marker, generator) or frozenset()
    for name in written:
        if name != marker:
            os.replace(tmp / name, target / name)
    for name in before - set(written):
        remove_entry(target / name)
    os.replace(tmp / marker, target / marker)
    tmp.rmdir()


def remove_entry(path: Path) -> None:
    """Remove a file, or a folder with everything in it (a link is removed, never followed)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
