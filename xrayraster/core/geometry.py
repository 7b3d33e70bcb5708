"""Scan and volume geometry: the one module that defines xrayraster's frames and units.

Every stage (renderer, reconstruction, voxelizer) reads these objects, so a label volume and
its reconstruction line up by construction.

Conventions
-----------
* Lengths in mm. Angles in radians in the Python API (degrees only in TOML configs).
* Scanner frame: right-handed, rotation axis z through the origin. At view angle θ the source
  sits at ``R_z(θ)·(0, −SOD, 0)`` and the detector centre at ``R_z(θ)·(0, SDD − SOD, 0)``; the
  gantry turns counter-clockwise seen from +z (equivalently the sample turns by −θ).
* Detector images are ``(row, col)`` arrays. Columns step along ``u = R_z(θ)·(1, 0, 0)``, rows
  along ``v = (0, 0, 1)``: the row index grows with z, as in ASTRA's ``cone_vec``. The centre of
  pixel (r, c) is ``d + (c − (ncol − 1)/2)·u + (r − (nrow − 1)/2)·v``, where ``u`` and ``v`` are
  one pixel long and ``d`` is the detector centre (moved by ``detector_offset``).
* Vector form (:class:`VectorGeometry`): one row of 12 numbers per view, ``(s, d, u, v)`` for a
  cone beam (source point) and ``(r, d, u, v)`` for a parallel beam (ray direction), exactly as
  ASTRA's ``cone_vec`` / ``parallel3d_vec``. Any scanner, tilted or misaligned, is a vector
  geometry; the circular geometries convert to it with :meth:`to_vec`.
* Volumes are C-ordered ``(z, y, x)``. Voxel ``(k, j, i)`` has its centre at
  ``(index − (n − 1)/2)·voxel_size + offset`` along each axis, so with no offset the scanner
  origin is the centre of the voxel grid.

All geometry objects are small immutable values: ``eval(repr(g)) == g``, ``g[views]`` selects a
subset of views, and construction validates every field with an error that names it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .choices import BEAMS, check_choice
from .errors import GeometryError

__all__ = [
    "ConeBeamGeometry",
    "ParallelBeamGeometry",
    "VectorGeometry",
    "VolumeGeometry",
    "full_circle",
]


def _finite(name: str, value: float, *, positive: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise GeometryError(f"{name} must be finite, got {x}")
    if positive and x <= 0:
        raise GeometryError(f"{name} must be > 0, got {x}")
    return x


def _pair(name: str, value, *, positive: bool) -> tuple[float, float]:
    if np.ndim(value) == 0:
        value = (value, value)
    if len(value) != 2:
        raise GeometryError(f"{name} must be a number or a (row, col) pair, got {value!r}")
    return tuple(_finite(f"{name}[{i}]", v, positive=positive) for i, v in enumerate(value))


def _shape(name: str, value, ndim: int) -> tuple[int, ...]:
    if np.ndim(value) == 0:
        value = (value,) * ndim
    if len(value) != ndim:
        raise GeometryError(f"{name} must have {ndim} entries, got {value!r}")
    out = []
    for i, n in enumerate(value):
        if not np.isfinite(n) or int(n) != n or n < 1:
            raise GeometryError(f"{name}[{i}] must be a positive integer, got {n!r}")
        out.append(int(n))
    return tuple(out)


def _angles(value) -> tuple[float, ...]:
    a = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if a.ndim != 1 or a.size == 0:
        raise GeometryError("angles must be a non-empty 1-D sequence of radians")
    if not np.all(np.isfinite(a)):
        raise GeometryError("angles must be finite (radians)")
    return tuple(float(x) for x in a)


def _select(items: tuple, index) -> tuple:
    """Subset of per-view items by int, slice or integer array (tomosipo-style indexing)."""
    if isinstance(index, (int, np.integer)):
        return (items[index],)
    if isinstance(index, slice):
        return items[index]
    idx = np.asarray(index)
    if idx.dtype == bool:
        idx = np.flatnonzero(idx)
    return tuple(items[int(i)] for i in idx)


def full_circle(num_views: int, start: float = 0.0) -> tuple[float, ...]:
    """``num_views`` equally spaced angles (radians) over 2π, end point excluded."""
    n = _shape("num_views", num_views, 1)[0]
    return tuple(float(start + 2 * math.pi * k / n) for k in range(n))


def _rot_z(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class _ScanGeometry:
    """Shared behaviour of scan geometries (dataclass subclasses)."""

    detector_shape: tuple[int, int]

    @property
    def num_views(self) -> int:
        return len(self._per_view())

    def __len__(self) -> int:
        return self.num_views

    def __getitem__(self, index):
        name = self._per_view_field()
        return type(self)(**{**self._kwargs(), name: _select(getattr(self, name), index)})

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self._kwargs().items())
        return f"{type(self).__name__}({args})"

    def _kwargs(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def _per_view(self) -> tuple:
        return getattr(self, self._per_view_field())

    @staticmethod
    def _per_view_field() -> str:
        return "angles"


@dataclass(frozen=True, eq=True, repr=False)
class ConeBeamGeometry(_ScanGeometry):
    """Circular cone-beam scan (point source, flat detector).

    ``pixel_size`` and ``detector_offset`` are ``(row, col)`` pairs in mm (a single number means
    square pixels); the offset moves the detector centre along ``v`` (rows) and ``u`` (columns).
    """

    source_to_origin: float
    source_to_detector: float
    detector_shape: tuple[int, int]
    pixel_size: tuple[float, float]
    angles: tuple[float, ...]
    detector_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        sod = _finite("source_to_origin", self.source_to_origin, positive=True)
        sdd = _finite("source_to_detector", self.source_to_detector, positive=True)
        if sdd <= sod:
            raise GeometryError(
                f"source_to_detector ({sdd} mm) must exceed source_to_origin ({sod} mm): "
                "the detector sits beyond the rotation axis"
            )
        _set(self, "source_to_origin", sod)
        _set(self, "source_to_detector", sdd)
        _set(self, "detector_shape", _shape("detector_shape", self.detector_shape, 2))
        _set(self, "pixel_size", _pair("pixel_size", self.pixel_size, positive=True))
        _set(self, "angles", _angles(self.angles))
        _set(self, "detector_offset", _pair("detector_offset", self.detector_offset, positive=False))

    @property
    def beam(self) -> str:
        return "cone"

    def to_vec(self) -> "VectorGeometry":
        rows = []
        (pv, pu), (ov, ou) = self.pixel_size, self.detector_offset
        for theta in self.angles:
            r = _rot_z(theta)
            src = r @ (0.0, -self.source_to_origin, 0.0)
            u, v = r @ (pu, 0.0, 0.0), np.array((0.0, 0.0, pv))
            det = r @ (0.0, self.source_to_detector - self.source_to_origin, 0.0)
            det = det + ou * u / pu + ov * v / pv
            rows.append(np.concatenate([src, det, u, v]))
        return VectorGeometry("cone", self.detector_shape, np.array(rows))


@dataclass(frozen=True, eq=True, repr=False)
class ParallelBeamGeometry(_ScanGeometry):
    """Circular parallel-beam scan; rays travel along ``R_z(θ)·(0, 1, 0)``."""

    detector_shape: tuple[int, int]
    pixel_size: tuple[float, float]
    angles: tuple[float, ...]
    detector_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        _set(self, "detector_shape", _shape("detector_shape", self.detector_shape, 2))
        _set(self, "pixel_size", _pair("pixel_size", self.pixel_size, positive=True))
        _set(self, "angles", _angles(self.angles))
        _set(self, "detector_offset", _pair("detector_offset", self.detector_offset, positive=False))

    @property
    def beam(self) -> str:
        return "parallel"

    def to_vec(self) -> "VectorGeometry":
        rows = []
        (pv, pu), (ov, ou) = self.pixel_size, self.detector_offset
        for theta in self.angles:
            r = _rot_z(theta)
            ray = r @ (0.0, 1.0, 0.0)
            u, v = r @ (pu, 0.0, 0.0), np.array((0.0, 0.0, pv))
            det = ou * u / pu + ov * v / pv
            rows.append(np.concatenate([ray, det, u, v]))
        return VectorGeometry("parallel", self.detector_shape, np.array(rows))


@dataclass(frozen=True, eq=True, repr=False)
class VectorGeometry(_ScanGeometry):
    """Arbitrary per-view geometry: ``vectors`` has one row ``(s|r, d, u, v)`` of 12 numbers per view.

    ``beam="cone"``: ``s`` is the source point. ``beam="parallel"``: ``r`` is the ray direction.
    ``d`` is the detector centre, ``u``/``v`` the vectors from one pixel to the next along a
    row (column index) and a column (row index). Same layout as ASTRA's cone_vec/parallel3d_vec.
    """

    beam: str
    detector_shape: tuple[int, int]
    vectors: tuple[tuple[float, ...], ...]

    def __post_init__(self):
        check_choice(self.beam, BEAMS, "beam", GeometryError)
        _set(self, "detector_shape", _shape("detector_shape", self.detector_shape, 2))
        vec = np.asarray(self.vectors, dtype=np.float64)
        if vec.ndim == 1 and vec.size == 12:
            vec = vec[None]
        if vec.ndim != 2 or vec.shape[1] != 12 or vec.shape[0] == 0:
            raise GeometryError(f"vectors must have shape (num_views, 12), got {vec.shape}")
        if not np.all(np.isfinite(vec)):
            raise GeometryError("vectors must be finite")
        s, d, u, v = vec[:, 0:3], vec[:, 3:6], vec[:, 6:9], vec[:, 9:12]
        normal = np.cross(u, v)
        if np.any(np.linalg.norm(normal, axis=1) <= 1e-12 * np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1)):
            raise GeometryError("vectors: detector u and v must be non-zero and not parallel")
        if self.beam == "cone":
            # Relative tolerance: a source in the plane up to rounding is still in the plane.
            height = np.einsum("ij,ij->i", normal, d - s) / np.linalg.norm(normal, axis=1)
            if np.any(np.abs(height) <= 1e-9 * np.linalg.norm(d - s, axis=1)):
                raise GeometryError("vectors: the source lies in the detector plane")
        elif np.any(np.abs(np.einsum("ij,ij->i", normal, s)) <= 1e-9 * np.linalg.norm(s, axis=1) * np.linalg.norm(normal, axis=1)):
            raise GeometryError("vectors: the ray direction is parallel to the detector plane")
        _set(self, "vectors", tuple(tuple(float(x) for x in row) for row in vec))

    @staticmethod
    def _per_view_field() -> str:
        return "vectors"

    @property
    def array(self) -> np.ndarray:
        """The vectors as a float64 ``(num_views, 12)`` array."""
        return np.array(self.vectors, dtype=np.float64)

    def to_vec(self) -> "VectorGeometry":
        return self


@dataclass(frozen=True, eq=True, repr=False)
class VolumeGeometry:
    """A voxel grid in the scanner frame: ``shape`` (z, y, x), ``voxel_size`` mm, ``offset`` mm.

    Voxel centres along each axis are ``(index − (n − 1)/2)·voxel_size + offset``.
    """

    shape: tuple[int, int, int]
    voxel_size: tuple[float, float, float]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        _set(self, "shape", _shape("shape", self.shape, 3))
        vs = self.voxel_size
        if np.ndim(vs) == 0:
            vs = (vs,) * 3
        if len(vs) != 3:
            raise GeometryError(f"voxel_size must be a number or a (z, y, x) triple, got {vs!r}")
        _set(self, "voxel_size", tuple(_finite(f"voxel_size[{i}]", x, positive=True) for i, x in enumerate(vs)))
        if len(self.offset) != 3:
            raise GeometryError(f"offset must be a (z, y, x) triple in mm, got {self.offset!r}")
        _set(self, "offset", tuple(_finite(f"offset[{i}]", x) for i, x in enumerate(self.offset)))

    def __repr__(self) -> str:
        return f"VolumeGeometry(shape={self.shape!r}, voxel_size={self.voxel_size!r}, offset={self.offset!r})"

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


def _set(obj, name: str, value) -> None:
    object.__setattr__(obj, name, value)


def as_vector_geometry(geometry) -> VectorGeometry:
    """Any scan geometry in its per-view vector form."""
    if not isinstance(geometry, (ConeBeamGeometry, ParallelBeamGeometry, VectorGeometry)):
        raise GeometryError(f"expected a scan geometry, got {type(geometry).__name__}")
    return geometry.to_vec()


def detector_pixel_centres(vec: VectorGeometry, view: int) -> np.ndarray:
    """Float64 ``(rows, cols, 3)`` pixel-centre positions (mm) of one view; a test reference."""
    s, d, u, v = np.split(vec.array[view], 4)
    nr, nc = vec.detector_shape
    r = np.arange(nr) - (nr - 1) / 2
    c = np.arange(nc) - (nc - 1) / 2
    return d + r[:, None, None] * v + c[None, :, None] * u

