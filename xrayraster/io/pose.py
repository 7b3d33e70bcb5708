"""A scan file's ``[pose]``: where the sample sits in the scanner, varied from scan to scan.

``offset_mm = [x, y, z]`` and ``tilt_deg = [about_x, about_y, about_z]`` (both default zero), in the
scanner frame (docs/geometry.md). The sample is first turned about the scanner's fixed x axis, then
y, then z (``R = R_z · R_y · R_x``, right-handed), all about its own box centre as placed without the
pose (``pivot_mm``: the origin for a ``[weave]``, which is centred on the axis; the objects' bounds
centre for ``[[objects]]``), and then moved by the offset: ``p' = R (p − pivot) + pivot + offset``.
The labels are voxelized from the same posed scene, so they follow; a ``[[mount]]`` is not posed
(a holder stays where the file puts it). Tilts lie in [−180, 180]: a value beyond is refused rather
than wrapped, so each recorded pose has one spelling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core import fields
from ..core.errors import ConfigError
from ..core.transform import Transform
from ..scene.scene import Scene

__all__ = ["POSE_KEYS", "Pose"]

#: The keys of the ``[pose]`` table.
POSE_KEYS = {"offset_mm", "tilt_deg"}
_AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
MAX_TILT_DEG = 180.0


@dataclass(frozen=True)
class Pose:
    """``offset_mm`` (x, y, z, mm), ``tilt_deg`` (about x, y, z, degrees) and ``pivot_mm`` (x, y, z,
    mm), the point the tilts turn about: not a file key, the loader sets it to the sample's box
    centre (module docstring)."""

    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tilt_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pivot_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def from_dict(cls, d: dict, where: str) -> "Pose":
        """The ``[pose]`` table, checked: three finite numbers each, tilts within ±180 degrees."""
        fields.only(d, POSE_KEYS, where)
        pose = {}
        if "offset_mm" in d:
            pose["offset_mm"] = fields.vector(d["offset_mm"], "offset_mm", where, 3, "[x, y, z] in mm")
        if "tilt_deg" in d:
            tilt = fields.vector(d["tilt_deg"], "tilt_deg", where, 3, "[about_x, about_y, about_z] in degrees")
            for i, t in enumerate(tilt):
                if abs(t) > MAX_TILT_DEG:
                    raise ConfigError(f"{where}: tilt_deg[{i}] must be within [-180, 180] degrees, got {t!r}; "
                                      f"use {t - 360 * round(t / 360)!r} for the same turn")
            pose["tilt_deg"] = tilt
        return cls(**pose)

    def to_dict(self) -> dict:
        """The pose as given, and the pivot the loader chose, for the scan's metadata."""
        return {"offset_mm": list(self.offset_mm), "tilt_deg": list(self.tilt_deg), "pivot_mm": list(self.pivot_mm)}

    def about(self, pivot_mm) -> "Pose":
        """This pose turning about ``pivot_mm`` (the sample's box centre without the pose)."""
        return Pose(self.offset_mm, self.tilt_deg, tuple(float(v) for v in pivot_mm))

    @property
    def is_identity(self) -> bool:
        return not any(self.offset_mm) and not any(self.tilt_deg)

    @property
    def transform(self) -> Transform:
        """The 4×4 map ``T(pivot + offset) · R_z · R_y · R_x · T(−pivot)`` (``A @ B`` applies B first)."""
        turn = Transform()
        for axis, degrees in zip(_AXES, self.tilt_deg):
            turn = Transform.rotation(axis, math.radians(degrees)) @ turn  # x first, then y, then z
        pivot = np.asarray(self.pivot_mm)
        return Transform.translation(pivot + np.asarray(self.offset_mm)) @ turn @ Transform.translation(-pivot)

    def box(self, box_mm) -> np.ndarray:
        """The ``(2, 3)`` min/max corners enclosing ``box_mm`` posed: the bounds of its posed corners."""
        lo, hi = np.asarray(box_mm, dtype=np.float64)
        corners = np.array([[(lo, hi)[k >> i & 1][i] for i in range(3)] for k in range(8)])
        posed = self.transform.apply(corners)
        return np.stack([posed.min(axis=0), posed.max(axis=0)])

    def place(self, scene: Scene) -> Scene:
        """``scene`` with every object posed (names, materials, labels and priorities kept); itself when
        the pose is the identity."""
        if self.is_identity:
            return scene
        posed = Scene()
        for o in scene.objects:
            posed.add(o.mesh, o.material, label=o.label, priority=o.priority, name=o.name, transform=self.transform)
        return posed
