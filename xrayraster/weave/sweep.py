"""The yarn mesher: closed cross-sections swept along a C² path with rotation-minimising frames.

A yarn is a closed 2-D outline (its cross-section, in mm, in the section plane's (u, v) axes:
``u`` along the yarn's width, ``v`` along its height) carried along a smooth centre line. The
pieces, each usable on its own:

- **Outlines** (:mod:`xrayraster.weave.sections`: ellipse, lenticular, power ellipse, rounded
  rectangle): ``(k, 2)`` float64 points, counter-clockwise, star-shaped about the origin, with the
  exact areas of the smooth shapes; re-exported here.
- **Path** (:class:`CubicSpline3`): a cubic spline through ``(m, 3)`` nodes, natural or clamped,
  parametrised by cumulative chord length; C² by construction. It is a small tridiagonal solve in
  NumPy (Thomas algorithm; the system is diagonally dominant, so no pivoting is needed): SciPy is
  not a dependency of the package. :func:`sample_path` places points on it at a near-uniform
  spacing of ``1 / samples_per_mm`` along arc length (the points lie exactly on the spline; only
  their spacing comes from a dense arc-length table); :func:`adaptive_params` spaces them for a
  chord error instead, dense in bends and sparse on straight runs.
- **Frames** (:func:`rotation_minimising_frames`, in :mod:`xrayraster.weave.frames`, re-exported
  here): the double-reflection method of Wang, Jüttler, Zheng and Liu, "Computation of rotation
  minimizing frames", ACM Trans. Graph. 27(1), 2008. The
  first frame's height axis is the ``up`` vector made perpendicular to the path, so a yarn that
  starts horizontally starts with its height along +z.
- **Sweep** (:func:`sweep`): the tube through the sections (one outline, or one per sample: per-node
  scale and rotation carried to every sample by :func:`smooth_profile`, C² and never overshooting,
  and applied by :func:`section_outlines`), capped at both ends by a fan from the outline's
  centroid (valid because the outlines above are star-shaped about it; :func:`sweep` checks that
  every fan triangle is positive, so a non-star outline is refused, not mis-meshed).
  The result is watertight, 2-manifold, outward-oriented and free of degenerate triangles; every
  triangle's area is checked after building.

**Bend limit.** A section swept round a bend of radius ``R`` folds through itself on the inner
side as soon as it reaches ``R`` or more toward the bend's centre: for a section centred on the
path, the bend radius must exceed the section's half-width in the bending direction (its
half-width or half-height, whichever lies in the plane of the bend). :func:`sweep` measures the
radius at every sample (the circle through three consecutive path points) and raises
:class:`WeaveError` naming both numbers when this fails. It does not look for distant parts of
one yarn meeting (a path that loops back on itself); yarn paths in a weave do not.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from ..core.errors import WeaveError
from .frames import rotation_minimising_frames
from .sections import (
    ellipse,
    ellipse_area,
    lenticular,
    lenticular_area,
    polygon_area,
    polygon_centroid,
    power_ellipse,
    power_ellipse_area,
    rounded_rectangle,
    rounded_rectangle_area,
)

__all__ = ["CubicSpline3", "adaptive_params", "bend_sagitta_mm", "ellipse", "ellipse_area", "lenticular", "lenticular_area", "polygon_area",
           "power_ellipse", "power_ellipse_area", "rotation_minimising_frames", "rounded_rectangle",
           "rounded_rectangle_area", "sample_path", "section_outlines", "smooth_profile", "sweep",
           "yarn_mesh"]


#: :func:`adaptive_params`: its table's samples per uniform step (the densest samples' spacing).
TABLE_PER_STEP = 2
#: :func:`adaptive_params`: the most uniform steps between two samples.
SPARSEST_STEPS = 16


# --------------------------------------------------------------------------------------------
# Path: a C² cubic spline through the nodes
# --------------------------------------------------------------------------------------------


class CubicSpline3:
    """Cubic spline through ``(m, 3)`` nodes, parametrised by cumulative chord length (mm).

    ``end_tangents=None`` gives the natural spline (zero second derivative at both ends);
    ``end_tangents=(d0, d1)`` clamps the first derivative at the ends (with respect to the chord
    length parameter, so pass unit vectors for unit speed). The second derivatives at the knots
    solve the standard tridiagonal system (Thomas algorithm, all three coordinates at once).
    """

    def __init__(self, nodes, end_tangents=None):
        nodes = np.asarray(nodes, dtype=np.float64)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or len(nodes) < 2:
            raise WeaveError(f"nodes must be an (m, 3) array with m >= 2, got shape {nodes.shape}")
        if not np.all(np.isfinite(nodes)):
            raise WeaveError("nodes must be finite (a NaN or infinite coordinate)")
        chords = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
        if np.any(chords <= 0):
            i = int(np.argmin(chords))
            raise WeaveError(f"nodes {i} and {i + 1} coincide; consecutive path nodes must differ")
        self.nodes = nodes
        self.knots = np.concatenate([[0.0], np.cumsum(chords)])
        self.second = self._solve(nodes, chords, end_tangents)

    @staticmethod
    def _solve(y: np.ndarray, h: np.ndarray, end_tangents) -> np.ndarray:
        m = len(y)
        lower, diag, upper = np.zeros(m), np.zeros(m), np.zeros(m)
        rhs = np.zeros((m, 3))
        slope = np.diff(y, axis=0) / h[:, None]
        lower[1:-1], diag[1:-1], upper[1:-1] = h[:-1], 2 * (h[:-1] + h[1:]), h[1:]
        rhs[1:-1] = 6 * (slope[1:] - slope[:-1])
        if end_tangents is None:
            diag[0] = diag[-1] = 1.0  # natural: M_0 = M_{m-1} = 0
        else:
            d0, d1 = (np.asarray(d, dtype=np.float64).reshape(3) for d in end_tangents)
            diag[0], upper[0], rhs[0] = 2 * h[0], h[0], 6 * (slope[0] - d0)
            lower[-1], diag[-1], rhs[-1] = h[-1], 2 * h[-1], 6 * (d1 - slope[-1])
        # Thomas algorithm: forward elimination, back substitution.
        c, d = np.zeros(m), np.zeros((m, 3))
        c[0], d[0] = upper[0] / diag[0], rhs[0] / diag[0]
        for i in range(1, m):
            denom = diag[i] - lower[i] * c[i - 1]
            c[i] = upper[i] / denom
            d[i] = (rhs[i] - lower[i] * d[i - 1]) / denom
        out = np.zeros((m, 3))
        out[-1] = d[-1]
        for i in range(m - 2, -1, -1):
            out[i] = d[i] - c[i] * out[i + 1]
        return out

    @property
    def length_parameter(self) -> float:
        """The parameter's range (total chord length through the nodes), mm."""
        return float(self.knots[-1])

    def __call__(self, t, derivative: int = 0) -> np.ndarray:
        """Points (or the 1st/2nd derivative) at parameters ``t``; ``(len(t), 3)``."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        i = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self.knots) - 2)
        t0, t1 = self.knots[i], self.knots[i + 1]
        h = (t1 - t0)[:, None]
        left, right = (t1 - t)[:, None], (t - t0)[:, None]
        m0, m1 = self.second[i], self.second[i + 1]
        y0, y1 = self.nodes[i], self.nodes[i + 1]
        a, b = y0 / h - m0 * h / 6, y1 / h - m1 * h / 6
        if derivative == 0:
            return (m0 * left**3 + m1 * right**3) / (6 * h) + a * left + b * right
        if derivative == 1:
            return (m1 * right**2 - m0 * left**2) / (2 * h) + b - a
        if derivative == 2:
            return (m0 * left + m1 * right) / h
        raise WeaveError(f"derivative must be 0, 1 or 2, got {derivative!r}")

    def curvature(self, t) -> np.ndarray:
        """Curvature ``|r′ × r″| / |r′|³`` (1/mm) at parameters ``t``; ``(len(t),)``."""
        first, second = self(t, 1), self(t, 2)
        return np.linalg.norm(np.cross(first, second), axis=1) / np.linalg.norm(first, axis=1) ** 3


def sample_path(spline: CubicSpline3, samples_per_mm: float, *, table_per_interval: int = 64):
    """Points and unit tangents on ``spline`` about ``1 / samples_per_mm`` apart along arc length.

    Returns ``(points, tangents, params)``: ``(n, 3)``, ``(n, 3)``, ``(n,)`` with n − 1 =
    ceil(length × samples_per_mm) (at least 1). Both ends and every point lie exactly on the spline;
    the spacing is uniform to the accuracy of a dense polyline arc-length table.
    """
    rate = float(samples_per_mm)
    if not (math.isfinite(rate) and rate > 0):
        raise WeaveError(f"samples_per_mm must be a positive number, got {samples_per_mm!r}")
    knots = spline.knots  # table_per_interval points per interval, as np.linspace(.., endpoint=False) puts them
    step = np.diff(knots) / table_per_interval
    fine = np.concatenate([(np.arange(table_per_interval) * step[:, None] + knots[:-1, None]).ravel(), knots[-1:]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(spline(fine), axis=0), axis=1))])
    intervals = max(1, math.ceil(arc[-1] * rate))
    params = np.interp(np.linspace(0.0, arc[-1], intervals + 1), arc, fine)
    params[0], params[-1] = spline.knots[0], spline.knots[-1]
    return (*_on_spline(spline, params), params)


def _on_spline(spline: CubicSpline3, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and unit tangents of ``spline`` at ``params``; a zero tangent is refused."""
    tangents = spline(params, 1)
    speed = np.linalg.norm(tangents, axis=1)
    if np.any(speed <= 0):
        raise WeaveError("the path has a cusp (zero tangent); move the nodes apart or clamp its ends")
    return spline(params), tangents / speed[:, None]


def adaptive_params(spline: CubicSpline3, outline, sagitta_mm: float, rate_per_mm: float, *, up=(0.0, 0.0, 1.0),
                    section_scale=None, section_rotation_deg=None) -> np.ndarray:
    """Path parameters of samples spaced so that no ring-to-ring chord of the swept tube misses the
    smooth one by more than ``sagitta_mm`` (to leading order): dense where the tube bends or its
    section changes, sparse where it runs straight and uniform. ``(n,)``, both ends included.

    Every point of the outline (``(k, 2)``, scaled and turned along the path by ``section_scale``
    and ``section_rotation_deg`` as :func:`yarn_mesh` does) traces a fibre p(s) over the centre
    line's arc length s. A chord of length h across it misses it by ``h² |p''⊥| / 8``, where ``p''⊥``
    is p'' across the fibre's direction (bends, section scaling and turning all enter it), so the
    sample density ``ρ(s) = √(max over the fibres |p''⊥| / (8 sagitta))`` holds that sagitta; the
    samples equidistribute ∫ρ ds. ``rate_per_mm`` is the uniform rate this replaces
    (:func:`sample_path`): p'' comes from second differences on a table of :data:`TABLE_PER_STEP`
    samples per uniform step ``1 / rate_per_mm``, and samples are never more than
    :data:`SPARSEST_STEPS` uniform steps apart (a tube without any curvature still follows its
    path's small turns).
    """
    rate = float(rate_per_mm)
    points, tangents, params = sample_path(spline, TABLE_PER_STEP * rate)
    frames = rotation_minimising_frames(points, tangents, up)
    shape = np.asarray(outline, dtype=np.float64)
    if section_scale is not None:
        shape = section_outlines(shape, smooth_profile(spline.knots, section_scale, params),
                                 smooth_profile(spline.knots, section_rotation_deg, params))
    fibres = _rings(points, shape, frames)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if len(arc) < 3:
        return params
    before, after = np.diff(arc)[:-1, None, None], np.diff(arc)[1:, None, None]
    back, ahead = fibres[1:-1] - fibres[:-2], fibres[2:] - fibres[1:-1]
    second = 2.0 * (ahead / after - back / before) / (before + after)  # p'' on an uneven grid
    direction = back + ahead
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    across = second - np.sum(second * direction, axis=-1, keepdims=True) * direction
    bend = np.linalg.norm(across, axis=-1).max(axis=1)
    bend = np.concatenate([bend[:1], bend, bend[-1:]])
    density = np.maximum(np.sqrt(bend / (8.0 * float(sagitta_mm))), rate / SPARSEST_STEPS)  # samples per mm
    count = np.concatenate([[0.0], np.cumsum(np.diff(arc) * (density[1:] + density[:-1]) / 2)])
    intervals = max(1, math.ceil(count[-1] * (1.0 - 1e-12)))
    out = np.interp(np.linspace(0.0, count[-1], intervals + 1), count, params)
    out[0], out[-1] = params[0], params[-1]
    return out


def bend_sagitta_mm(radius_mm: float, spacing_mm: float, reach_mm: float) -> float:
    """``(R + d)(1 − cos(h / 2R))``: how far chords ``h`` apart along a bend of radius R miss the fibre
    d outside it (0 for R = inf). Unchecked: :func:`~xrayraster.weave.tessellation.path_error_mm`
    checks its inputs and explains the terms."""
    if radius_mm == math.inf:
        return 0.0
    return 2.0 * (radius_mm + reach_mm) * math.sin(spacing_mm / (4.0 * radius_mm)) ** 2  # no cancellation


def smooth_profile(knots, values, t) -> np.ndarray:
    """C² interpolation of per-knot ``values`` ``(m, ...)`` at parameters ``t``; ``(len(t), ...)``.

    Between knots i and i + 1 the value moves from ``values[i]`` to ``values[i + 1]`` along the
    quintic smootherstep ``τ³(10 − 15τ + 6τ²)`` (τ the fraction of the interval), whose first and
    second derivatives vanish at both ends: C², the values at the knots and, unlike a cubic spline,
    never outside its two neighbouring values (a scale drawn in [1 − a, 1 + a] stays there).
    """
    knots, values = np.asarray(knots, dtype=np.float64), np.asarray(values, dtype=np.float64)
    t = np.clip(np.asarray(t, dtype=np.float64), knots[0], knots[-1])
    i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2)
    tau = (t - knots[i]) / (knots[i + 1] - knots[i])
    step = (tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)).reshape((-1,) + (1,) * (values.ndim - 1))
    return values[i] + (values[i + 1] - values[i]) * step


def section_outlines(outline, scale, rotation_deg) -> np.ndarray:
    """One outline per sample, ``(n, k, 2)``: ``outline`` ``(k, 2)`` scaled, then turned about its origin.

    ``scale`` ``(n, 2)`` multiplies u (width) and v (height); ``rotation_deg`` ``(n,)`` turns the
    scaled outline counter-clockwise in the (u, v) plane, i.e. about the path's tangent. Positive
    scales and a rotation keep the outline counter-clockwise and star-shaped about its origin.
    """
    shape = np.asarray(outline, dtype=np.float64)
    scale = np.asarray(scale, dtype=np.float64)
    angle = np.radians(np.asarray(rotation_deg, dtype=np.float64))
    u = shape[None, :, 0] * scale[:, 0, None]
    v = shape[None, :, 1] * scale[:, 1, None]
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return np.stack([u * cos - v * sin, u * sin + v * cos], axis=-1)


# --------------------------------------------------------------------------------------------
# Sweep
# --------------------------------------------------------------------------------------------


def _check_bends(points: np.ndarray, frames: np.ndarray, outlines: np.ndarray) -> None:
    """Refuse a path that bends tighter than its section (``outlines`` ``(n, k, 2)``) reaches toward the bend's centre."""
    if len(points) < 3:
        return
    p0, p1, p2 = points[:-2], points[1:-1], points[2:]
    a, b = p0 - p1, p2 - p1
    axb = np.cross(a, b)
    area2 = np.einsum("ij,ij->i", axb, axb)
    bent = area2 > 1e-24 * (np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b))
    if not np.any(bent):
        return
    a, b, axb, area2, rows = a[bent], b[bent], axb[bent], area2[bent], np.nonzero(bent)[0] + 1
    # circumcentre of (p0, p1, p2) relative to p1
    to_centre = (np.cross(axb, a) * np.einsum("ij,ij->i", b, b)[:, None]
                 + np.cross(b, axb) * np.einsum("ij,ij->i", a, a)[:, None]) / (2 * area2[:, None])
    radius = np.linalg.norm(to_centre, axis=1)
    inward = to_centre / radius[:, None]
    # how far the section reaches toward the centre: max over outline of (u U + v V) · inward
    du = np.einsum("ij,ij->i", frames[rows, 1], inward)
    dv = np.einsum("ij,ij->i", frames[rows, 2], inward)
    reach = (outlines[rows, :, 0] * du[:, None] + outlines[rows, :, 1] * dv[:, None]).max(axis=1)
    bad = reach >= radius
    if np.any(bad):
        j = int(np.argmax(reach - radius))
        along = float(np.sum(np.linalg.norm(np.diff(points[: rows[j] + 1], axis=0), axis=1)))
        raise WeaveError(
            f"the yarn path bends with radius {radius[j]:.4g} mm at {along:.4g} mm along it, but the "
            f"cross-section reaches {reach[j]:.4g} mm toward the bend's centre: the bend radius must exceed "
            "the section's half-width in the bending direction, or the tube folds through itself. "
            "Smooth the path (fewer or farther nodes) or make the yarn narrower")


def sweep(path_points, outline, frames, cap: bool = True):
    """The tube through ``outline`` placed at each path point in its frame: ``(vertices, faces)``.

    ``path_points`` ``(n, 3)`` mm, n >= 2; ``outline`` ``(k, 2)`` counter-clockwise, in the section's
    (u, v) axes, or ``(n, k, 2)``, one per path point (e.g. :func:`section_outlines`); ``frames``
    ``(n, 3, 3)`` rows [T, U, V] as :func:`rotation_minimising_frames` gives. Section i's point j is
    ``P_i + u_ij U_i + v_ij V_i``. With ``cap`` both ends are closed by a fan from their outline's
    centroid (checked to be star-shaped about it): the mesh is then watertight, 2-manifold and
    outward-oriented. Returns float64 vertices ``(n k + 2, 3)`` and int64 faces. Raises
    :class:`WeaveError` for a bend tighter than the section there (the module's bend limit) or a
    degenerate triangle.
    """
    points = np.asarray(path_points, dtype=np.float64)
    shape = np.asarray(outline, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise WeaveError(f"path_points must be (n, 3) with n >= 2, got shape {points.shape}")
    if shape.ndim not in (2, 3) or shape.shape[-1] != 2 or shape.shape[-2] < 3 or (
            shape.ndim == 3 and len(shape) != len(points)):
        raise WeaveError(f"outline must be (k, 2), or (n, k, 2) with n = {len(points)} path points, and k >= 3; "
                         f"got shape {shape.shape}")
    if frames.shape != (len(points), 3, 3):
        raise WeaveError(f"frames must be (n, 3, 3) = {(len(points), 3, 3)}, got {frames.shape}")
    if not (np.all(np.isfinite(points)) and np.all(np.isfinite(shape)) and np.all(np.isfinite(frames))):
        raise WeaveError("path_points, outline and frames must be finite")
    shapes = np.broadcast_to(shape, (len(points),) + shape.shape[-2:])
    x, y = shape[..., 0], shape[..., 1]  # the shoelace area of every distinct outline
    if np.any(np.sum(x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y, axis=-1) <= 0):
        raise WeaveError("outline must be counter-clockwise (positive area); reverse its points")
    ends = [polygon_centroid(shapes[i]) for i in (0, -1)]
    for i, centroid in zip((0, -1), ends):
        rel = shapes[i] - centroid
        fan = rel[:, 0] * np.roll(rel[:, 1], -1) - rel[:, 1] * np.roll(rel[:, 0], -1)
        if cap and np.any(fan <= 0):
            raise WeaveError("outline is not star-shaped about its centroid, so a fan cannot cap it; "
                             "use a convex or star-shaped cross-section")
    _check_bends(points, frames, shapes)

    n, k = shapes.shape[:2]
    vertices = _rings(points, shapes, frames).reshape(-1, 3)
    i = np.arange(n - 1)[:, None]
    j = np.arange(k)[None, :]
    a = i * k + j
    b = i * k + (j + 1) % k
    c = a + k
    d = b + k
    faces = [np.stack([a, b, d], axis=-1).reshape(-1, 3), np.stack([a, d, c], axis=-1).reshape(-1, 3)]
    if cap:
        ends = _rings(points[[0, -1]], np.array(ends)[:, None], frames[[0, -1]])[:, 0]
        start, end = n * k, n * k + 1
        jj = np.arange(k)
        faces.append(np.column_stack([np.full(k, start), (jj + 1) % k, jj]))
        faces.append(np.column_stack([np.full(k, end), (n - 1) * k + jj, (n - 1) * k + (jj + 1) % k]))
        vertices = np.concatenate([vertices, ends])
    faces = np.concatenate(faces).astype(np.int64)

    tri = vertices[faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    scale = float(np.ptp(vertices, axis=0).max())
    if not np.all(areas > 1e-14 * scale * scale):
        raise WeaveError(f"{int(np.count_nonzero(areas <= 1e-14 * scale * scale))} degenerate triangles in the "
                         "swept yarn (repeated path points or outline points); remove the duplicates")
    return vertices, faces


def _rings(points, outlines, frames) -> np.ndarray:
    """``(n, k, 3)`` mm: outline point j placed at sample i, ``P_i + u_ij U_i + v_ij V_i``
    (``outlines`` ``(k, 2)``, one for all samples, or ``(n, k, 2)``)."""
    return points[:, None] + outlines[..., :1] * frames[:, None, 1] + outlines[..., 1:] * frames[:, None, 2]


def _span_near(points, frames, outlines, box) -> slice:
    """The samples a tube clipped to ``box`` ((2, 3) mm) needs: each dropped run of end rings lies wholly
    beyond one face plane, as does the kept ring next to it, so the clipped solid is the same."""
    rings = _rings(points, outlines, frames)
    beyond = np.concatenate([rings.max(axis=1) < box[0], rings.min(axis=1) > box[1]], axis=1)  # (n, 6 faces)
    n = len(points)
    lead, trail = (int(np.where(b.all(axis=0), n, b.argmin(axis=0)).max()) for b in (beyond, beyond[::-1]))
    # a path that never meets the box is left whole (its clip is empty either way)
    return slice(0, n) if lead + trail >= n else slice(max(lead - 1, 0), n - max(trail - 1, 0))


def yarn_mesh(nodes, outline, samples_per_mm: float, up=(0.0, 0.0, 1.0), end_tangents=None,
              section_scale=None, section_rotation_deg=None, within=None, sagitta_mm=None) -> trimesh.Trimesh:
    """A closed yarn: ``outline`` swept along the natural (or clamped) C² spline through ``nodes``.

    The path is sampled at ``samples_per_mm`` along arc length (or, given ``sagitta_mm``, where
    :func:`adaptive_params` puts the samples for that largest chord error), framed by rotation-minimising
    frames whose height axis starts along ``up``, swept and capped. ``section_scale`` ``(m, 2)``
    (width and height factors) and ``section_rotation_deg`` ``(m,)`` (about the tangent), one per
    node, vary the section along the yarn: :func:`smooth_profile` carries them to every sample
    (C², within the node values) and :func:`section_outlines` applies them; give both or neither.
    ``within``, a ``(2, 3)`` box (mm) the tube will be clipped to, drops the rings beyond one of its
    faces but the one nearest the box: the same solid once clipped, with fewer triangles. Returns
    an unprocessed ``trimesh.Trimesh`` (the vertices and faces exactly as :func:`sweep` built them).
    """
    if (section_scale is None) != (section_rotation_deg is None):
        raise WeaveError("section_scale and section_rotation_deg go together: give both (one per node) or neither")
    if section_scale is not None:
        scale, angle = np.asarray(section_scale, dtype=np.float64), np.asarray(section_rotation_deg, dtype=np.float64)
        m = len(nodes)
        if scale.shape != (m, 2) or angle.shape != (m,):
            raise WeaveError(f"section_scale must be ({m}, 2) and section_rotation_deg ({m},), one per node; "
                             f"got {scale.shape} and {angle.shape}")
        if not (np.all(np.isfinite(scale)) and np.all(scale > 0) and np.all(np.isfinite(angle))):
            raise WeaveError("section_scale must be positive and finite, section_rotation_deg finite")
    spline = CubicSpline3(nodes, end_tangents)
    if sagitta_mm:
        params = adaptive_params(spline, outline, sagitta_mm, samples_per_mm, up=up, section_scale=section_scale,
                                 section_rotation_deg=section_rotation_deg)
        points, tangents = _on_spline(spline, params)
    else:
        points, tangents, params = sample_path(spline, samples_per_mm)
    frames = rotation_minimising_frames(points, tangents, up)
    if section_scale is not None:
        outline = section_outlines(outline, smooth_profile(spline.knots, scale, params),
                                   smooth_profile(spline.knots, angle, params))
    if within is not None:
        keep = _span_near(points, frames, np.asarray(outline, dtype=np.float64), np.asarray(within, dtype=np.float64))
        points, frames, outline = points[keep], frames[keep], outline[keep] if np.ndim(outline) == 3 else outline
    vertices, faces = sweep(points, outline, frames, cap=True)
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
