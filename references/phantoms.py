"""Analytic ellipsoid phantoms: an independent float64 NumPy reference for reconstruction tests.

Nothing here uses xrayraster's renderer or reconstruction; only :mod:`xrayraster.core.geometry` is
read, for its documented conventions (mm, radians, rotation axis z, pixel centres, (z, y, x)
volumes). Line integrals come from exact chord lengths, ground-truth volumes from point tests,
so a reconstruction compared with these is compared with the mathematics, not with itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from xrayraster.core.geometry import as_vector_geometry, detector_pixel_centres
from xrayraster.core.volume import VolumeGeometry

__all__ = [
    "Ellipsoid",
    "RTK_SHEPP_LOGAN",
    "SHEPP_LOGAN_3D",
    "chord_lengths",
    "from_phantom3d_row",
    "project",
    "rtk_shepp_logan",
    "shepp_logan_3d",
    "sphere",
    "voxel_values",
]


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rx(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


@dataclass(frozen=True)
class Ellipsoid:
    """A solid ellipsoid of constant attenuation; overlapping ellipsoids add (Shepp–Logan style).

    ``centre`` (x, y, z) mm; ``semi_axes`` (a, b, c) mm along the ellipsoid's own axes; ``mu``
    in mm⁻¹. Orientation: the axes are turned by ``rotation = R_z(phi)·R_x(theta)·R_z(psi)``
    (radians, active, z-x-z Euler angles), i.e. the columns of :attr:`rotation` are the a, b, c
    axes in the scanner frame. With ``theta = psi = 0`` this is simply a turn by ``phi`` about
    z, counter-clockwise seen from +z.
    """

    centre: tuple[float, float, float]
    semi_axes: tuple[float, float, float]
    phi: float = 0.0
    mu: float = 1.0
    theta: float = 0.0
    psi: float = 0.0

    def __post_init__(self):
        centre = tuple(float(x) for x in self.centre)
        axes = tuple(float(x) for x in self.semi_axes)
        if len(centre) != 3 or len(axes) != 3:
            raise ValueError("centre and semi_axes must each have 3 entries (mm)")
        if not all(a > 0 and math.isfinite(a) for a in axes):
            raise ValueError(f"semi_axes must be finite and > 0 mm, got {axes}")
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "semi_axes", axes)

    @property
    def rotation(self) -> np.ndarray:
        """3×3 float64 matrix whose columns are the a, b, c axis directions (scanner frame)."""
        return _rz(self.phi) @ _rx(self.theta) @ _rz(self.psi)

    @property
    def volume(self) -> float:
        """Volume in mm³."""
        a, b, c = self.semi_axes
        return 4.0 / 3.0 * math.pi * a * b * c

    def _to_unit_frame(self, points: np.ndarray) -> np.ndarray:
        """Points (..., 3) mm -> coordinates in which this ellipsoid is the unit ball."""
        # Row-vector form of R^T (p - c): project onto each ellipsoid axis, then scale.
        return ((points - np.asarray(self.centre)) @ self.rotation) / np.asarray(self.semi_axes)


def sphere(radius: float, mu: float, centre=(0.0, 0.0, 0.0)) -> Ellipsoid:
    """A ball of ``radius`` mm and attenuation ``mu`` mm⁻¹ centred at ``centre`` (x, y, z) mm."""
    return Ellipsoid(centre=tuple(centre), semi_axes=(radius, radius, radius), mu=mu)


def chord_lengths(ellipsoid: Ellipsoid, origins, directions) -> np.ndarray:
    """Exact length (mm) of the intersection of each full line ``o + t·d`` with ``ellipsoid``.

    ``origins`` and ``directions`` are broadcastable ``(..., 3)`` arrays in mm; directions need
    not be unit length (the result does not depend on their length) but must be non-zero.
    Returns a float64 array of the broadcast shape without the last axis; 0 for a miss.
    """
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    q0 = ellipsoid._to_unit_frame(o)
    e = (d @ ellipsoid.rotation) / np.asarray(ellipsoid.semi_axes)  # direction, unit-ball frame
    # Roots of |q0 + t e|^2 = 1 satisfy t2 - t1 = 2 sqrt(disc)/A with A = e·e and
    # disc/A = 1 - |q0⊥|^2, q0⊥ the part of q0 normal to e. Using q0⊥ directly instead of
    # B² − A·C avoids the cancellation when the origin (a cone-beam source) is far away.
    e_sq = np.einsum("...i,...i->...", e, e)
    along = np.einsum("...i,...i->...", q0, e) / e_sq
    q_perp = q0 - along[..., None] * e
    half_sq = np.clip(1.0 - np.einsum("...i,...i->...", q_perp, q_perp), 0.0, None)
    d_len = np.sqrt(np.einsum("...i,...i->...", d, d))
    return 2.0 * np.sqrt(half_sq) * d_len / np.sqrt(e_sq)


def _sub_offsets(k: int) -> np.ndarray:
    """Centres of k equal sub-intervals of a unit-length cell, relative to its centre."""
    if int(k) != k or k < 1:
        raise ValueError(f"supersample must be a positive integer, got {k!r}")
    return (np.arange(int(k)) + 0.5) / k - 0.5


def project(ellipsoids: Iterable[Ellipsoid], geometry, supersample: int = 1) -> np.ndarray:
    """Float64 line integrals ``Σ mu·chord`` (dimensionless), shape (views, rows, cols).

    ``geometry`` is any scan geometry (cone, parallel or vector). Cone beam: the line from the
    source point ``s`` through each pixel centre. Parallel beam: the line through each pixel
    centre along ``r``. Whole lines are used, so the ellipsoids must lie between source and
    detector (cone) as in any real scan. ``supersample = k`` averages k×k lines per pixel
    through sub-pixel centres spread evenly over the pixel's area (spanned by ``u`` and ``v``),
    modelling a detector element's finite area instead of its centre point.
    """
    ellipsoids = list(ellipsoids)
    vec = as_vector_geometry(geometry)
    offsets = _sub_offsets(supersample)
    out = np.zeros((vec.num_views, *vec.detector_shape), dtype=np.float64)
    for view in range(vec.num_views):
        s, _, u, v = np.split(vec.array[view], 4)
        centres = detector_pixel_centres(vec, view)
        for dv in offsets:
            for du in offsets:
                points = centres + du * u + dv * v
                if vec.beam == "cone":
                    origins, directions = s, points - s
                else:
                    origins, directions = points, s
                for e in ellipsoids:
                    out[view] += e.mu * chord_lengths(e, origins, directions)
    return out / len(offsets) ** 2


def voxel_values(ellipsoids: Iterable[Ellipsoid], volume_geometry: VolumeGeometry, supersample: int = 1) -> np.ndarray:
    """Float64 (z, y, x) ground truth in mm⁻¹: ``Σ mu`` over ellipsoids containing each voxel centre.

    A point on an ellipsoid's surface counts as inside (as in Schabel's phantom3d).
    ``supersample = k`` returns instead the mean over k³ points at the centres of the k³ equal
    sub-voxels, an approximation of the voxel's mean attenuation (partial-volume effect).
    """
    ellipsoids = list(ellipsoids)
    g = volume_geometry
    z, y, x = (g.axis_centres(axis) for axis in range(3))
    offsets = _sub_offsets(supersample)
    out = np.zeros(g.shape, dtype=np.float64)
    for oz in offsets:
        for oy in offsets:
            for ox in offsets:
                # (z, y, x)-shaped grid of (x, y, z) points, broadcast rather than materialised.
                pz = (z + oz * g.voxel_size[0])[:, None, None]
                py = (y + oy * g.voxel_size[1])[None, :, None]
                px = (x + ox * g.voxel_size[2])[None, None, :]
                for e in ellipsoids:
                    r, c, a = e.rotation, np.asarray(e.centre), np.asarray(e.semi_axes)
                    q_sq = 0.0
                    for i in range(3):  # coordinate along ellipsoid axis i, in semi-axis units
                        qi = ((px - c[0]) * r[0, i] + (py - c[1]) * r[1, i] + (pz - c[2]) * r[2, i]) / a[i]
                        q_sq = q_sq + qi * qi
                    out += e.mu * (q_sq <= 1.0)
    return out / len(offsets) ** 3


# --- 3-D Shepp–Logan ------------------------------------------------------------------------
#
# "Modified Shepp-Logan" table of M. C. Schabel's phantom3d.m (MATLAB File Exchange 9416, 2005;
# "Taken from Toft, 199-200"), read from the copy in CERN/TIGRE Utilities/phantom3dAniso.m and
# cross-checked with tsadakane/sl3d's `toft_schabel` table. Normalised coordinates in [-1, 1];
# angles in degrees.
#
#        A      a      b      c      x0      y0     z0    phi  theta  psi
_PHANTOM3D_MODIFIED_SHEPP_LOGAN = (
    (1.0, 0.6900, 0.920, 0.810, 0.00, 0.0000, 0.00, 0.0, 0.0, 0.0),
    (-0.8, 0.6624, 0.874, 0.780, 0.00, -0.0184, 0.00, 0.0, 0.0, 0.0),
    (-0.2, 0.1100, 0.310, 0.220, 0.22, 0.0000, 0.00, -18.0, 0.0, 10.0),
    (-0.2, 0.1600, 0.410, 0.280, -0.22, 0.0000, 0.00, 18.0, 0.0, 10.0),
    (0.1, 0.2100, 0.250, 0.410, 0.00, 0.3500, -0.15, 0.0, 0.0, 0.0),
    (0.1, 0.0460, 0.046, 0.050, 0.00, 0.1000, 0.25, 0.0, 0.0, 0.0),
    (0.1, 0.0460, 0.046, 0.050, 0.00, -0.1000, 0.25, 0.0, 0.0, 0.0),
    (0.1, 0.0460, 0.023, 0.050, -0.08, -0.6050, 0.00, 0.0, 0.0, 0.0),
    (0.1, 0.0230, 0.023, 0.020, 0.00, -0.6060, 0.00, 0.0, 0.0, 0.0),
    (0.1, 0.0230, 0.046, 0.020, 0.06, -0.6050, 0.00, 0.0, 0.0, 0.0),
)


def from_phantom3d_row(row) -> Ellipsoid:
    """Convert one phantom3d row ``(A, a, b, c, x0, y0, z0, phi, theta, psi)`` (degrees) exactly.

    phantom3d tests a point p with ``q = α·p`` and ``Σ((q − (x0, y0, z0))/(a, b, c))² ≤ 1``,
    where α is the passive z-x-z Euler matrix, ``α = R_z(ψ)ᵀ·R_x(θ)ᵀ·R_z(φ)ᵀ``. Hence the
    ellipsoid's axes are the columns of ``αᵀ = R_z(φ)·R_x(θ)·R_z(ψ)`` (our ``rotation`` with the
    same three angles in radians) and — a quirk of phantom3d, which subtracts the centre *after*
    rotating — its centre in space is ``αᵀ·(x0, y0, z0)``, not ``(x0, y0, z0)``. For the modified
    Shepp–Logan table θ = 0, so each ellipsoid is turned by φ + ψ about z: the two ventricles by
    −8° and +28°, centred at ``R_z(−8°)·(0.22, 0, 0)`` and ``R_z(28°)·(−0.22, 0, 0)``. We keep
    that quirk so our volume matches what phantom3d (and TIGRE, sl3d) actually produce.
    """
    mu, a, b, c, x0, y0, z0, phi, theta, psi = (float(x) for x in row)
    e = Ellipsoid((0.0, 0.0, 0.0), (a, b, c), math.radians(phi), mu, math.radians(theta), math.radians(psi))
    centre = e.rotation @ np.array([x0, y0, z0])
    return Ellipsoid(tuple(centre), (a, b, c), e.phi, mu, e.theta, e.psi)


#: The 10-ellipsoid modified 3-D Shepp–Logan phantom (values 1, −0.8, −0.2, −0.2, 0.1 × 6) in
#: normalised coordinates: the head fills [−1, 1] (outer ellipsoid semi-axes 0.69, 0.92, 0.81).
SHEPP_LOGAN_3D: tuple[Ellipsoid, ...] = tuple(from_phantom3d_row(r) for r in _PHANTOM3D_MODIFIED_SHEPP_LOGAN)


def shepp_logan_3d(radius_mm: float, mu_scale_per_mm: float) -> list[Ellipsoid]:
    """:data:`SHEPP_LOGAN_3D` scaled so normalised coordinate 1 is ``radius_mm`` mm from the
    origin and a table value of 1 is ``mu_scale_per_mm`` mm⁻¹ (the head's centre is then 0.2×)."""
    r, k = float(radius_mm), float(mu_scale_per_mm)
    return [
        Ellipsoid(
            tuple(r * x for x in e.centre), tuple(r * x for x in e.semi_axes), e.phi, k * e.mu, e.theta, e.psi
        )
        for e in SHEPP_LOGAN_3D
    ]


# --- RTK's Shepp–Logan ----------------------------------------------------------------------
#
# The table of RTK's rtk::SheppLoganPhantom (src/rtkSheppLoganPhantom.cxx, RTK 2.x): the original
# Shepp–Logan densities (2, −0.98, −0.02, …), which RTK's functional tests (rtkfdktest,
# rtkdisplaceddetectortest) reconstruct and score with their thresholds (error per pixel < 0.061,
# PSNR > 24 dB with peak 2). RTK's frame has the rotation axis along its y; ours along z:
#   ours (x, y, z) = (x_RTK, −z_RTK, y_RTK),
# a proper rotation, so RTK's angle about its y becomes a turn about our z; RTK turns the other
# way (angle → −angle here). Drawn on RTK's 128³ test grid of 2 mm voxels, these ellipsoids gave
# every voxel of RTK's DrawSheppLoganFilter (checked once against itk-rtk 2.7, to 6e-8).
#
#     semi-axes (x, y, z)_RTK     centre (x, y, z)_RTK     angle (deg)  density
_RTK_TABLE = (
    ((0.69, 0.90, 0.92), (0.0, 0.0, 0.0), 0.0, 2.0),
    ((0.6624, 0.880, 0.874), (0.0, 0.0, 0.0), 0.0, -0.98),
    ((0.41, 0.21, 0.16), (-0.22, -0.25, 0.0), 108.0, -0.02),
    ((0.31, 0.22, 0.11), (0.22, -0.25, 0.0), 72.0, -0.02),
    ((0.21, 0.50, 0.25), (0.0, -0.25, 0.35), 0.0, 0.02),
    ((0.046, 0.046, 0.046), (0.0, -0.25, 0.10), 0.0, 0.02),
    ((0.046, 0.02, 0.023), (-0.08, -0.25, -0.65), 0.0, 0.01),
    ((0.046, 0.02, 0.023), (0.06, -0.25, -0.65), 90.0, 0.01),
    ((0.056, 0.1, 0.04), (0.06, 0.625, -0.105), 90.0, 0.02),
    ((0.056, 0.1, 0.056), (0.0, 0.625, 0.1), 0.0, -0.02),
)

#: RTK's 10-ellipsoid Shepp–Logan in normalised coordinates, our frame (densities 2 at the skull,
#: 1.02 in the brain); :func:`rtk_shepp_logan` scales it as RTK's ``PhantomScale`` does.
RTK_SHEPP_LOGAN: tuple[Ellipsoid, ...] = tuple(
    Ellipsoid((cx, -cz, cy), (ax, az, ay), -math.radians(angle), density)
    for (ax, ay, az), (cx, cy, cz), angle, density in _RTK_TABLE
)


def rtk_shepp_logan(scale_mm: float = 128.0) -> list[Ellipsoid]:
    """:data:`RTK_SHEPP_LOGAN` with lengths × ``scale_mm`` (RTK's default scale, 128 mm) and its
    densities as μ in mm⁻¹, as RTK's tests use them."""
    k = float(scale_mm)
    return [Ellipsoid(tuple(k * x for x in e.centre), tuple(k * x for x in e.semi_axes), e.phi, e.mu)
            for e in RTK_SHEPP_LOGAN]
