"""Mesh files and the report of a woven sample: what ``Sample.export`` and ``xrayraster weave`` write.

Work on :class:`MeshPart` lists (what :meth:`Sample.parts` builds), never on a ``Sample``, so the
sample module can call in here without a cycle.

**Files.** One mesh per part, named ``<part>.<format>`` (STL binary or PLY binary, by trimesh),
each written atomically. With ``per="family"`` the parts are the matrix, the wefts and the warps
(plus one per tracer yarn, which has its own material); with ``per="yarn"`` every yarn is a part.

**Volumes.** ``report["volume_mm3"]`` gives the space each family *occupies* once overlaps are
settled the way the scene settles them: by priority (warp over weft over matrix; within a family
any overlap counts once). So the matrix, weft and warp volumes always add up to the box's, and
the fractions are of the box. They are exact mesh volumes (manifold3d, float64): with
``resolve="boolean"`` the sums of the disjoint meshes written; with ``"priority"`` the family
unions minus what higher families take from them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ..core.choices import MESH_FORMATS, check_choice
from ..core.errors import WeaveError
from ..core.files import atomic_write, atomic_write_text
from ..core.provenance import package_version
from ..scene.materials import Material
from .manifold_mesh import box_minus, from_manifold, to_manifold, union, without_slivers
from .yarn import PRIORITIES

__all__ = [
    "GENERATOR", "REPORT_NAME", "MeshPart", "export_report", "material_entry", "merge_meshes", "mesh_bounds",
    "occupied_volumes", "part_file", "settle", "write_parts", "write_report",
]

REPORT_NAME = "report.json"
GENERATOR = "xrayraster weave"


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One object of a sample's scene and one mesh file of its export."""

    name: str
    family: str  # "matrix", "weft" or "warp"
    material: Material
    label: int
    priority: float
    mesh: trimesh.Trimesh


def occupied_volumes(parts: list[MeshPart], families: dict[str, float]) -> dict[str, float]:
    """Volume (mm³) each family occupies when the higher ``families`` priority takes shared space.

    ``families`` maps family → priority; the matrix (lowest) is what the higher families leave of
    its parts. Exact: unions and differences of the meshes in manifold3d, float64.
    """
    solids = {f: union([to_manifold(p.mesh, p.name) for p in parts if p.family == f]) for f in families}
    out, above = {}, None
    for family in sorted(families, key=families.get, reverse=True):
        solid = solids[family] if above is None else solids[family] - above
        out[family] = float(solid.volume())
        above = solids[family] if above is None else above + solids[family]
    return out


def merge_meshes(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """One closed mesh of the space ``meshes`` fill: their union (manifold3d, float64), so a family's
    file has no overlapping or touching shells, whichever way its yarns were resolved."""
    return from_manifold(union([to_manifold(m) for m in meshes]))


def settle(objects: list[tuple[str, str, trimesh.Trimesh]], priorities: dict[str, float], box_mm):
    """Disjoint meshes from overlapping ``(name, family, mesh)`` objects, and the matrix around them.

    In order of family priority, highest first (a tracer, named apart from its family, before its
    family: it wins ties as in the scene), each object loses what the objects before it hold. Returns
    the objects in their given order with their new meshes, the matrix (``box_mm`` minus all of
    them, :func:`~xrayraster.weave.manifold_mesh.box_minus`) and the volume (mm³) the new meshes
    still share pairwise (manifold3d, float64: ~0).
    """
    order = sorted(range(len(objects)), key=lambda i: (-priorities[objects[i][1]], objects[i][0] == objects[i][1]))
    solids: dict[int, object] = {}
    taken = None
    for i in order:
        name, _, mesh = objects[i]
        solid = to_manifold(mesh, name)
        solids[i] = solid if taken is None else solid - taken
        taken = solid if taken is None else taken + solid
    shared = sum((solids[i] ^ solids[j]).volume() for k, i in enumerate(order) for j in order[k + 1:])
    settled = [(name, family, from_manifold(solids[i])) for i, (name, family, _) in enumerate(objects)]
    return settled, from_manifold(without_slivers(box_minus(box_mm, [taken]))), float(shared)


def write_parts(parts: list[MeshPart], directory, fmt: str) -> dict[str, str]:
    """Write each part's mesh as ``<name>.<fmt>`` in ``directory``; returns {part name: file name}."""
    check_choice(fmt, MESH_FORMATS, "format", WeaveError)
    directory = Path(directory)
    files = {}
    for part in parts:
        name = part_file(part.name, fmt)
        atomic_write(directory / name, lambda tmp, mesh=part.mesh: mesh.export(tmp, file_type=fmt))
        files[part.name] = name
    return files


def export_report(parts: list[MeshPart], facts: dict, settings: dict, box, *, resolve: str, per: str,
                  fmt: str) -> dict:
    """The report of an export (``Sample.exported``): the sample's ``settings`` (cell, tiling,
    resolution, seed, distortion), how it was resolved and written, the yarn counts and
    interpenetration of ``facts`` (``Sample.parts``), every part's file, family, label, priority and
    material, the materials, the ``box`` (mm) and the meshes' bounds, and each family's occupied
    volume (mm³, :func:`occupied_volumes`) and fraction of the box."""
    volumes = occupied_volumes(parts, PRIORITIES)
    lo, hi = (np.asarray(corner, dtype=float) for corner in box)
    box_volume = float(np.prod(hi - lo))
    keys = [p.name if p.name in facts["tracers"] else p.family for p in parts]  # a tracer's material is its own
    return {
        **settings,
        "resolve": resolve, "per": per, "format": fmt,
        "yarns": facts["yarns"],
        "triangles": int(sum(len(p.mesh.faces) for p in parts)),
        "parts": [{"name": p.name, "file": part_file(p.name, fmt), "family": p.family, "label": p.label,
                   "priority": p.priority, "material": key} for p, key in zip(parts, keys)],
        "materials": {key: material_entry(p.material) for p, key in zip(parts, keys)},
        "box_mm": [lo.tolist(), hi.tolist()],
        "mesh_bounds_mm": mesh_bounds(parts),
        "volume_mm3": {"box": box_volume, **volumes},
        "volume_fraction": {f: v / box_volume for f, v in volumes.items()},
        "interpenetration_mm3": facts["interpenetration_mm3"],
    }


def part_file(name: str, fmt: str) -> str:
    """The file name of part ``name``'s mesh."""
    return f"{name}.{fmt}"


def write_report(report: dict, directory) -> Path:
    """``report.json`` in ``directory``, written atomically."""
    text = json.dumps({"generator": GENERATOR, "version": package_version(), **report}, indent=2) + "\n"
    return atomic_write_text(Path(directory) / REPORT_NAME, text)


def material_entry(material: Material) -> dict:
    """A material as the report and scene files give it: name, density (g/cm³), mass fractions."""
    return {"name": material.name, "density": material.density, "mass_fractions": material.mass_fractions}


def mesh_bounds(parts: list[MeshPart]) -> list[list[float]]:
    """The ``[[min], [max]]`` corners (mm) of every part's vertices."""
    lo = np.min([p.mesh.bounds[0] for p in parts], axis=0)
    hi = np.max([p.mesh.bounds[1] for p in parts], axis=0)
    return [lo.tolist(), hi.tolist()]

