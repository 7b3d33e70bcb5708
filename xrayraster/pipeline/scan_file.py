"""Scan files (TOML): a scene file whose sample may be a woven one, plus the grid and the options.

The tables are the scene file's (docs/scene-format.md), read by its parsers, with the sample
either as ``[[objects]]`` or as a ``[weave]`` table (docs/weave.md, read by the weave file's
parser; ``[materials.NAME]`` serve both), and two more: ``[volume]``, the reconstruction grid in
the dict form of :class:`~xrayraster.core.volume.VolumeGeometry`, and ``[scan]``, the options
(:class:`ScanOptions`). ``[source]`` is required (a scan makes radiographs). A weave sample's
``[geometry]`` defaults to the framing scan ``xrayraster weave`` writes, and the sample is placed
as there: its box centred on the rotation axis, its thickness along z. The default ``[volume]`` is
the grid over the sample's box (the objects' bounds) at the scan's magnified pixel pitch. Every
check runs on loading, before any meshing or rendering, and names the file, the table and the key.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core import fields
from ..core.choices import FILTERS
from ..core.errors import ConfigError
from ..core.geometry import ConeBeamGeometry, ParallelBeamGeometry
from ..core.transform import Transform
from ..core.volume import VolumeGeometry
from ..io.scene_file import _add_object, _detector, _geometry, _materials, _source, read_toml
from ..io.weave_file import WeaveFile, framing_geometry, sample_grid, weave_from_dict
from ..physics.detector import Detector
from ..physics.spectrum import Spectrum
from ..scene.materials import Material
from ..scene.scene import Scene

__all__ = ["ScanFile", "ScanOptions", "load_scan_file"]

_TABLES = {"geometry", "objects", "weave", "materials", "source", "detector", "volume", "scan"}


@dataclass(frozen=True)
class ScanOptions:
    """The ``[scan]`` table: ``seed`` (noise seed, an integer >= 0), ``noise`` (photon noise on),
    ``filter`` (the FDK ramp-filter window, one of :data:`~xrayraster.core.choices.FILTERS`)."""

    seed: int = 0
    noise: bool = True
    filter: str = "ram-lak"

    @classmethod
    def from_dict(cls, d: dict, where: str) -> "ScanOptions":
        fields.only(d, {f.name for f in dataclasses.fields(cls)}, where)
        options = {}
        if "seed" in d:
            options["seed"] = fields.integer(d["seed"], "seed", where, 0)
        if "noise" in d:
            if not isinstance(d["noise"], bool):
                raise ConfigError(f"{where}: noise must be true or false, got {d['noise']!r}")
            options["noise"] = d["noise"]
        if "filter" in d:
            options["filter"] = fields.string(d["filter"], "filter", where)
            if options["filter"] not in FILTERS:
                raise ConfigError(f"{where}: filter must be one of {', '.join(FILTERS)}, got {d['filter']!r}")
        return cls(**options)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class ScanFile:
    """A loaded scan file. The sample is ``scene`` (from ``[[objects]]``) or ``weave`` (from
    ``[weave]``, meshed by :meth:`sample_scene`); the other is None. ``box_mm``: the sample's
    ``(2, 3)`` min/max corners in the scanner frame (a weave's as placed there)."""

    path: Path
    scene: Scene | None
    weave: WeaveFile | None
    box_mm: np.ndarray
    geometry: ConeBeamGeometry | ParallelBeamGeometry
    volume: VolumeGeometry
    spectrum: Spectrum
    detector: Detector | None
    options: ScanOptions

    def sample_scene(self, progress: bool = False) -> Scene:
        """The scene to scan: the objects, or the weave meshed and moved so its box is centred on the axis."""
        if self.weave is None:
            return self.scene
        lo, hi = self.weave.sample.box
        shift = Transform.translation(-(lo + hi) / 2)
        placed = Scene()
        for o in self.weave.sample.scene(self.weave.materials).objects:
            placed.add(o.mesh, o.material, label=o.label, priority=o.priority, name=o.name, transform=shift)
        return placed

    @property
    def weave_report(self) -> dict | None:
        """The weave's settings as ``xrayraster weave``'s report.json gives them (None for objects)."""
        if self.weave is None:
            return None
        s = self.weave.sample
        materials = self.weave.materials.resolve()
        return {"cell": s.cell.to_dict(), "cells": list(s.cells), "layers_of_cells": s.layers_of_cells,
                "points_per_section": s.points_per_section, "samples_per_mm": s.samples_per_mm, "seed": s.seed,
                "distortion": s.distortion.to_dict(), "box_mm": self.box_mm.tolist(),
                "materials": {family: repr(m) for family, m in materials.items()},
                "tracers": [t.yarn for t in self.weave.materials.tracers]}


def load_scan_file(path) -> ScanFile:
    """Read and check a scan file (module docstring); errors are ConfigErrors naming the file, table and key."""
    path = Path(path)
    data = read_toml(path, "scan file")
    fields.only(data, _TABLES, f"{path}")
    has_objects, has_weave = "objects" in data, "weave" in data
    if has_objects == has_weave:
        raise ConfigError(f"{path}: give the sample as [[objects]] (meshes) or as a [weave] table, "
                          f"{'not both' if has_objects else 'got neither'}")
    if "source" not in data:
        raise ConfigError(f"{path}: missing [source] table (the X-ray tube, e.g. kvp = 40); a scan makes radiographs")
    options = ScanOptions.from_dict(fields.table(data.get("scan", {}), "scan", f"{path}"), f"{path} [scan]")
    volume = VolumeGeometry.from_dict(data["volume"], f"{path} [volume]") if "volume" in data else None
    materials = _materials(data["materials"], f"{path} [materials]") if "materials" in data else None
    geometry = None
    if "geometry" in data:
        geometry = _geometry(fields.table(data["geometry"], "geometry", f"{path}"), f"{path} [geometry]")
    scene = weave = None
    if has_weave:
        weave = WeaveFile(path, *weave_from_dict(data["weave"], materials or {}, f"{path} [weave]"))
        lo, hi = weave.sample.box
        box = np.stack([lo, hi]) - (lo + hi) / 2
        geometry = geometry or framing_geometry(box)
    else:
        if geometry is None:
            raise ConfigError(f"{path}: missing [geometry] table (needed with [[objects]]; a [weave] sample frames itself)")
        scene, materials = _objects(data["objects"], path, materials)
        box = scene.bounds
    spectrum = _source(fields.table(data["source"], "source", f"{path}"), path.parent, f"{path} [source]")
    detector = None
    if "detector" in data:
        detector = _detector(fields.table(data["detector"], "detector", f"{path}"), materials, f"{path} [detector]")
    if volume is None:
        centre = (box[0] + box[1]) / 2
        volume = dataclasses.replace(sample_grid(box, geometry), offset=tuple(centre[::-1].tolist()))
    return ScanFile(path, scene, weave, np.asarray(box, dtype=np.float64), geometry, volume, spectrum, detector,
                    options)


def _objects(objects, path: Path, materials: dict | None) -> tuple[Scene, dict]:
    """The ``[[objects]]`` as load_scene_file reads them; every material must resolve (a scan makes radiographs)."""
    if not isinstance(objects, list) or not objects:
        raise ConfigError(f"{path}: objects must be a non-empty array of tables ([[objects]]), got {objects!r}")
    scene = Scene()
    library: dict[str, Material] = {}
    for k, spec in enumerate(objects):
        where = f"{path} [[objects]] #{k + 1}"
        _add_object(scene, fields.table(spec, "objects", where), path.parent, where, materials or {}, library)
    return scene, {**library, **(materials or {})}
