"""Grid files (JSON): the voxel grid of ``xrayraster reconstruct`` and ``xrayraster voxelize``,
and optionally the scan geometry, each in the dict form of :mod:`xrayraster.core.geometry`
(lengths mm, angles degrees)::

    {
      "geometry": {"beam": "cone", "source_to_origin": 100, "source_to_detector": 200,
                   "detector_shape": [256, 256], "pixel_size": 0.2, "num_views": 360},
      "volume":   {"shape": [256, 256, 256], "voxel_size": 0.1}
    }

A grid file may leave out ``geometry``: the projections' TIFF then supplies it (``xrayraster
render`` writes it there). ``xrayraster weave`` writes one as ``grid.json``.

Grid files were called "scan files" (``--scan-file``, a weave's ``scan.json``) until the name
went to the TOML input of ``xrayraster scan``; the content is unchanged, so an old one reads as
it is. Grid files written before the dict form was shared with TOML scene files spell three
keys differently; they are still read: ``type`` (``cone``, ``parallel`` or ``vector``) for
``beam`` (a vector geometry is one with ``vectors``), ``views`` for ``num_views`` and
``start_deg`` for ``start_angle_deg``.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..core.errors import ConfigError
from ..core.files import atomic_write_text
from ..core.geometry import geometry_from_dict
from ..core.inputs import read_text_file
from ..core.volume import VolumeGeometry

__all__ = ["GRID_KEYS", "read_grid_file", "write_grid_file"]

#: The keys of a grid file's object.
GRID_KEYS = {"geometry", "volume"}
_OLDER_SPELLINGS = {"views": "num_views", "start_deg": "start_angle_deg"}


def read_grid_file(path) -> tuple[object | None, VolumeGeometry]:
    """(scan geometry or None, volume geometry) from a grid file (module docstring)."""
    path = Path(path)
    text = read_text_file(path, "grid file")  # UTF-8, a byte-order mark allowed
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"grid file {str(path)!r} is not valid JSON: {exc}") from None
    if not isinstance(data, dict) or "volume" not in data:
        raise ConfigError(f"grid file {str(path)!r}: needs a 'volume' object (shape, voxel_size) and usually 'geometry'")
    unknown = set(data) - GRID_KEYS
    if unknown:
        raise ConfigError(f"grid file {str(path)!r}: unknown key(s) {sorted(unknown)}; use 'geometry' and 'volume'")
    where = f"{path.name}: geometry"
    geometry = geometry_from_dict(_current_spelling(data["geometry"], where), where) if "geometry" in data else None
    return geometry, VolumeGeometry.from_dict(data["volume"], f"{path.name}: volume")


def write_grid_file(path, volume: VolumeGeometry) -> Path:
    """A grid file holding only the voxel grid; written atomically."""
    text = json.dumps({"volume": volume.to_dict()}, indent=2) + "\n"
    return atomic_write_text(Path(path), text)


def _current_spelling(d, where: str):
    """A geometry object with the older key spellings (module docstring) renamed."""
    if not isinstance(d, dict):
        return d
    d = dict(d)
    for old, new in _OLDER_SPELLINGS.items():
        if old in d:
            if new in d:
                raise ConfigError(f"{where}: give '{new}' only ('{old}' is its older spelling)")
            d[new] = d.pop(old)
    kind = d.pop("type", None)
    if kind is not None:
        if kind not in ("cone", "parallel", "vector"):
            raise ConfigError(f"{where}.type must be 'cone', 'parallel' or 'vector', got {kind!r}")
        if kind != "vector":
            d.setdefault("beam", kind)
    return d
