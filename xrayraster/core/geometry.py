"""Scan geometry: the one module that defines xrayraster's frames and units (the voxel grid is
:mod:`xrayraster.core.volume`).

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
  one pixel long and ``d`` is the detector centre (moved by ``detector_offset``). A cone beam's
  ``source_offset`` moves the source alike, along ``u`` and ``v`` in its own plane, the detector
  staying where it is (RTK's ``SourceOffsetX/Y``).
* Vector form (:class:`VectorGeometry`): one row of 12 numbers per view, ``(s, d, u, v)`` for a
  cone beam (source point) and ``(r, d, u, v)`` for a parallel beam (ray direction), exactly as
  ASTRA's ``cone_vec`` / ``parallel3d_vec``. Any scanner, tilted or misaligned, is a vector
  geometry; the circular geometries convert to it with :meth:`to_vec`.
* Volumes are C-ordered ``(z, y, x)``. Voxel ``(k, j, i)`` has its centre at
  ``(index − (n − 1)/2)·voxel_size + offset`` along each axis, so with no offset the scanner
  origin is the centre of the voxel grid.

All geometry objects are small immutable values: ``eval(repr(g)) == g``, ``g[views]`` selects a
subset of views, and construction validates every field with an error that names it.

Dict form
---------
``g.to_dict()`` and ``type(g).from_dict(d)`` (or :func:`geometry_from_dict` for any kind) use one
key set, the one of TOML scene files, JSON grid files and TIFF metadata; lengths mm, angles in
degrees as in every config:

* scan geometries: ``beam`` (``"cone"``, the default, or ``"parallel"``), ``detector_shape``
  ``[rows, cols]`` (or one number), ``pixel_size`` ``[row, col]`` mm (or one), optional
  ``detector_offset`` ``[row, col]`` mm; cone beams add ``source_to_origin`` and
  ``source_to_detector``, and optionally ``source_offset`` ``[row, col]`` mm. Views: ``angles_deg``
  (a list), or ``num_views`` (default 1) equally spaced over ``arc_deg`` (default 360) from
  ``start_angle_deg`` (default 0), end point excluded.
* vector geometries: ``beam``, ``detector_shape`` and ``vectors`` (one row of 12 numbers a view).
* volumes: ``shape`` ``[z, y, x]``, ``voxel_size`` (one number or ``[z, y, x]``), optional ``offset``.

``to_dict`` writes a circular scan's views as ``num_views`` (and ``start_angle_deg``) when they
are exactly :func:`circular_arc`'s, which round-trips to the bit; other angle lists go out as
``angles_deg`` and come back within one or two float64 ulps (degrees to radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from functools import cached_property

import numpy as np

from . import fields
from .choices import BEAMS, check_choice
from .errors import ConfigError, GeometryError
from .memory import check_fits
from .validate import finite, pair, positive_ints, set_field

__all__ = [
    "ConeBeamGeometry",
    "ParallelBeamGeometry",
    "VectorGeometry",
    "full_circle",
]


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


#: Bytes a scan holds per view for its geometry, measured at 10⁶ views (Python 3.11): the angles
#: (41 B, and 40 B more while they are checked), the vector form's tuples (875 B) and its array
#: (96 B), 1.18 KB in all; rounded up for the per-view lists a scan's provenance keeps.
BYTES_PER_VIEW = 1500


def check_view_count(num_views: int, what: str = "num_views", error: type[Exception] = GeometryError) -> None:
    """Refuse ``num_views`` whose per-view geometry alone cannot fit in memory, before any view is made."""
    check_fits(num_views * BYTES_PER_VIEW, f"{what} = {num_views} ({BYTES_PER_VIEW} bytes a view for the geometry)",
               "use fewer views", error)


def circular_arc(num_views: int, start: float = 0.0, arc: float = 2 * math.pi) -> tuple[float, ...]:
    """``num_views`` equally spaced angles (radians) over ``arc`` from ``start``, end point excluded;
    refused (GeometryError) when their geometry cannot fit in memory."""
    n = positive_ints("num_views", num_views, 1)[0]
    check_view_count(n)
    return _arc(n, start, arc)


def _arc(n: int, start: float, arc: float) -> tuple[float, ...]:
    """:func:`circular_arc` without its checks: for angles that exist already (``to_dict``), which a
    memory check must not refuse at the end of a long scan."""
    return tuple(float(start + arc * k / n) for k in range(n))


def full_circle(num_views: int, start: float = 0.0) -> tuple[float, ...]:
    """``num_views`` equally spaced angles (radians) over 2π, end point excluded."""
    return circular_arc(num_views, start)


def _turned_detector(angles, pixel_size) -> tuple[np.ndarray, ...]:
    """cos θ and sin θ per view, and the detector's ``u`` = R_z(θ)·(pixel_col, 0, 0) and
    ``v`` = (0, 0, pixel_row) rows: every view at once, as the rotation R_z(θ) writes them out."""
    # math's cos and sin (the C library's), not numpy's vectorised ones, which may differ by an ulp:
    # the vectors stay bit for bit those of one R_z(θ) per view.
    c = np.fromiter(map(math.cos, angles), np.float64, len(angles))
    s = np.fromiter(map(math.sin, angles), np.float64, len(angles))
    pv, pu = pixel_size
    zero = np.zeros_like(c)
    return c, s, np.column_stack([c * pu, s * pu, zero]), np.column_stack([zero, zero, np.full_like(c, pv)])


def _offset(points: np.ndarray, u: np.ndarray, v: np.ndarray, pixel_size, offset) -> np.ndarray:
    """Detector centres or sources moved by ``offset`` (row, col mm) along ``v`` and ``u``."""
    (pv, pu), (ov, ou) = pixel_size, offset
    return points + ou * u / pu + ov * v / pv


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
        return {f.name: getattr(self, f.name) for f in dataclass_fields(self)}

    def to_dict(self) -> dict:
        """The dict form (module docstring): JSON and TOML ready."""
        out = {"beam": self.beam}
        for name, value in self._kwargs().items():
            if name != "angles":
                out[name] = list(value) if isinstance(value, tuple) else value
        out.update(_angles_to_dict(self.angles))
        return out

    @classmethod
    def from_dict(cls, d: dict, where: str = "geometry"):
        """A geometry of this class from its dict form; errors name ``where`` and the field."""
        geometry = geometry_from_dict(d, where)
        if not isinstance(geometry, cls):
            raise ConfigError(f"{where}: describes a {type(geometry).__name__}, not a {cls.__name__}")
        return geometry

    def _check_circular_fields(self) -> None:
        """The fields cone and parallel scans share, checked and stored in canonical form."""
        set_field(self, "detector_shape", positive_ints("detector_shape", self.detector_shape, 2))
        set_field(self, "pixel_size", pair("pixel_size", self.pixel_size, positive=True))
        set_field(self, "angles", _angles(self.angles))
        set_field(self, "detector_offset", pair("detector_offset", self.detector_offset, positive=False))

    def to_vec(self) -> "VectorGeometry":
        """The per-view vector form (:class:`VectorGeometry`), made once per geometry: the renderer
        and the reconstruction of one scan share it."""
        return self._vectors

    def _per_view(self) -> tuple:
        return getattr(self, self._per_view_field())

    @staticmethod
    def _per_view_field() -> str:
        return "angles"


@dataclass(frozen=True, eq=True, repr=False)
class ConeBeamGeometry(_ScanGeometry):
    """Circular cone-beam scan (point source, flat detector).

    ``pixel_size``, ``detector_offset`` and ``source_offset`` are ``(row, col)`` pairs in mm (a
    single number means square pixels); the detector offset moves the detector centre along ``v``
    (rows) and ``u`` (columns), the source offset the source along the same directions, in the plane
    ``source_to_detector`` away from the detector's (as RTK's ``SourceOffsetY/X``).
    """

    source_to_origin: float
    source_to_detector: float
    detector_shape: tuple[int, int]
    pixel_size: tuple[float, float]
    angles: tuple[float, ...]
    detector_offset: tuple[float, float] = (0.0, 0.0)
    source_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        sod = finite("source_to_origin", self.source_to_origin, positive=True)
        sdd = finite("source_to_detector", self.source_to_detector, positive=True)
        if sdd <= sod:
            raise GeometryError(
                f"source_to_detector ({sdd} mm) must exceed source_to_origin ({sod} mm): "
                "the detector sits beyond the rotation axis"
            )
        set_field(self, "source_to_origin", sod)
        set_field(self, "source_to_detector", sdd)
        self._check_circular_fields()
        set_field(self, "source_offset", pair("source_offset", self.source_offset, positive=False))

    @property
    def beam(self) -> str:
        return "cone"

    @classmethod
    def framing(cls, radius: float, half_height: float, *, num_views: int = 360, magnification: float = 2.0,
                columns: int = 256) -> "ConeBeamGeometry":
        """A full-circle scan whose detector just sees a sample from every angle.

        The sample is anything inside the cylinder of ``radius`` (mm) about the rotation axis and
        ``half_height`` (mm) above and below the origin. The source sits at five radii (a cone
        angle of about 23°, usual for micro-CT), the detector at ``magnification`` times that from
        the source, and ``columns`` square pixels span the cylinder's shadow with a 2 % margin;
        the rows cover the shadow of its near rim (the tallest), with the same margin.
        """
        r = finite("radius", radius, positive=True)
        h = finite("half_height", half_height, positive=True)
        m = finite("magnification", magnification, positive=True)
        if m <= 1.0:
            raise GeometryError(f"magnification must exceed 1 (the detector lies beyond the axis), got {m}")
        n = positive_ints("columns", columns, 1)[0]
        sod = 5.0 * r
        sdd = m * sod
        half_u = sdd * r / math.sqrt(sod * sod - r * r)   # the cylinder's tangent rays
        half_v = sdd * h / (sod - r)                     # its near rim's top and bottom
        pixel = 2.04 * half_u / n
        rows = math.ceil(2.04 * half_v / pixel)
        return cls(sod, sdd, (rows, n), pixel, full_circle(num_views))

    @cached_property
    def _vectors(self) -> "VectorGeometry":
        c, s, u, v = _turned_detector(self.angles, self.pixel_size)
        src = _offset(np.column_stack([s * self.source_to_origin, -c * self.source_to_origin, np.zeros_like(c)]),
                      u, v, self.pixel_size, self.source_offset)
        gap = self.source_to_detector - self.source_to_origin
        det = _offset(np.column_stack([-s * gap, c * gap, np.zeros_like(c)]), u, v, self.pixel_size, self.detector_offset)
        return VectorGeometry("cone", self.detector_shape, np.hstack([src, det, u, v]))


@dataclass(frozen=True, eq=True, repr=False)
class ParallelBeamGeometry(_ScanGeometry):
    """Circular parallel-beam scan; rays travel along ``R_z(θ)·(0, 1, 0)``."""

    detector_shape: tuple[int, int]
    pixel_size: tuple[float, float]
    angles: tuple[float, ...]
    detector_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        self._check_circular_fields()

    @property
    def beam(self) -> str:
        return "parallel"

    @cached_property
    def _vectors(self) -> "VectorGeometry":
        c, s, u, v = _turned_detector(self.angles, self.pixel_size)
        ray = np.column_stack([-s, c, np.zeros_like(c)])
        det = _offset(np.zeros_like(u), u, v, self.pixel_size, self.detector_offset)
        return VectorGeometry("parallel", self.detector_shape, np.hstack([ray, det, u, v]))


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
        set_field(self, "detector_shape", positive_ints("detector_shape", self.detector_shape, 2))
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
        set_field(self, "vectors", tuple(map(tuple, vec.tolist())))

    @staticmethod
    def _per_view_field() -> str:
        return "vectors"

    @cached_property
    def array(self) -> np.ndarray:
        """The vectors as a read-only float64 ``(num_views, 12)`` array, made once per geometry:
        renderers read one view's row per call, and rebuilding every row each time made a scan's
        time grow with the square of its views. Not a field, so equality and ``repr`` ignore it."""
        array = np.array(self.vectors, dtype=np.float64)
        array.flags.writeable = False
        return array

    def to_vec(self) -> "VectorGeometry":
        return self

    def to_dict(self) -> dict:
        return {"beam": self.beam, "detector_shape": list(self.detector_shape), "vectors": [list(row) for row in self.vectors]}


def as_vector_geometry(geometry) -> VectorGeometry:
    """Any scan geometry in its per-view vector form."""
    if not isinstance(geometry, (ConeBeamGeometry, ParallelBeamGeometry, VectorGeometry)):
        raise GeometryError(f"expected a scan geometry, got {type(geometry).__name__}")
    return geometry.to_vec()


def detector_pixel_centres(vec: VectorGeometry, view: int) -> np.ndarray:
    """Float64 ``(rows, cols, 3)`` pixel-centre positions (mm) of one view: the detector convention written out."""
    s, d, u, v = np.split(vec.array[view], 4)
    nr, nc = vec.detector_shape
    r = np.arange(nr) - (nr - 1) / 2
    c = np.arange(nc) - (nc - 1) / 2
    return d + r[:, None, None] * v + c[None, :, None] * u



# ----------------------------------------------------------------------------- dict form


def geometry_from_dict(d: dict, where: str = "geometry"):
    """The scan geometry a dict describes (module docstring); errors name ``where`` and the field."""
    d = fields.mapping(d, where)
    beam = d.get("beam", "cone")
    if beam not in BEAMS:
        raise ConfigError(f"{where}: beam must be 'cone' or 'parallel', got {beam!r}")
    shape = fields.one_or_pair(fields.required(d, "detector_shape", where), "detector_shape", where,
                               "an integer or [rows, cols]", element=fields.integer, lo=1)
    if "vectors" in d:
        fields.only(d, {"beam", "detector_shape", "vectors"}, where)
        rows = d["vectors"]
        if not isinstance(rows, list) or not rows or not all(isinstance(r, list) for r in rows):
            raise ConfigError(f"{where}: vectors must be a list of rows of 12 numbers, one a view, got {rows!r:.80}")
        vectors = [fields.vector(r, f"vectors[{i}]", where, 12, "12 numbers (s|r, d, u, v)") for i, r in enumerate(rows)]
        return fields.construct(VectorGeometry, where, beam=beam, detector_shape=shape, vectors=vectors)
    if beam == "parallel":
        for key in sorted({"source_to_origin", "source_to_detector"} & set(d)):
            raise ConfigError(f"{where}: '{key}' has no meaning for beam = 'parallel' (there is no source point); "
                              "drop it, or set beam = 'cone'")
    fields.only(d, SCAN_KEYS[beam], where)
    common = dict(
        detector_shape=shape,
        pixel_size=fields.one_or_pair(fields.required(d, "pixel_size", where), "pixel_size", where,
                                      "a number or [row, col] in mm", positive=True),
        angles=_angles_from_dict(d, where),
        detector_offset=fields.one_or_pair(d.get("detector_offset", 0.0), "detector_offset", where,
                                           "a number or [row, col] in mm"),
    )
    if beam == "parallel":
        return fields.construct(ParallelBeamGeometry, where, **common)
    return fields.construct(
        ConeBeamGeometry, where,
        source_to_origin=fields.number(fields.required(d, "source_to_origin", where), "source_to_origin", where, positive=True),
        source_to_detector=fields.number(fields.required(d, "source_to_detector", where), "source_to_detector", where,
                                         positive=True),
        source_offset=fields.one_or_pair(d.get("source_offset", 0.0), "source_offset", where, "a number or [row, col] in mm"),
        **common,
    )


_ANGLE_KEYS = {"angles_deg", "num_views", "start_angle_deg", "arc_deg"}
_CIRCULAR_KEYS = {"beam", "detector_shape", "pixel_size", "detector_offset", *_ANGLE_KEYS}
#: The keys of a circular scan's geometry table, by beam.
SCAN_KEYS = {"parallel": _CIRCULAR_KEYS,
             "cone": {*_CIRCULAR_KEYS, "source_to_origin", "source_to_detector", "source_offset"}}


def _angles_from_dict(d: dict, where: str) -> tuple[float, ...]:
    if "angles_deg" in d:
        if "num_views" in d:
            raise ConfigError(f"{where}: give either 'num_views' (full circle) or 'angles_deg', not both")
        for key in sorted({"start_angle_deg", "arc_deg"} & set(d)):
            raise ConfigError(f"{where}: '{key}' only applies to 'num_views', not to 'angles_deg'; "
                              f"drop '{key}' and add it to the angles in 'angles_deg'")
        degrees = fields.vector(d["angles_deg"], "angles_deg", where, None, "a non-empty array of angles in degrees")
        return tuple(math.radians(a) for a in degrees)
    start = fields.number(d.get("start_angle_deg", 0.0), "start_angle_deg", where)
    arc = fields.number(d.get("arc_deg", 360.0), "arc_deg", where, positive=True)
    count = fields.integer(d.get("num_views", 1), "num_views", where, 1)
    check_view_count(count, f"{where}: num_views", ConfigError)
    return circular_arc(count, math.radians(start), 2 * math.pi if arc == 360.0 else math.radians(arc))


def _angles_to_dict(angles: tuple[float, ...]) -> dict:
    """``num_views`` (and ``start_angle_deg``) where that gives back these very angles, else ``angles_deg``."""
    start = math.degrees(angles[0])
    if _arc(len(angles), math.radians(start), 2 * math.pi) == angles:
        return {"num_views": len(angles)} | ({"start_angle_deg": start} if start else {})
    return {"angles_deg": [math.degrees(a) for a in angles]}
