"""What an output may replace: only what xrayraster wrote itself, never a user's file.

**Files.** A command's or ``save``'s output file may replace an existing file only if that file
was written by xrayraster, as its own format says:

- TIFF (``.tif``, ``.tiff``): the Software tag starts with ``xrayraster`` (:data:`SOFTWARE`), or,
  for stacks written before the tag was set, the ImageJ ``Info`` metadata is a JSON object;
- PNG: the ``Software`` text chunk starts with ``xrayraster`` (or, written before, the quick-look's
  ``upscale`` chunk is there);
- JSON: a top-level object whose ``generator`` starts with ``xrayraster``;
- TOML: a first line that starts with :data:`TOML_HEADER` (the scan files ``xrayraster fit`` writes).

Any other existing file, a directory, or a file that cannot be read is someone else's.

**Directories.** A command that writes a directory (``scan``, ``weave``) records the names it
wrote in its marker file (``scan.json``, ``report.json``: a JSON object with ``generator`` and
``files``). An entry of the directory that the marker does not list is *foreign*
(:func:`directory_entries`); :func:`~xrayraster.core.files.atomic_directory` replaces a
directory only when nothing in it is foreign, and with ``overwrite`` replaces the recorded names
while every foreign entry stays as it was.

**Links.** An output path that is a symbolic link is resolved (:func:`resolved_output`): the
output goes where the link points, and the link stays. A link that points nowhere is refused.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .errors import ConfigError

#: The Software tag / text chunk of every TIFF and PNG xrayraster writes.
SOFTWARE = "xrayraster"
#: The first line of every TOML file xrayraster writes starts with it.
TOML_HEADER = "# Written by xrayraster"

#: Suffixes that name a file, refused as the name of an output directory (``-o out.tif`` of a
#: command that writes a directory is a mistake, not a directory the user wants).
FILE_SUFFIXES = frozenset({".tif", ".tiff", ".png", ".jpg", ".jpeg", ".json", ".toml", ".csv", ".txt", ".stl",
                           ".ply", ".obj", ".h5", ".hdf5", ".nii", ".gz", ".npy", ".npz", ".zip", ".raw"})


def resolved_output(path) -> Path:
    """``path`` with symbolic links resolved (a link's target receives the output; the link stays).

    A dangling link is refused: writing through it would create a file the user never named.
    """
    path = Path(path)
    if path.is_symlink() and not path.exists():
        raise ConfigError(f"{path} is a symbolic link to {os.readlink(path)}, which does not exist; "
                          "give the real output path or create the target first")
    return Path(os.path.realpath(path))


def is_own_file(path) -> bool:
    """Whether the existing file ``path`` was written by xrayraster (module docstring)."""
    path = Path(path)
    if not path.is_file():
        return False
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            return _own_tiff(path)
        if suffix == ".png":
            return _own_png(path)
        if suffix == ".json":
            return str(_json_object(path).get("generator", "")).startswith(SOFTWARE)
        if suffix == ".toml":
            with open(path, encoding="utf-8") as f:
                return f.readline().startswith(TOML_HEADER)
    except Exception:  # unreadable or not of its suffix's format: not ours, whatever went wrong
        return False
    return False


def _own_tiff(path: Path) -> bool:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        software = page.tags.get("Software")
        if software is not None and str(software.value).startswith(SOFTWARE):
            return True
        info = (tif.imagej_metadata or {}).get("Info")
    return isinstance(json.loads(info), dict) if info else False


def _own_png(path: Path) -> bool:
    from PIL import Image

    with Image.open(path) as image:
        if image.format != "PNG":
            return False
        text = getattr(image, "text", {}) or {}
    return str(text.get("Software", "")).startswith(SOFTWARE) or "upscale" in text


def _json_object(path: Path) -> dict:
    data = json.loads(path.read_text(encoding="utf-8"))
    return data if isinstance(data, dict) else {}


def read_record(path, generator: str) -> dict | None:
    """The JSON object at ``path`` if ``generator`` wrote it (its ``"generator"`` says so), else None:
    missing, unreadable, not a JSON object, or someone else's."""
    try:
        record = _json_object(Path(path))
    except (OSError, ValueError):
        return None
    return record if record.get("generator") == generator else None


def check_replaceable_files(paths) -> list[Path]:
    """Refuse, before any work, to write an output file over one xrayraster did not write.

    ``paths``: every file an operation is about to write. Returns them with links resolved
    (:func:`resolved_output`), the paths to write to. :class:`~xrayraster.core.errors.ConfigError`
    names the first path that is a directory or someone else's file.
    """
    resolved = []
    for path in paths:
        target = resolved_output(path)
        where = f"{path}" if target == Path(path).absolute() else f"{path} (a link to {target})"
        if target.is_dir():
            raise ConfigError(f"cannot write {where}: it is a directory; give a file name")
        if target.exists() and not is_own_file(target):
            raise ConfigError(f"{where} exists and was not written by xrayraster; it is never replaced: "
                              "move it away or choose another output name")
        resolved.append(target)
    return resolved


def recorded_names(directory, marker: str, generator: str) -> frozenset[str] | None:
    """The names an earlier output of ``generator`` recorded in ``directory/marker`` (the marker
    included), or None when the directory holds no such record."""
    record = read_record(Path(directory) / marker, generator)
    files = record.get("files") if record is not None else None
    if not isinstance(files, list):
        return None
    names = {name for name in files if isinstance(name, str) and name == Path(name).name and name not in ("", ".", "..")}
    return frozenset(names | {marker})


def directory_entries(directory, marker: str, generator: str) -> tuple[frozenset[str], list[str]]:
    """(the names ``directory`` holds that an earlier output recorded, the foreign entries sorted)."""
    entries = set(os.listdir(directory))
    recorded = recorded_names(directory, marker, generator) or frozenset()
    return frozenset(entries & recorded), sorted(entries - recorded)
