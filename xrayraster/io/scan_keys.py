"""The keys of a scan file as dotted paths (``source.kvp``, ``weave.sample.seed``, ``objects.0.translate``):
checked against the tables the loaders read, set in a scan table, and its relative file paths made absolute.

A dataset file's ``[vary]`` names scan-file keys this way (docs/dataset.md). A key is checked here,
against the key sets the scan file's parsers use, so a misspelt key is refused with the table's
allowed keys before any draw; whether a drawn value is of the right type and range is the scan
file loader's check, made on every draw. Tables of the scan file not described here (a new one)
take any key below them, left to that loader check.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from ..core.errors import ConfigError
from ..core.geometry import SCAN_KEYS
from ..core.volume import VolumeGeometry
from ..weave.distort import Distortion
from ..weave.voids import Voids
from ..weave.section import Section
from ..weave.spec import UnitCell
from .pose import POSE_KEYS
from .scan_file import SCAN_TABLES, ScanOptions
from .scene_file import (
    DETECTOR_KEYS,
    MATERIAL_KEYS,
    OBJECT_KEYS,
    PHYSICS_KEYS,
    PRIMITIVE_KEYS,
    SOURCE_KINDS,
    SOURCE_REALISM_KEYS,
)
from .weave_file import SAMPLE_TABLE_KEYS

__all__ = ["ANY", "INDEX", "KEYS", "PATH_KEYS", "absolute_paths", "check_key", "set_key", "value_at"]

ANY = "*"  # any name: a material, a filter's material, an element
INDEX = "#"  # an entry of an array of tables, by its index from 0


def _names(*groups) -> dict:
    """Leaf keys (values, no keys below them)."""
    return dict.fromkeys(set().union(*groups))


_MATERIAL = {**_names(MATERIAL_KEYS), "mass_fractions": {ANY: None}}
_SECTION = _names(f.name for f in dataclasses.fields(Section))
_BUNDLE = {"fibre": None, "fibre_fraction": None}
_OBJECT = {**_names(OBJECT_KEYS), "mesh": _names(*PRIMITIVE_KEYS.values())}
KEYS = {
    "geometry": _names({"vectors"}, *SCAN_KEYS.values()),
    "weave": {**_names(f.name for f in dataclasses.fields(UnitCell)), "weft_section": _SECTION,
              "warp_section": _SECTION, "sample": _names(SAMPLE_TABLE_KEYS),
              "distortion": _names(f.name for f in dataclasses.fields(Distortion)),
              "voids": _names(f.name for f in dataclasses.fields(Voids)),
              "materials": {"matrix": None, "weft": _BUNDLE, "warp": _BUNDLE, "tracers": None}},
    "materials": {ANY: _MATERIAL},
    "source": {**_names(SOURCE_REALISM_KEYS, *SOURCE_KINDS.values()), "filters": {ANY: None}},
    "detector": {**_names(DETECTOR_KEYS), "scintillator": _MATERIAL},
    "physics": _names(PHYSICS_KEYS),
    "volume": _names(f.name for f in dataclasses.fields(VolumeGeometry)),
    "scan": _names(f.name for f in dataclasses.fields(ScanOptions)),
    "pose": _names(POSE_KEYS),
    "objects": {INDEX: _OBJECT},
    "mount": {INDEX: {k: v for k, v in _OBJECT.items() if k not in ("label", "priority")}},
}
#: Keys whose values are file paths, relative to the file that gives them.
PATH_KEYS = (("objects", INDEX, "mesh"), ("mount", INDEX, "mesh"), ("source", "spectrum_file"))


def check_key(key: str, base: dict, where: str) -> None:
    """Refuse ``key`` (dotted) unless it names a scan-file key that can be set in ``base`` (the scan
    table): each part a key of its table, an array entry's index within the base's array (of
    tables, or of values as the last part: ``pose.tilt_deg.2``), and no part below a plain value
    of the base."""
    parts = key.split(".")
    tree, table = {**KEYS, **dict.fromkeys(SCAN_TABLES - set(KEYS), ANY)}, base
    for i, part in enumerate(parts):
        above = ".".join(parts[:i]) or "the scan file"
        if tree is None and isinstance(table, list) and i == len(parts) - 1:
            if not part.isdigit() or int(part) >= len(table):
                raise ConfigError(f"{where}: '{key}': the base scan's {above} has {len(table)} entries; name one by "
                                  f"its index, 0 to {len(table) - 1} (got {part!r})")
            return  # an entry of an array the base gives (pose.tilt_deg.2): its loader checks the value
        if tree is None:
            hint = (f"; to vary one entry of an array, give the array in the base scan ({above} = [...]) and "
                    f"name the entry by its index ({above}.0)") if part.isdigit() else ""
            raise ConfigError(f"{where}: '{key}': {above} is a value, not a table; vary {above} whole "
                              f"(e.g. with choice = [...]){hint}")
        if tree is ANY:
            pass  # a table this module does not describe: its loader checks the key
        elif INDEX in tree:
            count = len(table) if isinstance(table, list) else 0
            if not part.isdigit() or int(part) >= count:
                raise ConfigError(f"{where}: '{key}': {above} is an array of tables; name an entry by its index, "
                                  f"0 to {count - 1} in the base scan (got {part!r})")
            tree, table = tree[INDEX], table[int(part)]
            continue
        elif part in tree or ANY in tree:
            tree = tree.get(part, tree.get(ANY))
        else:
            allowed = ", ".join(sorted(tree))
            raise ConfigError(f"{where}: '{key}': no key {part!r} in {above} (docs/scan.md); allowed: {allowed}")
        if isinstance(table, dict) and part in table:
            table = table[part]
            if i < len(parts) - 1 and not isinstance(table, (dict, list)):
                raise ConfigError(f"{where}: '{key}': the base scan's {'.'.join(parts[:i + 1])} is {table!r}, "
                                  "not a table; vary it whole (e.g. with choice = [...])")
        else:
            table = {}


def set_key(table: dict, key: str, value) -> None:
    """Set the dotted ``key`` (checked by :func:`check_key`) in ``table``, making missing tables."""
    *parents, last = key.split(".")
    for part in parents:
        table = table[int(part)] if isinstance(table, list) else table.setdefault(part, {})
    table[int(last) if isinstance(table, list) else last] = value


def value_at(table: dict, key: str):
    """The value of the dotted ``key`` in ``table`` (array entries by index), None where it gives none."""
    for part in key.split("."):
        if isinstance(table, list) and part.isdigit() and int(part) < len(table):
            table = table[int(part)]
        elif isinstance(table, dict) and part in table:
            table = table[part]
        else:
            return None
    return table


def absolute_paths(table: dict, directory: Path) -> dict:
    """``table`` with its relative file paths (:data:`PATH_KEYS`: mesh files, spectrum files) made
    absolute against ``directory``, so it loads from anywhere; changed in place and returned."""
    for path in PATH_KEYS:
        for holder, key in _holders(table, path):
            value = holder.get(key)
            if isinstance(value, str) and value and not Path(value).is_absolute():
                holder[key] = str((Path(directory) / value).resolve())
    return table


def _holders(table, path: tuple):
    """The (dict, key) pairs ``path`` reaches in ``table``, ``INDEX`` standing for every array entry."""
    first, *rest = path
    if not rest:
        if isinstance(table, dict):
            yield table, first
        return
    if first == INDEX:
        for item in table if isinstance(table, list) else ():
            yield from _holders(item, tuple(rest))
    elif isinstance(table, dict) and first in table:
        yield from _holders(table[first], tuple(rest))
