"""Explicit 4×4 homogeneous transforms, composed before use (``A @ B`` applies B first)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, repr=False)
class Transform:
    """An affine map of points in mm; ``eval(repr(t)) == t``."""

    matrix: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))

    def __post_init__(self):
        m = np.asarray(self.matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError(f"Transform.matrix must be a finite 4×4 matrix, got shape {m.shape}")
        if not np.allclose(m[3], (0, 0, 0, 1)):
            raise ValueError("Transform.matrix: the last row must be (0, 0, 0, 1) (affine maps only)")
        if abs(np.linalg.det(m[:3, :3])) < 1e-300:
            raise ValueError("Transform.matrix is singular: it would flatten the mesh")
        object.__setattr__(self, "matrix", tuple(tuple(float(x) for x in row) for row in m))

    def __repr__(self) -> str:
        return f"Transform(matrix={self.matrix!r})"

    @property
    def array(self) -> np.ndarray:
        return np.array(self.matrix, dtype=np.float64)

    def __matmul__(self, other: "Transform") -> "Transform":
        return Transform(self.array @ other.array)

    def apply(self, points) -> np.ndarray:
        """Transform ``(n, 3)`` points; float64 out."""
        m = self.array
        return np.asarray(points, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]

    @property
    def flips_orientation(self) -> bool:
        """True for a mirror (negative determinant): triangle winding must then be reversed."""
        return bool(np.linalg.det(self.array[:3, :3]) < 0)

    @classmethod
    def translation(cls, offset) -> "Transform":
        m = np.eye(4)
        m[:3, 3] = offset
        return cls(m)

    @classmethod
    def scaling(cls, factor) -> "Transform":
        m = np.eye(4)
        m[:3, :3] = np.diag(np.broadcast_to(np.asarray(factor, dtype=np.float64), (3,)))
        return cls(m)

    @classmethod
    def rotation(cls, axis, angle: float) -> "Transform":
        """Right-handed rotation by ``angle`` radians about ``axis`` through the origin."""
        a = np.asarray(axis, dtype=np.float64)
        n = np.linalg.norm(a)
        if not np.isfinite(n) or n == 0:
            raise ValueError(f"rotation axis must be a non-zero finite vector, got {axis!r}")
        x, y, z = a / n
        c, s = math.cos(angle), math.sin(angle)
        k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
        m = np.eye(4)
        m[:3, :3] = np.eye(3) + s * k + (1 - c) * (k @ k)
        return cls(m)
