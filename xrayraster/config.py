"""TOML scene files: a scan geometry plus objects (see docs/scene-format.md)."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .geometry import ConeBeamGeometry, ParallelBeamGeometry, full_circle
from .scene import Scene
from .transform import Transform


class ConfigError(ValueError):
    """A scene file is invalid; the message names the file, the field and the fix."""


@dataclass(frozen=True)
class SceneFile:
    path: Path
    geometry: ConeBeamGeometry | ParallelBeamGeometry
    scene: Scene


_GEOMETRY_KEYS = {
    "beam", "source_to_origin", "source_to_detector", "detector_shape", "pixel_size",
    "detector_offset", "num_views", "angles_deg", "start_angle_deg",
}
_OBJECT_KEYS = {"name", "mesh", "material", "label", "priority", "unit_scale", "translate", "rotate_deg"}


def load_scene_file(path) -> SceneFile:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such scene file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    _only(data, {"geometry", "objects"}, f"{path}")
    if "geometry" not in data:
        raise ConfigError(f"{path}: missing [geometry] table")
    geometry = _geometry(data["geometry"], f"{path} [geometry]")
    objects = data.get("objects", [])
    if not objects:
        raise ConfigError(f"{path}: no [[objects]]; add at least one object with a mesh and a material")
    scene = Scene()
    for k, spec in enumerate(objects):
        where = f"{path} [[objects]] #{k + 1}"
        _only(spec, _OBJECT_KEYS, where)
        for key in ("mesh", "material"):
            if key not in spec:
                raise ConfigError(f"{where}: missing '{key}'")
        scene.add(
            _mesh(spec["mesh"], path.parent, where),
            spec["material"],
            name=spec.get("name"),
            label=spec.get("label"),
            priority=spec.get("priority", 0),
            unit_scale=spec.get("unit_scale", 1.0),
            transform=_placement(spec, where),
        )
    return SceneFile(path, geometry, scene)


def _only(table: dict, allowed: set, where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}")


def _geometry(g: dict, where: str):
    _only(g, _GEOMETRY_KEYS, where)
    if "angles_deg" in g and "num_views" in g:
        raise ConfigError(f"{where}: give either 'num_views' (full circle) or 'angles_deg', not both")
    start = math.radians(g.get("start_angle_deg", 0.0))
    if "angles_deg" in g:
        angles = [math.radians(a) for a in g["angles_deg"]]
    else:
        angles = full_circle(g.get("num_views", 1), start)
    beam = g.get("beam", "cone")
    common = dict(
        detector_shape=_required(g, "detector_shape", where),
        pixel_size=_required(g, "pixel_size", where),
        angles=angles,
        detector_offset=g.get("detector_offset", (0.0, 0.0)),
    )
    if beam == "cone":
        return ConeBeamGeometry(_required(g, "source_to_origin", where), _required(g, "source_to_detector", where), **common)
    if beam == "parallel":
        return ParallelBeamGeometry(**common)
    raise ConfigError(f"{where}: beam must be 'cone' or 'parallel', got {beam!r}")


def _required(table: dict, key: str, where: str):
    if key not in table:
        raise ConfigError(f"{where}: missing '{key}'")
    return table[key]


def _mesh(spec, base: Path, where: str):
    if isinstance(spec, str):
        return base / spec
    if not isinstance(spec, dict):
        raise ConfigError(f"{where}: mesh must be a file path or a primitive table like {{ box = [10, 10, 10] }}")
    import trimesh

    kinds = {"box", "sphere", "cylinder"} & set(spec)
    if len(kinds) != 1:
        raise ConfigError(f"{where}: a mesh primitive needs exactly one of box, sphere, cylinder")
    kind = kinds.pop()
    if kind == "box":
        _only(spec, {"box"}, f"{where} mesh")
        return trimesh.creation.box(spec["box"])
    if kind == "sphere":
        _only(spec, {"sphere", "subdivisions"}, f"{where} mesh")
        return trimesh.creation.icosphere(subdivisions=spec.get("subdivisions", 4), radius=spec["sphere"])
    _only(spec, {"cylinder", "height", "sections"}, f"{where} mesh")
    return trimesh.creation.cylinder(radius=spec["cylinder"], height=_required(spec, "height", where), sections=spec.get("sections", 64))


def _placement(spec: dict, where: str) -> Transform | None:
    if "translate" not in spec and "rotate_deg" not in spec:
        return None
    t = Transform()
    for axis, angle in zip(np.eye(3), spec.get("rotate_deg", (0.0, 0.0, 0.0))):
        t = Transform.rotation(axis, math.radians(angle)) @ t  # about x, then y, then z
    offset = spec.get("translate", (0.0, 0.0, 0.0))
    if len(offset) != 3:
        raise ConfigError(f"{where}: translate must be [x, y, z] in mm")
    return Transform.translation(offset) @ t
