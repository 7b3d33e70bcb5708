"""Per-view quantities of filtered backprojection (FDK for cone beams, FBP for parallel beams).

Everything here is plain float64 NumPy, computed once per reconstruction from a scan geometry
(any :class:`~xrayraster.core.geometry.VectorGeometry`, so tilted or misaligned scanners too) and a
:class:`~xrayraster.core.volume.VolumeGeometry`. The OpenCL kernels read these arrays; the float64
reference the tests compare them with (``references/fdk.py``) derives its own from the same
formulas, so a wrong weight here fails those tests.

The algorithm (Feldkamp, Davis & Kress 1984, written for a general flat detector)
----------------------------------------------------------------------------------
For view i with source ``s``, detector centre ``d`` and pixel steps ``u`` (columns), ``v`` (rows):

* ``n`` is the detector normal pointing away from the source, ``D = n·(d − s)`` the source to
  detector-plane distance, ``R`` the source's distance from the rotation axis (z), ``Δθ`` the
  view's angular gap (half the angle between its neighbours).
* Pre-weighting: projection × cosine weight ``ŝ·(p − s) / |p − s|`` (p a pixel centre, ŝ the
  horizontal unit vector from the source towards the axis; 1 for parallel beams) × redundancy
  weight ``W`` (below). For a detector that faces the axis this is the usual ``D / |p − s|``.
  Where the source is offset sideways (or the detector turned about its rows), FDK's change of
  variables from parallel lines to the source's fan measures the rays' angles from the source's
  line to the axis, not from the detector normal; the normal's cosine reconstructs a centred
  sphere (source 100 mm from the axis, 10 mm to the side) 0.52 % low, this one 0.02 % low, as
  RTK's FDK does.
* Ramp filtering along detector rows with pixel pitch ``|u|`` mm (:mod:`xrayraster.recon.ramp_filter`).
* Voxel-driven backprojection: a voxel at x projects to the detector through the 3×4 matrix
  ``P`` of :attr:`FDKViews.matrices`: ``(col·w, row·w, w) = P·(i, j, k, 1)`` in voxel indices,
  where ``w = n·(x − s) / D`` is the voxel's depth relative to the detector (1 for parallel
  beams). It adds ``scale_i / w² · q_i(row, col)`` with bilinear interpolation (zero outside the
  detector), ``scale_i = Δθ·|s| / D`` (cone; ``|s|`` is the source's distance from the origin,
  the isocentre: R unless the source sits above or below it) or ``Δθ`` (parallel).

With the ramp in physical detector units this is FDK's formula on the virtual detector through
the axis: ``f(x) = Σ_i Δθ·(R²/U²)·q_virtual = Σ_i Δθ·(R·D/U²)·q_detector`` with ``U = w·D``,
since the ramp kernel is homogeneous of degree −2.

Redundancy weights (per view and detector column, evaluated on the detector's centre row)
-----------------------------------------------------------------------------------------
A ray is described by its fan angle γ (signed, counter-clockwise about +z from the source's
central ray to the origin; 0 for parallel beams) and its signed distance ``t`` from the axis.
The same line is measured again, reversed, at source angle ``β + π + 2γ`` with fan angle −γ.

* ``full``: the views cover the circle (no angular gap larger than 3× the median gap). Every line
  is measured twice: ``W = ½``, or, for a laterally displaced detector (an extended field of
  view; it sees −Δ ≤ t on one side and beyond Δ on the other), Wang's weights
  ``W = sin²(π/4·(1 + t/Δ))`` for ``|t| ≤ Δ``, 1 beyond (lines measured once), 0 on the short
  side's missing part. ``W(t) + W(−t) = 1`` wherever both are measured. ``displaced="auto"``
  chooses from the lines' actual coverage of the axis (whatever moved them: detector or source
  offsets, a tilt) and from what is reconstructed: ½ when the object lies within the radius Δ
  that every view sees on both sides (every line through it is measured twice, and the lines
  measured once carry nothing, so ½ is exact; Wang's weights would only add their cone-beam
  error, as they favour one of two conjugate rays, which differ off the mid-plane); else Wang's
  when the coverage is off-centre by more than :data:`DISPLACED_SHARE` of its width, else ½.
  The object's reach is the radius about the axis outside which nothing attenuates:
  ``object_radius_mm`` where the caller knows it (``xr.scan``: the sample and its mount), else
  the grid's (the reconstruction is taken to frame the object). The choice is logged; ``displaced=``
  forces either.
* ``short``: a scan over less than the circle. Parker's weights with ``δ = (range − π)/2``,
  β from the start of the arc; the range must be at least π plus the full fan angle.

Angular gaps: views are sorted by angle (any input order); each gets half the angle between its
neighbours (circularly for full scans, one-sided at the ends of a short scan).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ..core.choices import SCAN_KINDS, check_choice, is_switch
from ..core.errors import GeometryError
from ..core.geometry import as_vector_geometry
from ..core.validate import finite
from ..core.volume import VolumeGeometry

log = logging.getLogger(__name__)

# "auto" picks Wang's weights when the coverage of the axis is off-centre by more than this share
# of its width. Measured on RTK's displaced-detector test geometry (docs/reconstruction.md): ½ is
# better up to about 1.6 % (Wang's weights favour one of two conjugate rays, which differ off the
# mid-plane), Wang's beyond (the lines measured once get their full weight). RTK uses 10 %, where
# ½ already costs 0.073 per voxel against Wang's 0.052.
DISPLACED_SHARE = 0.02


@dataclass(frozen=True)
class FDKViews:
    """What the filter and backprojection need, per view (all float64)."""

    beam: str  # "cone" or "parallel"
    detector_shape: tuple[int, int]  # (rows, cols)
    vectors: np.ndarray  # (views, 12): s|r, d, u, v in mm (cosine weights are computed from them)
    depth: np.ndarray  # (views,): D, source to detector plane, mm (1 for parallel beams)
    toward_axis: np.ndarray  # (views, 3): ŝ, the cosine weights' direction (zeros for parallel beams)
    redundancy: np.ndarray  # (views, cols): W of the module docstring
    pixel_pitch: float  # |u|, mm: the ramp filter's sample spacing
    matrices: np.ndarray  # (views, 3, 4): voxel index (i, j, k, 1) -> (col·w, row·w, w)
    scale: np.ndarray  # (views,): Δθ·|s|/D (cone) or Δθ (parallel)
    scan: str  # "full" or "short"
    displaced: bool  # Wang weights applied (full scan, laterally displaced detector)
    # Virtual columns before column 0 and after the last: the filtered rows continue there. A
    # displaced detector's short side cuts the rays that the long side's mirror images measure;
    # the ramp filter's response runs on past that edge, and voxels projecting there need it
    # (without it, a bias of +0.025 on a density of 1 beyond the overlap, measured in float64).
    lead: int = 0
    trail: int = 0

    @property
    def filtered_cols(self) -> int:
        """Columns of a filtered row: the detector's and the virtual ones."""
        return self.lead + self.detector_shape[1] + self.trail


def fdk_views(geometry, volume: VolumeGeometry, scan: str = "auto", displaced="auto",
              object_radius_mm: float | None = None) -> FDKViews:
    """The per-view arrays for reconstructing ``volume`` from ``geometry``; see the module docstring.

    ``scan``: ``"auto"`` (full if the views cover the circle, else short), ``"full"`` or ``"short"``.
    ``displaced``: for full scans, ``"auto"`` (see :func:`full_scan_weights`), ``True`` (Wang's) or
    ``False`` (½). ``object_radius_mm``: the radius about the rotation axis outside which nothing
    attenuates, which ``"auto"`` weighs (None: the grid's, :func:`grid_radius`).
    """
    check_choice(scan, SCAN_KINDS, "scan", GeometryError)
    if not is_switch(displaced):
        raise GeometryError(f"displaced must be 'auto', True or False, got {displaced!r}")
    vec = as_vector_geometry(geometry)
    if not isinstance(volume, VolumeGeometry):
        raise GeometryError(f"volume must be a VolumeGeometry, got {type(volume).__name__}")
    reach = grid_radius(volume) if object_radius_mm is None else finite("object_radius_mm", object_radius_mm,
                                                                        positive=True)
    a = vec.array
    s, d, u, v = a[:, 0:3], a[:, 3:6], a[:, 6:9], a[:, 9:12]
    rows, cols = vec.detector_shape
    pitch = np.linalg.norm(u, axis=1)
    if np.ptp(pitch) > 1e-9 * pitch.max():
        raise GeometryError("vectors: every view must have the same column pitch |u| (one ramp filter for all views)")
    normal = np.cross(u, v)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    cone = vec.beam == "cone"
    direction = (d - s) if cone else s  # towards the detector
    normal *= np.sign(np.einsum("ij,ij->i", normal, direction))[:, None]

    theta = _view_angles(s, cone)
    gaps, arc_start, arc_range, full = _angular_gaps(theta, scan)
    # Lines through the centre row's pixel centres: fan angle γ and signed distance t from the axis.
    c = np.arange(cols) - (cols - 1) / 2
    centres = d[:, None, :] + c[None, :, None] * u[:, None, :]  # (views, cols, 3)
    ray = (centres - s[:, None, :]) if cone else np.broadcast_to(s[:, None, :], centres.shape)
    gamma, t = _fan_angle_and_offset(s, centres, ray, cone)

    wang, lead, trail = False, 0, 0
    if full:
        redundancy, wang = full_scan_weights(t, displaced, reach)
        if wang:
            lead, trail = _virtual_columns(t)
    else:
        redundancy = _parker_weights((theta - arc_start) % (2 * math.pi), gamma, arc_range, cone)

    if cone:
        depth = np.einsum("ij,ij->i", normal, d - s)  # D
        radius = np.hypot(s[:, 0], s[:, 1])  # R
        if np.any(radius <= 0):
            raise GeometryError("vectors: a cone-beam source lies on the rotation axis (z); FDK needs R > 0")
        # |s|, not R: a source above or below the isocentre (the origin) is scaled by its distance
        # from it, as RTK does (Rit and Clackdoyle 2014), which cancels FDK's drop off the source's
        # plane at the isocentre's height, where a scan centres its object (docs/reconstruction.md).
        scale = gaps * np.linalg.norm(s, axis=1) / depth
        toward_axis = np.column_stack([-s[:, :2] / radius[:, None], np.zeros(len(a))])
    else:
        depth = np.ones(len(a))
        scale = gaps
        toward_axis = np.zeros((len(a), 3))
    matrices = _projection_matrices(s, d, u, v, normal, depth, cone, volume, (rows, cols))
    return FDKViews(vec.beam, (rows, cols), a, depth, toward_axis, redundancy, float(pitch[0]), matrices, scale,
                    "full" if full else "short", wang, lead, trail)


def _view_angles(s: np.ndarray, cone: bool) -> np.ndarray:
    """Gantry angle θ of each view, radians in [0, 2π): cone source at R_z(θ)(0, −R, ·),
    parallel ray direction R_z(θ)(0, 1, 0)."""
    x, y = (s[:, 0], -s[:, 1]) if cone else (-s[:, 0], s[:, 1])
    if np.any(np.hypot(x, y) <= 1e-12 * np.linalg.norm(s, axis=1)):
        raise GeometryError("vectors: a view looks along the rotation axis (z); FDK/FBP needs views around the axis")
    return np.arctan2(x, y) % (2 * math.pi)


def _angular_gaps(theta: np.ndarray, scan: str):
    """(gap per view, arc start, arc range, full?) for views at angles ``theta`` (any order)."""
    n = len(theta)
    order = np.argsort(theta, kind="stable")
    sorted_theta = theta[order]
    if n == 1:
        raise GeometryError("angles: one view cannot be reconstructed; give views around the object")
    circular = np.diff(np.append(sorted_theta, sorted_theta[0] + 2 * math.pi))  # gap after each sorted view
    if np.any(circular <= 1e-12):
        raise GeometryError("angles: two views share the same angle; drop the duplicates")
    largest = int(np.argmax(circular))
    median = float(np.median(circular))
    full = circular[largest] <= 3 * median if scan == "auto" else scan == "full"
    gaps_sorted = np.empty(n)
    if full:
        gaps_sorted = 0.5 * (circular + np.roll(circular, 1))
        start, arc = 0.0, 2 * math.pi
    else:
        # The arc runs from the view after the largest gap to the view before it. Each view
        # stands for the arc around it (midpoint rule): the ends get a whole gap, and the arc
        # starts half a gap before the first view, so N views over [0, π) make a complete
        # parallel-beam scan.
        start_pos = (largest + 1) % n
        seq = np.roll(np.arange(n), -start_pos)  # sorted positions in arc order
        arc_theta = np.unwrap(sorted_theta[seq])
        step = np.diff(arc_theta)
        inner = 0.5 * (step[:-1] + step[1:])
        gaps_sorted[seq] = np.concatenate([[step[0]], inner, [step[-1]]])
        start = float(sorted_theta[start_pos]) - 0.5 * step[0]
        arc = float(arc_theta[-1] - arc_theta[0]) + 0.5 * (step[0] + step[-1])
    gaps = np.empty(n)
    gaps[order] = gaps_sorted
    return gaps, start, arc, bool(full)


def _fan_angle_and_offset(s, centres, ray, cone: bool):
    """Fan angle γ (rad, counter-clockwise about +z from the central ray) and signed distance t
    (mm) of each line from the axis, both in the xy-plane; arrays (views, cols)."""
    r = ray[..., :2]
    r = r / np.linalg.norm(r, axis=-1, keepdims=True)
    p = centres[..., :2]
    t = p[..., 0] * r[..., 1] - p[..., 1] * r[..., 0]  # (p × r)_z: sign flips with the line's side
    if not cone:
        return np.zeros_like(t), t
    central = -s[:, None, :2]
    cross = central[..., 0] * r[..., 1] - central[..., 1] * r[..., 0]
    dot = central[..., 0] * r[..., 0] + central[..., 1] * r[..., 1]
    return np.arctan2(cross, dot), t


def full_scan_weights(t: np.ndarray, displaced="auto", reach_mm: float = math.inf) -> tuple[np.ndarray, bool]:
    """(W, Wang's?) for a full scan whose lines lie at signed distances ``t`` (views, cols) mm.

    ``"auto"`` chooses from the coverage, not from the geometry's parameters (a source offset
    moves the lines as much as a detector offset does), and from ``reach_mm``, the radius about
    the axis outside which nothing attenuates: ½ when that lies within the coverage both sides of
    the axis share in every view (Δ); otherwise Wang's weights when in some view the lines reach
    further on one side of the axis than on the other by more than :data:`DISPLACED_SHARE` of the
    coverage's width, else ½."""
    low, high = t.min(axis=1), t.max(axis=1)  # per view
    overlap = np.minimum(-low, high)  # Δ: both t and −t are on the detector for |t| ≤ Δ
    off_centre = float((np.abs(high + low) / (high - low)).max())
    inside = reach_mm <= float(overlap.min())
    wang = (not inside and off_centre > DISPLACED_SHARE) if displaced == "auto" else bool(displaced)
    log.info("FDK, full scan: the detector's coverage of the axis is off-centre by %.1f %% of its width and "
             "seen from both sides to %.1f mm; the object reaches %.1f mm; %s", 100 * off_centre,
             float(overlap.min()), reach_mm, "Wang's displaced-detector weights" if wang else "weights ½")
    if not wang:
        return np.full(t.shape, 0.5), False
    if np.any(overlap <= 0):
        raise GeometryError(
            "detector_offset: the detector does not reach the rotation axis in some views; a displaced "
            "detector must still see the axis (overlap > 0) for a full-scan reconstruction"
        )
    # +1: the long side is t > 0. A centred view (forced to Wang's) takes +1 like the others: a
    # side that flipped from view to view with rounding would break W(t) + W(−t) = 1.
    side = np.where(high + low >= -1e-9 * (high - low), 1.0, -1.0)[:, None]
    x = np.clip(side * t / overlap[:, None], -1.0, 1.0)
    return np.sin(0.25 * math.pi * (1.0 + x)) ** 2, True


def grid_radius(volume: VolumeGeometry) -> float:
    """The farthest distance (mm) from the rotation axis of the grid's footprint in the xy-plane,
    voxel edges included."""
    (_, ny, nx), (_, vy, vx), (_, oy, ox) = volume.shape, volume.voxel_size, volume.offset
    half = np.array([nx * vx, ny * vy]) / 2
    return footprint_radius(np.array([ox, oy]) - half, np.array([ox, oy]) + half)


def footprint_radius(low_mm, high_mm) -> float:
    """The farthest distance (mm) from the rotation axis (z) of a box with corners ``low_mm`` and
    ``high_mm`` (x, y first), seen from above: one of its four corners'."""
    return max(math.hypot(x, y) for x in (low_mm[0], high_mm[0]) for y in (low_mm[1], high_mm[1]))


def _virtual_columns(t: np.ndarray) -> tuple[int, int]:
    """(lead, trail): columns to add before the first and after the last so that each side reaches
    as far from the axis as the other (the mirror of every line the long side measures), in the
    views' smallest column spacing, rounded up."""
    spacing = np.abs(np.diff(t, axis=1)).min(axis=1)
    first, last = np.abs(t[:, 0]), np.abs(t[:, -1])
    lead = int(np.ceil(max(0.0, float(((last - first) / spacing).max()))))
    trail = int(np.ceil(max(0.0, float(((first - last) / spacing).max()))))
    return lead, trail


def _parker_weights(beta: np.ndarray, gamma: np.ndarray, arc: float, cone: bool) -> np.ndarray:
    """Parker's short-scan weights, β (views,) from the arc start, γ (views, cols)."""
    delta = 0.5 * (arc - math.pi)
    need = float(np.abs(gamma).max()) if cone else 0.0
    if delta < need - 1e-9:
        raise GeometryError(
            f"angles: a short scan over {math.degrees(arc):.2f}° cannot be reconstructed: it needs at least "
            f"180° + the fan angle = {math.degrees(math.pi + 2 * need):.2f}°; scan a wider range"
        )
    b = beta[:, None]
    g = np.broadcast_to(gamma, (len(beta), gamma.shape[1]))
    w = np.ones(g.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        rise = b < 2 * delta - 2 * g
        w = np.where(rise, np.sin(0.25 * math.pi * b / (delta - g)) ** 2, w)
        fall = b > math.pi - 2 * g
        w = np.where(fall, np.sin(0.25 * math.pi * (math.pi + 2 * delta - b) / (delta + g)) ** 2, w)
    w = np.where(b > math.pi + 2 * delta + 1e-12, 0.0, w)
    return np.nan_to_num(w, nan=0.0)


def _projection_matrices(s, d, u, v, normal, depth, cone: bool, volume: VolumeGeometry, detector_shape) -> np.ndarray:
    """(views, 3, 4): voxel index (i, j, k, 1) -> (col·w, row·w, w), see the module docstring.

    The detector point ``d + a·u + b·v`` (a, b relative to the detector centre) is found on the
    line through the voxel: for a cone beam from ``s``, for a parallel beam along ``r``."""
    nrow, ncol = detector_shape
    nz, ny, nx = volume.shape
    vz, vy, vx = volume.voxel_size
    oz, oy, ox = volume.offset
    # Voxel index -> scanner (x, y, z, 1), mm.
    to_mm = np.array([
        [vx, 0, 0, ox - (nx - 1) / 2 * vx],
        [0, vy, 0, oy - (ny - 1) / 2 * vy],
        [0, 0, vz, oz - (nz - 1) / 2 * vz],
        [0, 0, 0, 1.0],
    ])
    # Dual basis of (u, v) within the detector plane: du·u = 1, du·v = 0; dv·v = 1, dv·u = 0.
    plane_normal = np.cross(u, v)
    du = np.cross(v, plane_normal)
    du /= _dot(du, u)[:, None]
    dv = np.cross(plane_normal, u)
    dv /= _dot(dv, v)[:, None]
    if cone:
        # The detector point on the line from s through x is s + (x − s)/w, w = n·(x − s)/D, so
        # a·w = du·(x − s) + w·du·(s − d), likewise b: all three rows are affine in x.
        w_rows = np.concatenate([normal, -_dot(normal, s)[:, None]], axis=1) / depth[:, None]
        a_rows = np.concatenate([du, -_dot(du, s)[:, None]], axis=1) + _dot(du, s - d)[:, None] * w_rows
        b_rows = np.concatenate([dv, -_dot(dv, s)[:, None]], axis=1) + _dot(dv, s - d)[:, None] * w_rows
    else:
        # x moves along r onto the plane n·(y − d) = 0: y = x − r·(n·x)/(n·r) + r·(n·d)/(n·r).
        r = s
        nr = _dot(normal, r)[:, None]
        def through(dual):
            linear = dual - _dot(dual, r)[:, None] * normal / nr
            shift = _dot(dual, r)[:, None] * _dot(normal, d)[:, None] / nr - _dot(dual, d)[:, None]
            return np.concatenate([linear, shift], axis=1)
        a_rows, b_rows = through(du), through(dv)
        w_rows = np.tile([0.0, 0.0, 0.0, 1.0], (len(s), 1))
    # (a, b) are pixel offsets from the detector centre; indices add the centre's index.
    m = np.stack([a_rows + (ncol - 1) / 2 * w_rows, b_rows + (nrow - 1) / 2 * w_rows, w_rows], axis=1)
    return m @ to_mm


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two (views, 3) arrays."""
    return np.einsum("ij,ij->i", a, b)
