"""Geometries to and from files: the JSON scan file of ``xrayraster reconstruct``, and the
``repr`` that every output TIFF carries in its metadata.

Scan file (JSON; lengths mm, angles degrees as in every config)::

    {
      "geometry": {"type": "cone", "source_to_origin": 100, "source_to_detector": 200,
                   "detector_shape": [256, 256], "pixel_size": 0.2, "views": 360},
      "volume":   {"shape": [256, 256, 256], "voxel_size": 0.1}
    }

``geometry.type``: ``cone`` (fields of :class:`~xrayraster.ConeBeamGeometry`), ``parallel``
(:class:`~xrayraster.ParallelBeamGeometry`) or ``vector`` (``beam``, ``detector_shape``,
``vectors``: one row of 12 numbers per view, :class:`~xrayraster.VectorGeometry`). Angles, for
cone and parallel: ``angles_deg`` (a list), or ``views`` (equally spaced over ``arc_deg``,
default 360, from ``start_deg``, default 0; the end point is excluded). ``detector_offset``
(row, col) mm is optional. ``volume``: ``shape`` (z, y, x), ``voxel_size`` (one number or z, y, x)
and optional ``offset`` (z, y, x) mm. A scan file may leave out ``geometry``: the projections'
TIFF then supplies it (``xrayraster render`` writes it there).
"""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np

from ..core.errors import GeometryError
from ..core.geometry import (
    ConeBeamGeometry,
    ParallelBeamGeometry,
    VectorGeometry,
    VolumeGeometry,
)

_CLASSES = {cls.__name__: cls for cls in (ConeBeamGeometry, ParallelBeamGeometry, VectorGeometry, VolumeGeometry)}


def geometry_from_repr(text: str):
    """The geometry written by ``repr`` (e.g. in a TIFF's metadata), parsed without ``eval``."""
    try:
        node = ast.parse(text.strip(), mode="eval").body
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _CLASSES
                and not node.args):
            raise ValueError
        kwargs = {k.arg: ast.literal_eval(k.value) for k in node.keywords}
    except (SyntaxError, ValueError):
        raise GeometryError(f"not a geometry: {text[:80]!r}...; expected e.g. ConeBeamGeometry(source_to_origin=..., ...)") from None
    return _CLASSES[node.func.id](**kwargs)


def read_scan_file(path) -> tuple[object | None, VolumeGeometry]:
    """(scan geometry or None, volume geometry) from a JSON scan file (module docstring)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise GeometryError(f"scan file {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GeometryError(f"scan file {str(path)!r} is not valid JSON: {exc}") from None
    if not isinstance(data, dict) or "volume" not in data:
        raise GeometryError(f"scan file {str(path)!r}: needs a 'volume' object (shape, voxel_size) and usually 'geometry'")
    unknown = set(data) - {"geometry", "volume"}
    if unknown:
        raise GeometryError(f"scan file {str(path)!r}: unknown key(s) {sorted(unknown)}; use 'geometry' and 'volume'")
    geometry = scan_geometry_from_dict(data["geometry"], f"{path.name}: geometry") if "geometry" in data else None
    return geometry, volume_from_dict(data["volume"], f"{path.name}: volume")


def scan_geometry_from_dict(d: dict, where: str = "geometry"):
    """A scan geometry from the scan file's ``geometry`` object."""
    d = _fields(d, where, required={"type"})
    kind = d.pop("type")
    if kind == "vector":
        _only(d, {"beam", "detector_shape", "vectors"}, where)
        return VectorGeometry(d.get("beam", "cone"), d.get("detector_shape"), d.get("vectors"))
    if kind not in ("cone", "parallel"):
        raise GeometryError(f"{where}.type must be 'cone', 'parallel' or 'vector', got {kind!r}")
    angles = _angles(d, where)
    common = {"detector_shape": d.pop("detector_shape", None), "pixel_size": d.pop("pixel_size", None),
              "angles": angles, "detector_offset": d.pop("detector_offset", (0.0, 0.0))}
    if kind == "cone":
        cone = {"source_to_origin": d.pop("source_to_origin", None), "source_to_detector": d.pop("source_to_detector", None)}
        _only(d, set(), where)
        return ConeBeamGeometry(**cone, **common)
    _only(d, set(), where)
    return ParallelBeamGeometry(**common)


def volume_from_dict(d: dict, where: str = "volume") -> VolumeGeometry:
    d = _fields(d, where, required={"shape", "voxel_size"})
    _only(d, {"shape", "voxel_size", "offset"}, where)
    return VolumeGeometry(d["shape"], d["voxel_size"], tuple(d.get("offset", (0.0, 0.0, 0.0))))


def _fields(d, where: str, required: set) -> dict:
    if not isinstance(d, dict):
        raise GeometryError(f"{where} must be a JSON object, got {type(d).__name__}")
    missing = required - set(d)
    if missing:
        raise GeometryError(f"{where}: missing {', '.join(sorted(missing))}")
    return dict(d)


def _only(d: dict, allowed: set, where: str) -> None:
    extra = set(d) - allowed
    if extra:
        raise GeometryError(f"{where}: unknown or misplaced key(s) {sorted(extra)}")


def _angles(d: dict, where: str) -> tuple[float, ...]:
    if "angles_deg" in d:
        if {"views", "arc_deg", "start_deg"} & set(d):
            raise GeometryError(f"{where}: give angles_deg, or views (with arc_deg, start_deg), not both")
        return tuple(math.radians(float(a)) for a in np.atleast_1d(d.pop("angles_deg")))
    if "views" not in d:
        raise GeometryError(f"{where}: give angles_deg (a list, degrees) or views (a count over arc_deg, default 360)")
    views = d.pop("views")
    if not isinstance(views, int) or isinstance(views, bool) or views < 1:
        raise GeometryError(f"{where}.views must be a positive integer, got {views!r}")
    arc, start = float(d.pop("arc_deg", 360.0)), float(d.pop("start_deg", 0.0))
    return tuple(math.radians(start + arc * k / views) for k in range(views))
