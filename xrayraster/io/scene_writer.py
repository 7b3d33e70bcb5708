"""An in-memory :class:`~xrayraster.scene.scene.Scene` written as a scene file (docs/scene-format.md):
``scene.toml`` beside a folder of its meshes, which ``xrayraster render`` and :func:`load_scene_file`
read back into the same scene.

Meshes are Wavefront OBJ with 17 significant digits, which round-trip float64 (trimesh writes PLY and
STL in float32, and OBJ with a fixed number of decimals), so the vertices read back are the scene's
to the last bit and a render of the file equals a render of the scene. Every file is written
atomically.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import tomli_w

from ..core.errors import ConfigError
from ..core.files import atomic_writes
from ..scene.materials import Material
from ..scene.scene import Scene

#: The folder beside the TOML file that holds its meshes.
MESH_FOLDER = "meshes"


def write_scene_file(path, scene: Scene, geometry, *, source: dict | None = None,
                     detector: dict | None = None) -> Path:
    """Write ``scene`` seen by ``geometry`` (a ``ConeBeamGeometry`` or ``ParallelBeamGeometry``) as the
    scene file ``path``, its meshes in ``meshes/`` beside it. ``source`` and ``detector``: the file's
    ``[source]`` and ``[detector]`` tables (docs/scene-format.md), checked when the file is loaded.
    Objects keep their names, labels and priorities (and so their order of insertion, which breaks
    ties); a material is written to ``[materials]`` by its mass fractions and density, under its
    name (suffixed where two different materials share one), or kept as a library name."""
    scene.require_objects()
    path = Path(path)
    folder = path.parent / MESH_FOLDER
    names = _material_names(scene)
    materials = {names[o.material]: {"mass_fractions": o.material.mass_fractions, "density": o.material.density}
                 for o in scene.objects if isinstance(o.material, Material)}
    objects, writes = [], []
    for k, o in enumerate(scene.objects):
        mesh_file = folder / f"{k:04d}_{re.sub(r'[^A-Za-z0-9_.-]', '_', o.name)}.obj"
        writes.append((mesh_file, lambda tmp, mesh=o.mesh: _write_obj(tmp, mesh.vertices, mesh.faces)))
        objects.append({"name": o.name, "mesh": f"{MESH_FOLDER}/{mesh_file.name}", "material": names[o.material],
                        "label": o.label, "priority": o.priority})
    tables = {"geometry": geometry.to_dict(), "objects": objects}
    for key, table in (("materials", materials), ("source", source), ("detector", detector)):
        if table:
            tables[key] = table
    text = "# A scene written by xrayraster; its meshes are in meshes/.\n" + tomli_w.dumps(tables)
    writes.append((path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8")))  # last: the file that names them
    atomic_writes(writes)
    return path


def _write_obj(path, vertices_mm, faces) -> None:
    with open(path, "w", encoding="utf-8") as f:
        f.write("# xrayraster: vertices in mm, 17 significant digits (float64 exactly)\n")
        np.savetxt(f, vertices_mm, fmt="v %.17g %.17g %.17g")
        np.savetxt(f, faces + 1, fmt="f %d %d %d")


def _material_names(scene: Scene) -> dict:
    """{material: the name the file gives it}: a library name as it is, a Material its own name (made
    unique, so that no entry of ``[materials]`` hides another material or a library name in use)."""
    names: dict = {}
    for o in scene.objects:
        m = o.material
        if not isinstance(m, Material) and not (isinstance(m, str) and m):
            raise ConfigError(f"object {o.name!r}: material {m!r} cannot be written to a scene file; "
                              "give an xr.Material or a library material's name")
        if isinstance(m, str):
            names[m] = m
    for o in scene.objects:
        m = o.material
        if isinstance(m, Material) and m not in names:
            base, taken = re.sub(r"[^A-Za-z0-9_-]", "_", m.name) or "material", set(names.values())
            names[m] = next(n for n in (base, *(f"{base}_{i}" for i in range(2, len(names) + 3))) if n not in taken)
    return names
