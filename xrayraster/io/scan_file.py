"""Scan files (TOML): a scene file whose sample may be a woven one, plus the grid and the options.

The tables are the scene file's (docs/scene-format.md), read by its parsers, with the sample
either as ``[[objects]]`` or as a ``[weave]`` table (docs/weave.md, read by the weave file's
parser; ``[materials.NAME]`` serve both), and two more: ``[volume]``, the reconstruction grid in
the dict form of :class:`~xrayraster.core.volume.VolumeGeometry`, and ``[scan]``, the options
(:class:`ScanOptions`). ``[source]`` is required (a scan makes radiographs). ``[[mount]]`` tables
(the keys of ``[[objects]]`` but ``label`` and ``priority``) add objects that are scanned but never
labelled, such as a sample holder: they are in the projections, not in the labels, and the sample owns
any space it shares with them. The scanner's imperfections (docs/realism.md) are keys of ``[source]``
and ``[detector]``, as in scene files. A weave sample's
``[geometry]`` defaults to the framing scan ``xrayraster weave`` writes, and the sample is placed
as there: its box centred on the rotation axis, its thickness along z. The default ``[volume]`` is
the grid over the sample's box (the objects' bounds) at the scan's magnified pixel pitch. Every
check runs on loading, before any meshing or rendering, and names the file, the table and the key.
``[pose]`` (:class:`~.pose.Pose`) turns and moves the sample, not the mount, before the box, the
default ``[geometry]`` of a weave and the default ``[volume]`` are taken from it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core import fields
from ..core.choices import FILTERS, LABEL_CLASSES, LABEL_EXTRAS, is_switch
from ..core.errors import ConfigError
from ..core.estimate import plan
from ..core.geometry import ConeBeamGeometry, ParallelBeamGeometry
from ..core.transform import Transform
from ..core.volume import VolumeGeometry
from ..physics.detector import Detector
from ..physics.realism import Realism
from ..physics.spectrum import Spectrum
from ..recon.truncation import DEFAULT_WIDTH
from ..scene.materials import Material
from ..scene.scene import Scene
from ..weave.size import BendSearch
from ..weave.tessellation import resolution_for
from .pose import Pose
from .scene_file import (
    OBJECT_KEYS,
    add_object,
    parse_detector,
    parse_geometry,
    parse_materials,
    parse_realism,
    parse_source,
    read_toml,
)
from .weave_file import WeaveFile, framing_geometry, sample_grid, weave_from_dict

__all__ = ["SCAN_TABLES", "ScanFile", "ScanOptions", "load_scan_file", "mesh_resolution_for"]

#: The tables a scan file may hold (a dataset file holds them too, inline: dataset/dataset_file.py).
SCAN_TABLES = {"geometry", "objects", "weave", "mount", "materials", "source", "detector", "physics", "volume", "scan",
               "pose"}


@dataclass(frozen=True)
class ScanOptions:
    """The ``[scan]`` table: ``seed`` (noise seed, an integer >= 0), ``noise`` (photon noise on),
    ``filter`` (the FDK ramp-filter window, one of :data:`~xrayraster.core.choices.FILTERS`),
    ``mesh_tolerance_voxels`` (a weave's largest predicted path-length error per yarn boundary, in
    voxels of the grid, where ``[weave.sample]`` leaves the mesh resolution open; 0.05 = 1/20),
    ``truncation`` (``"auto"``, true or false: extrapolate rows cut off by the detector's edges, a
    sample wider than the field of view) and ``truncation_width`` (the extrapolation's width on
    each side, a share of the detector width, where the object's reach is unknown: a scan knows its
    sample's, so this applies to ``xrayraster reconstruct`` without ``--object-radius``), as
    :func:`xrayraster.fdk` takes them; ``labels``, the label volumes of a woven sample: first its
    classes, ``"classes"`` (matrix 1, weft 2, warp 3) or ``"binder"`` (the binders a class of their
    own, 4; the stuffers stay warp), then, optionally, ``"instances"`` (one id per yarn,
    beside them), ``"directions"`` (each yarn voxel's yarn direction) and ``"centrelines"`` (the
    yarns' centre lines as polylines) (docs/labels.md)."""

    seed: int = 0
    noise: bool = True
    filter: str = "ram-lak"
    mesh_tolerance_voxels: float = 0.05
    truncation: str | bool = "auto"
    truncation_width: float = DEFAULT_WIDTH
    labels: tuple[str, ...] = ("classes",)

    @classmethod
    def from_dict(cls, d: dict, where: str) -> "ScanOptions":
        fields.only(d, {f.name for f in dataclasses.fields(cls)}, where)
        options = {}
        if "seed" in d:
            options["seed"] = fields.integer(d["seed"], "seed", where, 0)
        if "mesh_tolerance_voxels" in d:
            options["mesh_tolerance_voxels"] = fields.number(d["mesh_tolerance_voxels"], "mesh_tolerance_voxels",
                                                             where, positive=True)
        if "noise" in d:
            options["noise"] = fields.boolean(d["noise"], "noise", where)
        if "truncation" in d:
            if not is_switch(d["truncation"]):
                raise ConfigError(f"{where}: truncation must be \"auto\", true or false, got {d['truncation']!r}")
            options["truncation"] = d["truncation"]
        if "truncation_width" in d:
            options["truncation_width"] = fields.number(d["truncation_width"], "truncation_width", where, positive=True)
            if options["truncation_width"] > 4:
                raise ConfigError(f"{where}: truncation_width must be at most 4 (a share of the detector width), "
                                  f"got {d['truncation_width']!r}")
        if "filter" in d:
            options["filter"] = fields.choice(d["filter"], "filter", where, FILTERS)
        if "labels" in d:
            labels = d["labels"]
            if not isinstance(labels, list) or not labels:
                raise ConfigError(f"{where}: labels must be a list of label volumes, the classes first "
                                  f"(\"classes\" or \"binder\"), then any of {', '.join(LABEL_EXTRAS)}, got {labels!r}")
            chosen = [fields.choice(labels[0], "labels[0]", where, LABEL_CLASSES)]
            chosen += [fields.choice(x, f"labels[{i}]", where, LABEL_EXTRAS) for i, x in enumerate(labels[1:], 1)]
            if len(set(chosen)) != len(chosen):
                raise ConfigError(f"{where}: labels names a label volume twice: {labels!r}")
            options["labels"] = tuple(chosen)
        return cls(**options)

    def to_dict(self) -> dict:
        return {**dataclasses.asdict(self), "labels": list(self.labels)}


@dataclass(frozen=True)
class ScanFile:
    """A loaded scan file. The sample is ``scene`` (from ``[[objects]]``) or ``weave`` (from
    ``[weave]``, meshed by :meth:`sample_scene`); the other is None. ``box_mm``: the sample's
    ``(2, 3)`` min/max corners in the scanner frame (a weave's as placed there), posed. ``realism``: the
    scanner's imperfections; ``mount``: the ``[[mount]]`` objects (None without), which
    :meth:`with_mount` adds to the sample for the projections; ``pose``: the ``[pose]`` (the objects
    of ``scene`` are posed already, a weave is posed by :meth:`sample_scene`)."""

    path: Path | str  # the file, or the ``where`` name of a table loaded from a dict
    scene: Scene | None
    weave: WeaveFile | None
    box_mm: np.ndarray
    geometry: ConeBeamGeometry | ParallelBeamGeometry
    volume: VolumeGeometry
    spectrum: Spectrum
    detector: Detector | None
    options: ScanOptions
    mesh_resolution: dict | None = None  # a weave's knobs, and whether the grid chose them (mesh_resolution_for)
    realism: Realism = Realism()
    mount: Scene | None = None
    pose: Pose = Pose()

    def sample_scene(self, progress: bool = False) -> Scene:
        """The scene to scan: the objects, or the weave meshed and moved so its box is centred on the
        axis; posed either way."""
        if self.weave is None:
            return self.scene
        return self.weave.sample.scene(self.weave.materials, transform=self.weave_placement(), progress=progress,
                                       binder_label="binder" in self.options.labels)

    def weave_placement(self) -> Transform:
        """Where the weave's frame lands in the scanner's: its box centred on the axis, posed."""
        lo, hi = self.weave.sample.box
        return self.pose.transform @ Transform.translation(-(lo + hi) / 2)

    def with_mount(self, sample: Scene) -> Scene:
        """What the projections see: ``sample`` (from :meth:`sample_scene`, which the labels are made
        from) and then the mount, below every sample object (priority: the sample's lowest minus 1),
        so the sample owns any space they share and the labels stay the sample's. ``sample`` itself
        when the file has no mount."""
        if self.mount is None:
            return sample
        scene = Scene()
        for o in sample.objects:
            scene.add(o.mesh, o.material, label=o.label, priority=o.priority, name=o.name)
        below = min(o.priority for o in sample.objects) - 1
        for o in self.mount.objects:
            scene.add(o.mesh, o.material, priority=below, name=o.name)
        return scene

    @property
    def weave_report(self) -> dict | None:
        """The weave's settings as ``xrayraster weave``'s report.json gives them (None for objects)."""
        if self.weave is None:
            return None
        s = self.weave.sample
        materials = self.weave.materials.resolve()
        return {"cell": s.cell.to_dict(), "cells": list(s.cells), "layers_of_cells": s.layers_of_cells,
                "points_per_section": s.points_per_section, "samples_per_mm": s.samples_per_mm, "seed": s.seed,
                "distortion": s.distortion.to_dict(), **({} if s.voids.is_zero else {"voids": s.voids.to_dict()}),
                "box_mm": self.box_mm.tolist(),
                "materials": {family: repr(m) for family, m in materials.items()},
                "tracers": [t.yarn for t in self.weave.materials.tracers]}


def load_scan_file(source, *, where: str = "scan table", base_dir=None) -> ScanFile:
    """Read and check a scan file (module docstring), or the dict of one already parsed (TOML's tables
    as dicts, e.g. a dataset's drawn table): then ``where`` names it in messages and as the result's
    ``path``, and relative file paths (meshes, spectrum files) are relative to ``base_dir`` (default:
    the current directory). Errors are ConfigErrors naming the file (or ``where``), table and key."""
    if isinstance(source, Mapping):
        path, data, base = where, source, Path(base_dir if base_dir is not None else ".")
    else:
        path = Path(source)
        data, base = read_toml(path, "scan file"), path.parent
    fields.only(data, SCAN_TABLES, f"{path}")
    has_objects, has_weave = "objects" in data, "weave" in data
    if has_objects == has_weave:
        raise ConfigError(f"{path}: give the sample as [[objects]] (meshes) or as a [weave] table, "
                          f"{'not both' if has_objects else 'got neither'}")
    if "source" not in data:
        raise ConfigError(f"{path}: missing [source] table (the X-ray tube, e.g. kvp = 40); a scan makes radiographs")
    options = ScanOptions.from_dict(fields.table(data.get("scan", {}), "scan", f"{path}"), f"{path} [scan]")
    if options.labels != ("classes",) and not has_weave:
        raise ConfigError(f"{path} [scan]: labels = {list(options.labels)} labels a woven sample's yarns; this file's "
                          "sample is [[objects]], whose labels are their own: remove labels or give a [weave]")
    volume = VolumeGeometry.from_dict(data["volume"], f"{path} [volume]") if "volume" in data else None
    materials = parse_materials(data["materials"], f"{path} [materials]") if "materials" in data else None
    pose = Pose.from_dict(fields.table(data["pose"], "pose", f"{path}"), f"{path} [pose]") if "pose" in data else Pose()
    geometry = None
    if "geometry" in data:
        geometry = parse_geometry(fields.table(data["geometry"], "geometry", f"{path}"), f"{path} [geometry]")
    scene = weave = None
    if has_weave:
        weave = WeaveFile(path, *weave_from_dict(data["weave"], materials or {}, f"{path} [weave]",
                                                 grid_chooses_knobs=True))
        lo, hi = weave.sample.box
        box = np.stack([lo, hi]) - (lo + hi) / 2
        pose = pose.about(np.zeros(3))
        box = pose.box(box)
        # The framing sees a box centred on the axis: the smallest such box around the posed one.
        geometry = geometry or framing_geometry(np.abs(box).max(axis=0) * [[-1], [1]])
    else:
        if geometry is None:
            raise ConfigError(f"{path}: missing [geometry] table (needed with [[objects]]; a [weave] sample frames itself)")
        scene, materials = _objects(data["objects"], path, base, materials)
        pose = pose.about(scene.bounds.mean(axis=0))
        scene = pose.place(scene)
        box = scene.bounds
    mount = None
    if "mount" in data:
        mount, materials = _mount(data["mount"], path, base, materials, scene)
    spectrum = parse_source(fields.table(data["source"], "source", f"{path}"), base, f"{path} [source]")
    detector = None
    if "detector" in data:
        detector = parse_detector(fields.table(data["detector"], "detector", f"{path}"), materials, f"{path} [detector]")
    if volume is None:
        centre = (box[0] + box[1]) / 2
        volume = dataclasses.replace(sample_grid(box, geometry), offset=tuple(centre[::-1].tolist()))
    resolution = None
    if weave is not None:
        given = {k: k in fields.table(data["weave"].get("sample", {}), "weave.sample", f"{path} [weave]")
                 for k in ("points_per_section", "samples_per_mm")}
        weave, resolution = mesh_resolution_for(weave, volume, options.mesh_tolerance_voxels, given)
    return ScanFile(path, scene, weave, np.asarray(box, dtype=np.float64), geometry, volume, spectrum, detector,
                    options, resolution, parse_realism(data, geometry, path), mount, pose)


def mesh_resolution_for(weave: WeaveFile, volume: VolumeGeometry, tolerance_voxels: float,
                        given: dict[str, bool]) -> tuple[WeaveFile, dict]:
    """The weave meshed no finer than the grid needs: the knobs ``given`` as False are replaced by
    :func:`~xrayraster.weave.tessellation.resolution_for` at ``tolerance_voxels`` of the smallest voxel
    side (a 128³ scan does not pay for the triangles a 512³ one needs). Returns the weave and a record
    of the choice (knobs, tolerance in mm, which were chosen) for the scan's metadata."""
    sample = weave.sample
    tolerance = tolerance_voxels * float(min(volume.voxel_size))
    knobs = {"points_per_section": sample.points_per_section, "samples_per_mm": sample.samples_per_mm}
    if not all(given.values()):  # the search for the tightest bend grows with the binders' columns: planned first
        plan(BendSearch(sample), ConfigError, f"{weave.path} ")
        k, rate = resolution_for(sample.cell, tolerance)
        knobs = {"points_per_section": knobs["points_per_section"] if given["points_per_section"] else k,
                 "samples_per_mm": knobs["samples_per_mm"] if given["samples_per_mm"] else rate}
    record = {**knobs, "tolerance_mm": tolerance, "tolerance_voxels": tolerance_voxels,
              "chosen_from_the_grid": sorted(name for name, fixed in given.items() if not fixed)}
    return dataclasses.replace(weave, sample=dataclasses.replace(sample, **knobs)), record


def _objects(objects, path: Path | str, base: Path, materials: dict | None) -> tuple[Scene, dict]:
    """The ``[[objects]]`` as load_scene_file reads them; every material must resolve (a scan makes radiographs)."""
    if not isinstance(objects, list) or not objects:
        raise ConfigError(f"{path}: objects must be a non-empty array of tables ([[objects]]), got {objects!r}")
    scene = Scene()
    library: dict[str, Material] = {}
    for k, spec in enumerate(objects):
        where = f"{path} [[objects]] #{k + 1}"
        add_object(scene, fields.table(spec, "objects", where), base, where, materials or {}, library)
    return scene, {**library, **(materials or {})}


def _mount(mounts, path: Path | str, base: Path, materials: dict | None, sample: Scene | None) -> tuple[Scene, dict]:
    """The ``[[mount]]`` tables: objects as in ``[[objects]]``, without a label or a priority (a
    mount is never labelled, and the sample owns any space it shares with one). Named ``mountK``
    unless named; a name an ``[[objects]]`` entry has is an error."""
    if not isinstance(mounts, list) or not mounts:
        raise ConfigError(f"{path}: mount must be a non-empty array of tables ([[mount]]), got {mounts!r}")
    scene = Scene()
    library: dict[str, Material] = {}
    taken = {o.name for o in sample.objects} if sample is not None else set()
    for k, spec in enumerate(mounts):
        where = f"{path} [[mount]] #{k + 1}"
        spec = fields.table(spec, "mount", where)
        for key, why in (("label", "a mount is never labelled (it is background, 0, in the labels)"),
                         ("priority", "the sample owns any space it shares with a mount")):
            if key in spec:
                raise ConfigError(f"{where}: {key} does not apply to a mount: {why}; remove it")
        fields.only(spec, OBJECT_KEYS - {"label", "priority"}, where)
        spec = {"name": f"mount{k + 1}", **spec}
        if spec["name"] in taken:
            raise ConfigError(f"{where}: name {spec['name']!r} is taken by an [[objects]] entry; give the mount "
                              "another name")
        add_object(scene, spec, base, where, materials or {}, library)
    return scene, {**library, **(materials or {})}
