"""Weave files (TOML): a woven sample to generate, and the scene file its export comes with.

A weave file holds a ``[weave]`` table, the unit cell (docs/weave.md), with four optional
sub-tables: ``[weave.sample]`` (tiling, mesh resolution, seed), ``[weave.distortion]``,
``[weave.voids]`` and ``[weave.materials]``; plus ``[materials.NAME]`` tables in the scene-file form for materials the
library does not have. A material name is looked up in ``[materials]`` first, then in the
library, as in scene files. The same ``[weave]`` table is what a scan file will hold.

The scene file written beside an export (:func:`write_scene_file`) is an ordinary scene file
(docs/scene-format.md): a cone-beam geometry that frames the sample
(:meth:`~xrayraster.core.geometry.ConeBeamGeometry.framing`), one ``[[objects]]`` entry per mesh
file with its label and priority, the sample moved so its box is centred on the rotation axis
(which runs along the sample's z, its thickness), each material as mass fractions and density,
and a tube source, so ``xrayraster render`` and ``xrayraster voxelize`` take it as it is.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomli_w

from ..core import fields
from ..core.errors import ConfigError, WeaveError
from ..core.estimate import plan
from ..core.files import atomic_write_text
from ..core.geometry import ConeBeamGeometry
from ..core.volume import VolumeGeometry
from ..scene.material_library import library_key
from ..scene.materials import Material
from ..weave.distort import Distortion
from ..weave.materials import FibreBundle, Tracer, YarnMaterials
from ..weave.sample import Sample
from ..weave.size import Size, WeaveJob
from ..weave.spec import UnitCell
from ..weave.voids import Voids
from .scene_file import library_material, parse_materials, read_toml

__all__ = [
    "WeaveFile", "framing_geometry", "load_weave_file", "sample_grid", "weave_from_dict",
    "write_scene_file",
]

_SUBTABLES = ("sample", "distortion", "materials", "voids")
#: The keys of the ``[weave.sample]`` table.
SAMPLE_TABLE_KEYS = {"cells", "layers_of_cells", "points_per_section", "samples_per_mm", "seed"}
_FAMILIES = ("matrix", "weft", "warp")

#: The source the exported scene file gets: the tube of a laboratory micro-CT scan of a carbon
#: composite (40 kV, tungsten, 2 mm aluminium; 10 W for 5 s a view, 1.25 mAs). Edit it there.
DEFAULT_SOURCE = {"kvp": 40.0, "filters": {"Al": 2.0}, "mas": 1.25}


@dataclass(frozen=True)
class WeaveFile:
    """A loaded weave file: the sample to generate and its materials (``path`` None for a table)."""

    path: Path | None
    sample: Sample
    materials: YarnMaterials


def load_weave_file(source) -> WeaveFile:
    """Read and validate a weave file, or the dict of one already parsed (TOML's tables as dicts);
    errors name the file (or "weave table"), the table and the field."""
    if isinstance(source, Mapping):
        path, data, where = None, source, "weave table"
    else:
        path = Path(source)
        data, where = read_toml(path, "weave file"), f"{path}"
    fields.only(data, {"weave", "materials"}, where)
    if "weave" not in data:
        raise ConfigError(f"{where}: missing [weave] table (the unit cell; every key may be left at its default)")
    materials = parse_materials(data["materials"], f"{where} [materials]") if "materials" in data else {}
    sample, yarn_materials = weave_from_dict(data["weave"], materials, f"{where} [weave]")
    plan(WeaveJob(sample, tables=True), ConfigError, f"{where} ")
    return WeaveFile(path, sample, yarn_materials)


def weave_from_dict(d, materials: dict[str, Material], where: str = "[weave]", *,
                    grid_chooses_knobs: bool = False) -> tuple[Sample, YarnMaterials]:
    """A ``[weave]`` table (with its sub-tables) → the sample and its materials.

    ``materials``: the file's own ``[materials]``, looked up before the library. A sample whose
    meshes cannot fit in memory is refused before its cell is built, naming the key that makes it
    large (:mod:`~xrayraster.weave.size`); ``grid_chooses_knobs``: the mesh knobs the table leaves
    out are chosen later from a scan's grid (a scan file), so they are checked at their coarsest.
    """
    d = fields.table(d, "weave", where.rsplit(" ", 1)[0])
    cell = UnitCell.arguments_from_dict({k: v for k, v in d.items() if k not in _SUBTABLES}, where)
    sub = {name: fields.table(d.get(name, {}), f"weave.{name}", where) for name in _SUBTABLES}
    sample_where = f"{where[:-1]}.sample]"
    s = sub["sample"]
    fields.only(s, SAMPLE_TABLE_KEYS, sample_where)
    kwargs = {}
    if "cells" in s:
        kwargs["cells"] = tuple(fields.vector(s["cells"], "cells", sample_where, 2, "[nx, ny]",
                                              element=fields.integer, lo=1))
    for key, lo in (("layers_of_cells", 1), ("points_per_section", 8), ("seed", 0)):
        if key in s:
            kwargs[key] = fields.integer(s[key], key, sample_where, lo)
    if "samples_per_mm" in s:
        kwargs["samples_per_mm"] = fields.number(s["samples_per_mm"], "samples_per_mm", sample_where, positive=True)
    _check_size(cell, kwargs, grid_chooses_knobs, where.removesuffix("[weave]"))
    cell = UnitCell.from_arguments(cell, where)
    distortion = Distortion.from_dict(sub["distortion"], f"{where[:-1]}.distortion]")
    voids = Voids.from_dict(sub["voids"], f"{where[:-1]}.voids]")
    try:
        sample = Sample(cell, distortion=distortion, voids=voids, **kwargs)
    except WeaveError as exc:
        raise ConfigError(f"{sample_where}: {exc}") from None
    return sample, _yarn_materials(sub["materials"], materials, f"{where[:-1]}.materials]")


def _check_size(cell: dict, sample: dict, grid_chooses_knobs: bool, file: str) -> None:
    """Refuse (ConfigError: ``file``, then the table and the key) a sample whose meshes cannot fit,
    from the checked keyword arguments of its cell and sample, before either is built."""
    knobs = {}
    if grid_chooses_knobs:  # at their coarsest: 8 points (the fewest), one sample per cell length
        size = Size.planned(cell, sample)
        knobs = {"points_per_section": 8, "samples_per_mm": 1.0 / (size.weft_per_layer * size.weft_spacing)}
    size = Size.planned(cell, {**knobs, **sample})
    plan(WeaveJob(size, export=False, tables=True), ConfigError, file)


def _yarn_materials(d: dict, materials: dict[str, Material], where: str) -> YarnMaterials:
    fields.only(d, {*_FAMILIES, "tracers"}, where)

    def material(value, field: str) -> Material:
        name = fields.string(value, field, where)
        if name in materials:
            return materials[name]
        if library_key(name):
            return library_material(name)
        raise ConfigError(f"{where}: {field}: material {name!r} is neither in [materials] "
                          f"({', '.join(sorted(materials)) or 'none defined'}) nor a library material "
                          f"({', '.join(Material.library_names())}); add a [materials.{name}] table or use one of those")

    def yarn_material(value, field: str):
        """A name, or a fibre bundle table (the yarn is the fibre in the sample's matrix)."""
        if not isinstance(value, dict):
            return material(value, field)
        fields.only(value, {"fibre", "fibre_fraction"}, f"{where} {field}")
        bundle = {}
        if "fibre" in value:
            bundle["fibre"] = material(value["fibre"], f"{field}.fibre")
        if "fibre_fraction" in value:
            bundle["fibre_fraction"] = fields.number(value["fibre_fraction"], f"{field}.fibre_fraction", where)
        return FibreBundle(**bundle)

    kwargs = {family: yarn_material(d[family], family) for family in ("weft", "warp") if family in d}
    if "matrix" in d:
        kwargs["matrix"] = material(d["matrix"], "matrix")
    tracers = d.get("tracers", [])
    if not isinstance(tracers, list):
        raise ConfigError(f"{where}: tracers must be an array of tables like "
                          f"[{{ yarn = \"weft_c0_l2_y3\", material = \"e_glass\" }}], got {tracers!r}")
    kwargs["tracers"] = tuple(_tracer(t, i, yarn_material, where) for i, t in enumerate(tracers))
    try:
        return YarnMaterials(**kwargs)
    except WeaveError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _tracer(spec, i: int, material, where: str) -> Tracer:
    """One ``tracers`` entry; ``material`` reads a name or a fibre bundle (default: e-glass at 0.6)."""
    field = f"tracers[{i}]"
    spec = fields.table(spec, field, where)
    fields.only(spec, {"yarn", "material", "label"}, f"{where} {field}")
    yarn = fields.string(fields.required(spec, "yarn", f"{where} {field}"), f"{field}.yarn", where)
    label = fields.integer(spec["label"], f"{field}.label", where, 1) if "label" in spec else None
    if "material" not in spec:
        return Tracer(yarn, label=label)
    return Tracer(yarn, material(spec["material"], f"{field}.material"), label)


def framing_geometry(box_mm, num_views: int = 360) -> ConeBeamGeometry:
    """The scan of the exported scene: a full circle about the box's centre line (z) that sees all of it."""
    lo, hi = np.asarray(box_mm, dtype=np.float64)
    radius = float(np.hypot(*(hi - lo)[:2]) / 2)
    return ConeBeamGeometry.framing(radius, float(hi[2] - lo[2]) / 2, num_views=num_views)


def sample_grid(box_mm, geometry: ConeBeamGeometry) -> VolumeGeometry:
    """Voxels over the (centred) box at the scan's magnified pixel pitch: the reconstruction's natural grid."""
    lo, hi = np.asarray(box_mm, dtype=np.float64)
    voxel = geometry.pixel_size[1] * geometry.source_to_origin / geometry.source_to_detector
    # A box turned by a pose is a whole number of voxels only up to rounding (cos 90° = 6e-17): that
    # must not add a voxel, so extents within 1e-9 voxel above a whole number round down.
    shape = tuple(int(np.ceil((hi[i] - lo[i]) / voxel - 1e-9)) for i in (2, 1, 0))
    return VolumeGeometry(shape, voxel)


def write_scene_file(path, report: dict, geometry: ConeBeamGeometry) -> Path:
    """The scene file of an export (module docstring), from its report; written atomically."""
    lo, hi = np.asarray(report["box_mm"], dtype=np.float64)
    centre = (lo + hi) / 2
    objects = [{"name": part["name"], "mesh": part["file"], "material": part["material"], "label": part["label"],
                "priority": part["priority"], "translate": (-centre).tolist()} for part in report["parts"]]
    materials = {name: {"mass_fractions": m["mass_fractions"], "density": m["density"]}
                 for name, m in report["materials"].items()}
    scene = {"geometry": geometry.to_dict(), "objects": objects, "materials": materials, "source": DEFAULT_SOURCE}
    header = (f"# The scene of a woven sample exported by xrayraster weave ({report['resolve']} resolve).\n"
              "# Render it: xrayraster render scene.toml -o radiograph.tif; edit [geometry] and [source] freely.\n")
    text = header + tomli_w.dumps(scene)
    return atomic_write_text(Path(path), text)

