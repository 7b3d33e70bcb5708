"""The voxel grid every volume lives on: reconstructions and label volumes alike.

Volumes are C-ordered ``(z, y, x)``. Voxel ``(k, j, i)`` has its centre at
``(index − (n − 1)/2)·voxel_size + offset`` along each axis (mm), so with no offset the scanner
origin (on the rotation axis, :mod:`xrayraster.core.geometry`) is the centre of the grid. A
reconstruction and its labels share one :class:`VolumeGeometry`, so they line up voxel for voxel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import fields
from .errors import GeometryError
from .validate import finite, positive_ints, set_field


@dataclass(frozen=True, eq=True, repr=False)
class VolumeGeometry:
    """A voxel grid in the scanner frame: ``shape`` (z, y, x), ``voxel_size`` mm, ``offset`` mm.

    Voxel centres along each axis are ``(index − (n − 1)/2)·voxel_size + offset``.
    """

    shape: tuple[int, int, int]
    voxel_size: tuple[float, float, float]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        set_field(self, "shape", positive_ints("shape", self.shape, 3))
        vs = self.voxel_size
        if np.ndim(vs) == 0:
            vs = (vs,) * 3
        if len(vs) != 3:
            raise GeometryError(f"voxel_size must be a number or a (z, y, x) triple, got {vs!r}")
        set_field(self, "voxel_size", tuple(finite(f"voxel_size[{i}]", x, positive=True) for i, x in enumerate(vs)))
        if len(self.offset) != 3:
            raise GeometryError(f"offset must be a (z, y, x) triple in mm, got {self.offset!r}")
        set_field(self, "offset", tuple(finite(f"offset[{i}]", x) for i, x in enumerate(self.offset)))

    def __repr__(self) -> str:
        return f"VolumeGeometry(shape={self.shape!r}, voxel_size={self.voxel_size!r}, offset={self.offset!r})"

    def to_dict(self) -> dict:
        """``{"shape": [z, y, x], "voxel_size": [z, y, x], "offset": [z, y, x]}`` (mm): JSON and TOML ready."""
        return {"shape": list(self.shape), "voxel_size": list(self.voxel_size), "offset": list(self.offset)}

    @classmethod
    def from_dict(cls, d: dict, where: str = "volume") -> "VolumeGeometry":
        """A volume grid from its dict form; errors name ``where`` and the field."""
        d = fields.mapping(d, where)
        fields.only(d, {"shape", "voxel_size", "offset"}, where)
        shape = fields.one_or_three(fields.required(d, "shape", where), "shape", where, "voxel counts", fields.integer, lo=1)
        voxel = fields.one_or_three(fields.required(d, "voxel_size", where), "voxel_size", where, "in mm", fields.number,
                              positive=True)
        offset = fields.vector(d.get("offset", [0.0, 0.0, 0.0]), "offset", where, 3, "[z, y, x] in mm")
        return fields.construct(cls, where, shape=shape, voxel_size=voxel, offset=offset)

    def axis_centres(self, axis: int) -> np.ndarray:
        """Voxel-centre coordinates (mm) along ``axis`` (0 = z, 1 = y, 2 = x)."""
        n = self.shape[axis]
        return (np.arange(n) - (n - 1) / 2) * self.voxel_size[axis] + self.offset[axis]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Outer corners (mm) of the grid as two ``(x, y, z)`` points."""
        half = np.array(self.shape[::-1]) * np.array(self.voxel_size[::-1]) / 2
        centre = np.array(self.offset[::-1])
        return centre - half, centre + half
