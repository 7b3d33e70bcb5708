"""Tessellation error of the yarn meshes: how far the mesher's polygons and polylines lie from the
smooth yarns, predicted from geometry, and the coarsest resolution that meets a tolerance.

Two knobs set a yarn mesh's resolution (:class:`xrayraster.weave.Sample`): ``points_per_section``
(k, the outline's points) and ``samples_per_mm`` (the path's samples, ``h = 1 / samples_per_mm``
apart along arc length, or closer). Both errors are *sagittas*: a chord ``c`` across an arc of
curvature ``κ`` misses it by ``s = c² κ / 8`` to leading order.

- **Section.** The outline's k points lie on the smooth convex section (the shapes of
  :mod:`xrayraster.weave.sections`), so each edge cuts off a sliver of it. The sliver's depth is
  computed exactly, not estimated: for the edge with outward unit normal ``N`` from vertex ``P``,
  it is ``h(N) − N·P``, where ``h`` is the smooth shape's support function (``max N·p`` over the
  shape: ``√((aN_u)² + (bN_v)²)`` for the ellipse; the dual norm ``‖(aN_u, bN_v)‖_m``,
  ``m = n/(n − 1)``, for the superellipse of exponent n ≥ 1; ``R − (R − b)|N_v|`` on a lens's arcs
  of radius R; ``(a − r)|N_u| + (b − r)|N_v| + r`` for the rounded rectangle, a rectangle grown by
  its corner radius r). The arc between two vertices turns through the edge's normal, so that
  support point lies on the edge's own arc. With ``c ~ perimeter / k`` the depths fall as k⁻², and
  so does the area: each sliver's area lies between ``c·s / 2`` (the triangle on the chord) and
  ``c·s`` (the strip), ``2 c s / 3`` for a parabolic arc, which :func:`area_error_mm2` sums.
- **Path.** On a bend of radius R the path's samples are joined by straight chords, and the
  section's rings by planar quadrilaterals: a fibre ``d`` outside the centre line (radius R + d)
  is cut by chords of angle ``θ = h / R``, missing its arc by ``(R + d)(1 − cos(θ/2)) ≈ h²(R + d)
  / (8R²)``. The tube's volume per step is ``A·R·sin θ`` instead of ``A·R·θ`` (the ruled solid
  between two rings; exact for a circular arc), a relative loss of ``1 − sin θ / θ ≈ h² / (6R²)``.

**What a ray sees.** The depth ``s`` is the path-length error of one boundary crossing at normal
incidence. A ray crossing at incidence θ (from the surface normal) sees up to ``s / cos θ``, and a
ray through a yarn crosses twice (both errors have the same sign: the polygon is inscribed), so a
chord through a yarn at near-normal incidence is short by up to ``2 s``. Rays grazing the yarn's
sides converge more slowly (``k⁻¹`` for the ellipse, ``k^(−2/3)`` for the superellipse n = 3,
not at all for a flat side, which the polygon moves inward by ``s``), but on a band of rays only
about ``s`` wide: a detector pixel averages it away, and the mean chord error across a yarn is its
area error over its width. Tables and rates: docs/weave.md, "Tessellation error".
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import WeaveError
from ..core.validate import show
from .binders import binder_curvature_along, smallest_bend_radius_mm
from .sample import Sample, section_outline
from .sections import corner_radius, lens_arc
from .section import Section
from .spec import UnitCell
from .sweep import bend_sagitta_mm

__all__ = [
    "area_error_mm2",
    "binder_bend_radius_mm",
    "binder_curvature",
    "edge_sagittas_mm",
    "path_error_mm",
    "resolution_for",
    "section_error_mm",
]

def _number(name: str, value, *, zero: bool = False, infinite: bool = False) -> float:
    """``value`` as a float > 0 (>= 0 with ``zero``; ``inf`` allowed with ``infinite``), else a WeaveError."""
    wanted = f"a {'non-negative' if zero else 'positive'}{'' if infinite else ' finite'} number"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise WeaveError(f"{name} must be {wanted}, got {show(value)}")
    x = float(value)
    if not ((x > 0 or (zero and x == 0)) and (math.isfinite(x) or (infinite and x == math.inf))):
        raise WeaveError(f"{name} must be {wanted}, got {show(value)}")
    return x


def _points(k) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 8 or k % 4:
        raise WeaveError(f"points_per_section must be an integer >= 8 and a multiple of 4 (as Sample takes it), "
                         f"got {show(k)}")
    return int(k)


def _support(section: Section, width: float, height: float):
    """The smooth section's support function: unit normals ``(m, 2)`` -> ``max N·p`` over the shape, mm."""
    a, b = width / 2, height / 2
    if section.shape == "ellipse":
        return lambda n: np.hypot(a * n[:, 0], b * n[:, 1])
    if section.shape == "lenticular":
        radius, _ = lens_arc(width, height)
        # valid for the normals of the arcs, which every edge's normal is (the corners are vertices)
        return lambda n: radius - (radius - b) * np.abs(n[:, 1])
    if section.shape == "rounded_rectangle":
        r = corner_radius(width, height, section.corner)
        return lambda n: (a - r) * np.abs(n[:, 0]) + (b - r) * np.abs(n[:, 1]) + r
    exponent = section.exponent
    if exponent < 1:
        raise WeaveError(f"section.exponent: a power_ellipse with exponent {show(exponent)} < 1 is not convex, so its "
                         "inscribed polygon's error has no sagitta bound here; use an exponent >= 1")
    m = math.inf if exponent == 1 else exponent / (exponent - 1)  # Hölder conjugate: the dual norm

    def superellipse(n):
        x, y = np.abs(a * n[:, 0]), np.abs(b * n[:, 1])
        top = np.maximum(x, y)  # scaled so that a large m cannot overflow
        return top * ((x / top) ** m + (y / top) ** m) ** (1 / m)

    return superellipse


def edge_sagittas_mm(section: Section, width_mm: float, height_mm: float, points_per_section: int):
    """Per edge of the outline :class:`Sample` draws: its length and its sliver's depth, ``(k,)`` each, mm.

    Edge i runs from outline point i to point i + 1; its depth is the largest distance from the
    edge to the smooth section's boundary (exact, from the support function: module docstring).
    """
    if not isinstance(section, Section):
        raise WeaveError(f"section must be a Section, got {show(section)}")
    section.check("section")
    outline = section_outline(section, _number("width_mm", width_mm), _number("height_mm", height_mm),
                              _points(points_per_section))
    edge = np.roll(outline, -1, axis=0) - outline
    chord = np.hypot(edge[:, 0], edge[:, 1])
    normal = np.column_stack([edge[:, 1], -edge[:, 0]]) / chord[:, None]  # outward: the outline is CCW
    depth = _support(section, width_mm, height_mm)(normal) - np.einsum("ij,ij->i", normal, outline)
    return chord, np.maximum(depth, 0.0)  # a flat edge's depth rounds to ±1e-17


def section_error_mm(section: Section, width_mm: float, height_mm: float, points_per_section: int) -> float:
    """The largest distance (mm) between the k-point outline and the smooth section.

    It is the largest path-length error of one boundary crossing at normal incidence; at incidence
    θ a crossing sees up to this ÷ cos θ, and a ray through the yarn crosses twice (module docstring).
    """
    return float(edge_sagittas_mm(section, width_mm, height_mm, points_per_section)[1].max())


def area_error_mm2(section: Section, width_mm: float, height_mm: float, points_per_section: int) -> float:
    """Predicted area (mm²) the k-point outline misses: ``Σ 2 c s / 3`` over its edges.

    Bounds: the true loss lies between ``Σ c s / 2`` and ``Σ c s`` (3/4 and 3/2 of this value).
    """
    chord, depth = edge_sagittas_mm(section, width_mm, height_mm, points_per_section)
    return float(2.0 / 3.0 * np.dot(chord, depth))


def path_error_mm(min_bend_radius_mm: float, samples_per_mm: float, half_extent_mm: float) -> float:
    """Largest distance (mm) between the swept tube and the smooth one, from sampling the path.

    ``(R + d)(1 − cos(h / 2R))`` with R = ``min_bend_radius_mm`` (``inf`` for a straight yarn, which
    has none), d = ``half_extent_mm`` (how far the section reaches outward in the plane of the bend:
    half the height for a binder) and h = 1 / ``samples_per_mm``: the sagitta of the outermost
    fibre's chords (module docstring). R must exceed d (else the tube folds, see the sweep's bend
    limit) and h may not exceed πR (the samples would not resolve the bend).
    """
    radius = _number("min_bend_radius_mm", min_bend_radius_mm, infinite=True)
    spacing = 1.0 / _number("samples_per_mm", samples_per_mm)
    reach = _number("half_extent_mm", half_extent_mm, zero=True)
    if radius <= reach:
        raise WeaveError(f"min_bend_radius_mm ({show(radius)}) must exceed half_extent_mm ({show(reach)}): a tube bent "
                         "tighter than its section reaches folds through itself")
    if radius == math.inf:
        return 0.0
    if spacing > math.pi * radius:
        raise WeaveError(f"samples_per_mm ({show(samples_per_mm)}) puts samples {spacing:.4g} mm apart, more than half a "
                         f"turn of the {radius:.4g} mm bend; use samples_per_mm >= {1 / (math.pi * radius):.4g}")
    return bend_sagitta_mm(radius, spacing, reach)


def binder_curvature(cell: UnitCell) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per binder of the cell: arc length (mm) and curvature (1/mm) along its centre line inside the
    cell: the binders of a 1 × 1 :class:`Sample` (:func:`~xrayraster.weave.binders.binder_curvature_along`,
    :data:`~xrayraster.weave.binders.CURVATURE_SAMPLES` points per node interval)."""
    if not isinstance(cell, UnitCell):
        raise WeaveError(f"cell must be a UnitCell, got {show(cell)}")
    return binder_curvature_along(Sample(cell).yarns(), cell.size)


def binder_bend_radius_mm(cell: UnitCell) -> float:
    """Smallest bend radius (mm) of the cell's binder centre lines inside the cell (:func:`binder_curvature`);
    ``inf`` when no binder bends."""
    return smallest_bend_radius_mm(binder_curvature(cell))


def resolution_for(cell: UnitCell, tolerance_mm: float) -> tuple[int, float]:
    """The coarsest ``(points_per_section, samples_per_mm)`` whose predicted error stays within ``tolerance_mm``.

    Each knob gets half the tolerance, so their sum (the largest distance between the mesh and the
    smooth yarns) stays within it; for two errors ∝ k⁻² and ∝ h², the even split is also the one
    with the fewest triangles (k × samples). ``points_per_section``: the smallest multiple of 4
    (>= 8) with :func:`section_error_mm` <= tolerance / 2 for the weft and the warp section.
    ``samples_per_mm``: :func:`path_error_mm` = tolerance / 2, solved exactly, on the binders'
    tightest bend (:func:`binder_bend_radius_mm`, the warp's half-height outside it; wefts and
    stuffers are straight), times 1 + 1e-12 against rounding; never coarser than one sample per
    half turn of that bend, nor than one per cell length when no binder bends.
    """
    if not isinstance(cell, UnitCell):
        raise WeaveError(f"cell must be a UnitCell, got {show(cell)}")
    share = _number("tolerance_mm", tolerance_mm) / 2

    def worst(k: int) -> float:
        return max(section_error_mm(cell.weft_section, cell.weft_width, cell.weft_height, k),
                   section_error_mm(cell.warp_section, cell.warp_width, cell.warp_height, k))

    fails, k = 4, 8  # 4 is below the minimum, so counts as failing
    while worst(k) > share:
        fails, k = k, 2 * k
    while k - fails > 4:  # bisect over multiples of 4 (the errors fall monotonically with k)
        mid = (fails + k) // 8 * 4
        fails, k = (fails, mid) if worst(mid) <= share else (mid, k)

    radius, reach = binder_bend_radius_mm(cell), cell.warp_height / 2
    spacing = cell.size[1]
    if radius < math.inf:
        exact = 4.0 * radius * math.asin(math.sqrt(min(1.0, share / (2.0 * (radius + reach)))))
        spacing = min(spacing, math.pi * radius, exact)
    return k, (1.0 + 1e-12) / spacing
