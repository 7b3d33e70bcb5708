"""TOML scene files: a scan geometry plus objects (see docs/scene-format.md).

Materials by name: an object's ``material`` (or the detector's ``scintillator``) is looked up in
the file's ``[materials]`` first, then in the named-material library
(:mod:`xrayraster.scene.material_library`, e.g. "water", "pmma", "aluminium", "steel"), so a
``[materials]`` entry always wins over a library material of the same name.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core import fields
from ..core.choices import DETECTOR_MODES, SCATTER_MODELS
from ..core.errors import (
    ConfigError,
    MaterialError,
    MeshError,
    PhysicsError,
    SceneError,
    SpectrumError,
)
from ..core.geometry import ConeBeamGeometry, ParallelBeamGeometry, geometry_from_dict
from ..core.inputs import read_text_file
from ..core.transform import Transform
from ..physics.detector import Detector
from ..physics.realism import Realism
from ..physics.spectrum import Spectrum
from ..scene.material_library import library_key
from ..scene.materials import ENERGY_MAX_KEV, ENERGY_MIN_KEV, Material
from ..scene.scene import Scene


@dataclass(frozen=True)
class SceneFile:
    """A loaded scene file. ``materials`` ({NAME: Material}): the ``[materials]`` table and the
    library materials the objects use by name; None when the file has no ``[materials]`` and some
    object's material is neither (then only path lengths can be rendered). ``spectrum`` and
    ``detector`` are None when the file has no ``[source]`` or ``[detector]`` table; ``realism``
    holds the scanner's imperfections those tables ask for (docs/realism.md)."""

    path: Path
    geometry: ConeBeamGeometry | ParallelBeamGeometry
    scene: Scene
    materials: dict | None = None
    spectrum: Spectrum | None = None
    detector: Detector | None = None
    realism: Realism = Realism()


# The public key sets below are shared with the scan file's loader and its dotted keys
# (xrayraster.io.scan_file, xrayraster.io.scan_keys).

#: The keys of an ``[[objects]]`` entry.
OBJECT_KEYS = {"name", "mesh", "material", "label", "priority", "unit_scale", "translate", "rotate_deg"}
#: A mesh primitive's kind → the keys of its inline table.
PRIMITIVE_KEYS = {"box": {"box"}, "sphere": {"sphere", "subdivisions"}, "cylinder": {"cylinder", "height", "sections"}}
_MATERIAL_KINDS = ("element", "formula", "mass_fractions")
#: The keys of a ``[materials.NAME]`` table (or an inline scintillator table).
MATERIAL_KEYS = {*_MATERIAL_KINDS, "density"}
#: The ``[source]`` table: the key that picks the kind → every key of that kind.
SOURCE_KINDS = {
    "kvp": {"kvp", "anode", "anode_angle_deg", "filters", "mas", "bin_kev"},
    "monochromatic_kev": {"monochromatic_kev", "photons_per_mm2_at_1m"},
    "spectrum_file": {"spectrum_file"},
}
#: The ``[source]`` keys of the scanner's imperfections, allowed with any source kind.
SOURCE_REALISM_KEYS = {"focal_spot_mm", "focal_plane_mm"}
_DETECTOR_REALISM_KEYS = {"flat_fields", "gain_variation"}
#: The keys of the ``[physics]`` table: what the simulation models beyond the primary beam.
PHYSICS_KEYS = {"scatter"}
#: The keys of the ``[detector]`` table.
DETECTOR_KEYS = {"mode", "scintillator", "scintillator_mm", "blur_sigma_px", "psf", "electronic_noise", "dark",
                 *_DETECTOR_REALISM_KEYS}
_MAX_SUBDIVISIONS = 8  # 1.3 million triangles
_MAX_SECTIONS = 10_000


def read_toml(path: Path, kind: str) -> dict:
    """The tables of the TOML file ``path`` (UTF-8, a byte-order mark allowed); a file that cannot be
    read as text (:func:`~xrayraster.core.inputs.read_text_file`) or bad TOML is a ConfigError naming it."""
    text = read_text_file(path, kind)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


def load_scene_file(source, *, where: str = "scene table", base_dir=None,
                    objects_of: SceneFile | None = None) -> SceneFile:
    """Read and check a scene file, or the dict of one already parsed (the preview's edited table):
    then ``where`` names it in messages and as the result's ``path``, and mesh and spectrum files
    are relative to ``base_dir`` (default: the current directory). ``objects_of``: a file loaded
    before from the same ``[[objects]]`` and ``[materials]`` (the preview, when only the scanner's
    tables changed), whose scene and materials are taken as they are, no mesh read again. Errors are
    ConfigErrors naming the file (or ``where``), the table and the key."""
    if isinstance(source, Mapping):
        path, data, base = Path(where), source, Path(base_dir if base_dir is not None else ".")
    else:
        path = Path(source)
        data, base = read_toml(path, "scene file"), path.parent
    fields.only(data, {"geometry", "objects", "materials", "source", "detector", "physics"}, f"{path}")
    if "geometry" not in data:
        raise ConfigError(f"{path}: missing [geometry] table")
    if not isinstance(data["geometry"], dict):
        raise ConfigError(f"{path}: geometry must be a table ([geometry]), got {data['geometry']!r}")
    geometry = parse_geometry(data["geometry"], f"{path} [geometry]")
    if objects_of is not None:
        scene, materials = objects_of.scene, objects_of.materials
    else:
        scene, materials = _objects(data, base, path)
    spectrum = None
    if "source" in data:
        spectrum = parse_source(fields.table(data["source"], "source", f"{path}"), base, f"{path} [source]")
    detector = None
    if "detector" in data:
        detector = parse_detector(fields.table(data["detector"], "detector", f"{path}"), materials, f"{path} [detector]")
    return SceneFile(path, geometry, scene, materials, spectrum, detector, parse_realism(data, geometry, path))


def _objects(data: dict, base: Path, path: Path) -> tuple[Scene, dict | None]:
    """The ``[[objects]]`` as a scene, and the materials they and the detector may name."""
    materials = None
    if "materials" in data:
        materials = parse_materials(data["materials"], f"{path} [materials]")
    objects = data.get("objects", [])
    if not isinstance(objects, list):
        raise ConfigError(f"{path}: objects must be an array of tables ([[objects]]), got {objects!r}")
    if not objects:
        raise ConfigError(f"{path}: no [[objects]]; add at least one object with a mesh and a material")
    scene = Scene()
    library: dict[str, Material] = {}  # library materials the objects use, by the name they give
    for k, spec in enumerate(objects):
        where = f"{path} [[objects]] #{k + 1}"
        if not isinstance(spec, dict):
            raise ConfigError(f"{where}: must be a table ([[objects]]), got {spec!r}")
        add_object(scene, spec, base, where, materials, library)
    if library and (materials is not None or all(isinstance(o.material, Material) for o in scene.objects)):
        materials = {**library, **(materials or {})}
    return scene, materials


def add_object(scene: Scene, spec: dict, base: Path, where: str, materials: dict | None = None,
               library: dict | None = None) -> None:
    """Add one ``[[objects]]`` entry ``spec`` to ``scene``: its material looked up in ``materials``
    first, then in the library (a library material used is recorded in ``library``, by its name)."""
    name = spec.get("name")
    if name is not None:
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where}: name must be a non-empty string, got {name!r}")
        where = f"{where} ({name})"
    fields.only(spec, OBJECT_KEYS, where)
    mesh, material = fields.required(spec, "mesh", where), fields.required(spec, "material", where)
    if isinstance(material, (list, dict)):
        raise ConfigError(f"{where}: material must be a name (a string), got {material!r}")
    if materials is not None and isinstance(material, str) and material in materials:
        material = materials[material]  # [materials] wins over the library
    elif isinstance(material, str) and library_key(material):
        material = library_material(material)
        if library is not None:
            library[material.name] = material
    elif materials is not None:
        defined = ", ".join(sorted(materials)) or "none"
        raise ConfigError(
            f"{where}: material {material!r} is not defined in [materials] (defined: {defined}) nor a library "
            f"material ({', '.join(Material.library_names())}); add a [materials.{material}] table or use one of those"
        )
    label = spec.get("label")
    options = dict(
        name=name,
        label=None if label is None else fields.integer(label, "label", where, 1, 65535),
        priority=fields.number(spec.get("priority", 0), "priority", where),
        unit_scale=fields.number(spec.get("unit_scale", 1.0), "unit_scale", where, positive=True),
        transform=_placement(spec, where),
    )
    source = _mesh(mesh, base, where)
    try:
        scene.add(source, material, **options)
    except (MeshError, SceneError) as exc:  # open mesh, NaN vertices, unreadable file: name the entry
        what = f"mesh file {str(source)!r}" if isinstance(source, Path) else f"mesh primitive {mesh!r}"
        raise ConfigError(f"{where}: {what}: {exc}") from None


def library_material(name: str) -> Material:
    """The library material ``name`` stands for, called ``name`` (as the file writes it)."""
    return dataclasses.replace(Material.named(name), name=name)


# ----------------------------------------------------------------------------- tables


def parse_geometry(g, where: str):
    """The ``[geometry]`` table: the dict form of a cone or parallel scan (:mod:`xrayraster.core.geometry`)."""
    if isinstance(g, dict) and "vectors" in g:
        raise ConfigError(f"{where}: scene files take cone or parallel geometries; 'vectors' is for scan files")
    return geometry_from_dict(g, where)


def _mesh(spec, base: Path, where: str):
    if isinstance(spec, str) and spec:
        return base / spec
    if not isinstance(spec, dict):
        raise ConfigError(
            f"{where}: mesh must be a file path or a primitive table like {{ box = [10, 10, 10] }}, got {spec!r}"
        )
    import trimesh

    where = f"{where} mesh"
    kinds = set(PRIMITIVE_KEYS) & set(spec)
    if len(kinds) != 1:
        fields.only(spec, set().union(*PRIMITIVE_KEYS.values()), where)
        raise ConfigError(f"{where}: a mesh primitive needs exactly one of box, sphere, cylinder")
    kind = kinds.pop()
    fields.only(spec, PRIMITIVE_KEYS[kind], where)
    if kind == "box":
        extents = fields.vector(spec["box"], "box", where, 3, "[x, y, z] edge lengths in mm", positive=True)
        return trimesh.creation.box(extents)
    if kind == "sphere":
        return trimesh.creation.icosphere(
            subdivisions=fields.integer(spec.get("subdivisions", 4), "subdivisions", where, 0, _MAX_SUBDIVISIONS),
            radius=fields.number(spec["sphere"], "sphere", where, positive=True),
        )
    return trimesh.creation.cylinder(
        radius=fields.number(spec["cylinder"], "cylinder", where, positive=True),
        height=fields.number(fields.required(spec, "height", where), "height", where, positive=True),
        sections=fields.integer(spec.get("sections", 64), "sections", where, 3, _MAX_SECTIONS),
    )


def _placement(spec: dict, where: str) -> Transform | None:
    if "translate" not in spec and "rotate_deg" not in spec:
        return None
    rotate = fields.vector(spec.get("rotate_deg", [0, 0, 0]), "rotate_deg", where, 3, "[x, y, z] in degrees")
    offset = fields.vector(spec.get("translate", [0, 0, 0]), "translate", where, 3, "[x, y, z] in mm")
    t = Transform()
    for axis, angle in zip(np.eye(3), rotate):
        t = Transform.rotation(axis, math.radians(angle)) @ t  # about x, then y, then z
    return Transform.translation(offset) @ t


def parse_materials(specs, where: str) -> dict[str, Material]:
    """The ``[materials]`` table → {NAME: Material}; ``where`` names it (``"FILE [materials]"``)."""
    specs = fields.table(specs, "materials", where.rsplit(" ", 1)[0])
    return {name: _material(spec, name, f"{where[:-1]}.{name}]") for name, spec in specs.items()}


def _material(spec, name: str, where: str) -> Material:
    """One ``[materials.NAME]`` table (or an inline scintillator table) → a Material called ``name``."""
    if not isinstance(spec, dict):
        raise ConfigError(
            f"{where}: must be a table such as {{ element = \"Al\" }}, {{ formula = \"H2O\", density = 1.0 }} "
            f"or {{ mass_fractions = {{ Fe = 0.98, C = 0.02 }}, density = 7.85 }}, got {spec!r}"
        )
    fields.only(spec, MATERIAL_KEYS, where)
    kinds = [k for k in _MATERIAL_KINDS if k in spec]
    if len(kinds) != 1:
        given = f"got {' and '.join(kinds)}" if kinds else "got none"
        raise ConfigError(f"{where}: give exactly one of element, formula, mass_fractions ({given})")
    kind = kinds[0]
    density = spec.get("density")
    if density is not None:
        density = fields.number(density, "density", where, positive=True)
    elif kind != "element":
        raise ConfigError(f"{where}: missing 'density' (g/cm³); a {kind} material needs one")
    try:
        if kind == "element":
            return Material.element(fields.string(spec["element"], "element", where), density, name=name)
        if kind == "formula":
            return Material.from_formula(fields.string(spec["formula"], "formula", where), density, name=name)
        fractions = spec["mass_fractions"]
        if not isinstance(fractions, dict) or not fractions:
            raise ConfigError(
                f"{where}: mass_fractions must be a table of element → mass fraction, "
                f"e.g. {{ Fe = 0.98, C = 0.02 }}, got {fractions!r}"
            )
        checked = {el: fields.number(w, f"mass_fractions.{el}", where, nonnegative=True) for el, w in fractions.items()}
        return Material.from_mass_fractions(checked, density, name=name)
    except MaterialError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def parse_source(src: dict, base: Path, where: str) -> Spectrum:
    """The ``[source]`` table → its Spectrum; a ``spectrum_file`` is relative to ``base``."""
    fields.only(src, set().union(*SOURCE_KINDS.values(), SOURCE_REALISM_KEYS), where)
    kinds = [k for k in SOURCE_KINDS if k in src]
    if len(kinds) != 1:
        given = f"got {' and '.join(kinds)}" if kinds else "got none"
        raise ConfigError(
            f"{where}: give exactly one source kind: kvp (an X-ray tube), monochromatic_kev, or spectrum_file ({given})"
        )
    kind = kinds[0]
    stray = sorted(set(src) - SOURCE_KINDS[kind] - SOURCE_REALISM_KEYS)
    if stray:
        raise ConfigError(
            f"{where}: {', '.join(stray)} do(es) not apply to a {kind} source; "
            f"allowed with {kind}: {', '.join(sorted(SOURCE_KINDS[kind]))}"
        )
    try:
        if kind == "kvp":
            filters = src.get("filters", {})
            if not isinstance(filters, dict):
                raise ConfigError(f"{where}: filters must be a table of material → thickness in mm, e.g. {{ Al = 2.0 }}, got {filters!r}")
            return Spectrum.from_tube(
                kvp=fields.number(src["kvp"], "kvp", where, positive=True),
                anode=fields.string(src.get("anode", "W"), "anode", where),
                anode_angle_deg=fields.number(src.get("anode_angle_deg", 12.0), "anode_angle_deg", where, positive=True),
                filters={m: fields.number(t, f"filters.{m}", where, nonnegative=True) for m, t in filters.items()},
                mas=fields.number(src.get("mas", 1.0), "mas", where, positive=True),
                bin_kev=fields.number(src.get("bin_kev", 0.5), "bin_kev", where, positive=True),
            )
        if kind == "monochromatic_kev":
            energy = fields.number(src["monochromatic_kev"], "monochromatic_kev", where, positive=True)
            if not ENERGY_MIN_KEV <= energy <= ENERGY_MAX_KEV:
                raise ConfigError(
                    f"{where}: monochromatic_kev must be in [{ENERGY_MIN_KEV:g}, {ENERGY_MAX_KEV:g}] keV "
                    f"(the range of the attenuation tables), got {src['monochromatic_kev']!r}"
                )
            photons = fields.number(fields.required(src, "photons_per_mm2_at_1m", where), "photons_per_mm2_at_1m", where, positive=True)
            return Spectrum.monochromatic(energy, photons)
        return Spectrum.from_file(base / fields.string(src["spectrum_file"], "spectrum_file", where))
    except SpectrumError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def parse_detector(spec: dict, materials: dict | None, where: str) -> Detector:
    """The ``[detector]`` table → a Detector; a scintillator by name from ``materials`` or the library."""
    fields.only(spec, DETECTOR_KEYS, where)
    mode = spec.get("mode", "integrating")
    if mode not in DETECTOR_MODES:
        raise ConfigError(f"{where}: mode must be 'integrating' or 'counting', got {mode!r}")
    scintillator = spec.get("scintillator")
    if isinstance(scintillator, str) and (materials is None or scintillator not in materials) \
            and library_key(scintillator):
        scintillator = library_material(scintillator)
    elif isinstance(scintillator, str):
        if materials is None or scintillator not in materials:
            defined = ", ".join(sorted(materials)) if materials else "none"
            raise ConfigError(
                f"{where}: scintillator {scintillator!r} is not defined in [materials] (defined: {defined}) nor a library "
                f"material ({', '.join(Material.library_names())}); add "
                f"[materials.{scintillator}], or give an inline table such as {{ formula = \"CsI\", density = 4.51 }}"
            )
        scintillator = materials[scintillator]
    elif isinstance(scintillator, dict):
        label = scintillator.get("element") or scintillator.get("formula") or "scintillator"
        scintillator = _material(scintillator, label if isinstance(label, str) else "scintillator", f"{where} scintillator")
    elif scintillator is not None:
        raise ConfigError(
            f"{where}: scintillator must be a material name from [materials] or an inline table such as "
            f"{{ formula = \"CsI\", density = 4.51 }}, got {scintillator!r}"
        )
    thickness = fields.number(spec.get("scintillator_mm", 0.0), "scintillator_mm", where, nonnegative=True)
    if (scintillator is None) != (thickness == 0):
        raise ConfigError(f"{where}: give both scintillator and scintillator_mm > 0, or neither (every photon then counts)")
    try:
        return Detector(
            mode=mode,
            scintillator=scintillator,
            scintillator_mm=thickness,
            blur_sigma_px=fields.number(spec.get("blur_sigma_px", 0.0), "blur_sigma_px", where, nonnegative=True),
            psf=_psf(spec["psf"], where) if "psf" in spec else None,
            electronic_noise=fields.number(spec.get("electronic_noise", 0.0), "electronic_noise", where, nonnegative=True),
            dark=fields.number(spec.get("dark", 0.0), "dark", where, nonnegative=True),
        )
    except PhysicsError as exc:  # the psf's shape and sum, and psf with blur_sigma_px
        raise ConfigError(f"{where}: {exc}") from None


def _psf(value, where: str) -> tuple:
    """The ``psf`` key: rows of numbers, an odd-sized 2-D kernel (the Detector checks shape and sum)."""
    form = "an array of rows of numbers (an odd-sized 2-D kernel), e.g. [[0, 1, 0], [1, 4, 1], [0, 1, 0]]"
    rows = fields.vector(value, "psf", where, None, form, element=lambda row, field, w: fields.vector(
        row, field, w, None, form, element=fields.number, nonnegative=True))
    if len({len(row) for row in rows}) != 1:
        raise ConfigError(f"{where}: psf rows must all have the same length, got {[len(row) for row in rows]}")
    return rows


def parse_realism(data: dict, geometry, path: Path) -> Realism:
    """The scanner's imperfections (docs/realism.md) from ``[source]`` (``focal_spot_mm``,
    ``focal_plane_mm``), ``[detector]`` (``flat_fields``, ``gain_variation``) and ``[physics]``
    (``scatter``); all off by default."""
    source, detector = data.get("source", {}), data.get("detector", {})
    physics = fields.table(data.get("physics", {}), "physics", f"{path}")
    fields.only(physics, PHYSICS_KEYS, f"{path} [physics]")
    where_source, where_detector = f"{path} [source]", f"{path} [detector]"
    options = {}
    if "focal_spot_mm" in source:
        options["focal_spot_mm"] = fields.number(source["focal_spot_mm"], "focal_spot_mm", where_source,
                                                 nonnegative=True)
        if options["focal_spot_mm"] and geometry.beam != "cone":
            raise ConfigError(f"{where_source}: focal_spot_mm applies to cone-beam scans; a parallel beam has no "
                              "source point (remove it, or use beam = \"cone\")")
    if "focal_plane_mm" in source:
        plane = fields.number(source["focal_plane_mm"], "focal_plane_mm", where_source, positive=True)
        if not options.get("focal_spot_mm"):
            raise ConfigError(f"{where_source}: focal_plane_mm needs focal_spot_mm > 0 (the spot whose blur it places)")
        if plane >= geometry.source_to_detector:
            raise ConfigError(f"{where_source}: focal_plane_mm ({plane:g} mm from the source) must lie before the "
                              f"detector (source_to_detector = {geometry.source_to_detector:g} mm)")
        options["focal_plane_mm"] = plane
    if "flat_fields" in detector:
        options["flat_fields"] = fields.integer(detector["flat_fields"], "flat_fields", where_detector, 1)
    if "gain_variation" in detector:
        options["gain_variation"] = fields.number(detector["gain_variation"], "gain_variation", where_detector,
                                                  nonnegative=True)
    if "scatter" in physics:
        options["scatter"] = fields.choice(physics["scatter"], "scatter", f"{path} [physics]", SCATTER_MODELS)
    return Realism(**options)
