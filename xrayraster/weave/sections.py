"""Yarn cross-sections: closed 2-D outlines in mm and the exact areas of the smooth shapes.

Each outline is ``(k, 2)`` float64 points, counter-clockwise, centred on the origin, in the
section plane's ``(u, v)`` axes (``u`` along the yarn's width, ``v`` along its height); each is
convex or star-shaped about the origin, which :func:`xrayraster.weave.sweep.sweep` relies on to cap
the ends. The ``*_area`` functions give the smooth shape's area, so tessellation error can be measured.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import WeaveError

__all__ = ["polygon_area", "ellipse", "ellipse_area", "lenticular", "lenticular_area", "power_ellipse", "power_ellipse_area", "rounded_rectangle", "rounded_rectangle_area"]


def _check_size(name: str, value) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise WeaveError(f"{name} must be a positive number of mm, got {value!r}")
    return value


def _check_k(k, minimum: int = 3, multiple: int = 1) -> int:
    if isinstance(k, bool) or int(k) != k or k < minimum or k % multiple:
        extra = f" and a multiple of {multiple}" if multiple > 1 else ""
        raise WeaveError(f"k (points per cross-section) must be an integer >= {minimum}{extra}, got {k!r}")
    return int(k)


def polygon_area(outline) -> float:
    """Signed area (shoelace) of a closed 2-D outline, mm²; positive when counter-clockwise."""
    p = np.asarray(outline, dtype=np.float64)
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


def polygon_centroid(p: np.ndarray) -> np.ndarray:
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


def ellipse(width: float, height: float, k: int = 32) -> np.ndarray:
    """``k`` points on the ellipse of full ``width`` (along u) and ``height`` (along v), mm; CCW."""
    a, b = _check_size("width", width) / 2, _check_size("height", height) / 2
    t = 2.0 * np.pi * np.arange(_check_k(k)) / k
    return np.column_stack([a * np.cos(t), b * np.sin(t)])


def ellipse_area(width: float, height: float) -> float:
    """Exact area of the smooth ellipse, mm²: π·(width/2)·(height/2)."""
    return math.pi * width * height / 4.0


def lens_arc(width: float, height: float) -> tuple[float, float]:
    """Radius and half-angle of each of the lens's two arcs (a = half-width, h = half-height)."""
    a, h = width / 2, height / 2
    radius = (a * a + h * h) / (2 * h)
    return radius, math.atan2(a, radius - h)


def lenticular(width: float, height: float, k: int = 32) -> np.ndarray:
    """``k`` points (even) on a lens: two equal circular arcs meeting in corners at (±width/2, 0).

    The upper arc passes through (0, height/2), the lower through (0, -height/2); ``height`` may
    not exceed ``width`` (equal gives a circle). Each arc gets ``k/2`` points, corners included.
    """
    width, height = _check_size("width", width), _check_size("height", height)
    if height > width:
        raise WeaveError(f"lenticular: height ({height} mm) may not exceed width ({width} mm); "
                         "a lens taller than wide is not two arcs meeting at the sides")
    k = _check_k(k, minimum=4, multiple=2)
    radius, alpha = lens_arc(width, height)
    h = height / 2
    theta = np.pi / 2 - alpha + 2 * alpha * np.arange(k // 2) / (k // 2)
    upper = np.column_stack([radius * np.cos(theta), h - radius + radius * np.sin(theta)])
    return np.concatenate([upper, -upper])  # the lower arc is the upper one turned by 180°


def lenticular_area(width: float, height: float) -> float:
    """Exact area of the lens, mm²: two circular segments, each R²·α − a·(R − h)."""
    radius, alpha = lens_arc(width, height)
    return 2.0 * (radius * radius * alpha - (width / 2) * (radius - height / 2))


def power_ellipse(width: float, height: float, exponent: float, k: int = 32) -> np.ndarray:
    """``k`` points on |u/a|^n + |v/b|^n = 1 (a = width/2, b = height/2, n = ``exponent``); CCW.

    n = 2 is the ellipse, n > 2 squarer, 1 < n < 2 pointed at the ends of the axes, n < 1 concave
    (still star-shaped about the centre). Points at u = a·sgn(cos t)|cos t|^(2/n),
    v = b·sgn(sin t)|sin t|^(2/n) for t uniform in [0, 2π). This is not TexGen's "power ellipse"
    (which raises only the v coordinate to a power).
    """
    a, b = _check_size("width", width) / 2, _check_size("height", height) / 2
    n = float(exponent)
    if not (math.isfinite(n) and n > 0):
        raise WeaveError(f"power_ellipse: exponent must be a positive number, got {exponent!r}")
    t = 2.0 * np.pi * np.arange(_check_k(k, minimum=4)) / k
    c, s = np.cos(t), np.sin(t)
    c[np.abs(c) < 1e-15] = 0.0  # cos(pi/2) is 6e-17, whose (2/n)th power is not small
    s[np.abs(s) < 1e-15] = 0.0
    return np.column_stack([a * np.sign(c) * np.abs(c) ** (2 / n), b * np.sign(s) * np.abs(s) ** (2 / n)])


def power_ellipse_area(width: float, height: float, exponent: float) -> float:
    """Exact area of the superellipse, mm²: 4ab·Γ(1 + 1/n)² / Γ(1 + 2/n)."""
    n = float(exponent)
    return width * height * math.gamma(1 + 1 / n) ** 2 / math.gamma(1 + 2 / n)


def corner_radius(width: float, height: float, corner_fraction: float) -> float:
    """The rounded rectangle's corner radius, mm: ``corner_fraction`` of half the smaller side."""
    f = float(corner_fraction)
    if not (math.isfinite(f) and 0 < f <= 1):
        raise WeaveError(f"rounded_rectangle: corner_fraction must be in (0, 1], got {corner_fraction!r} "
                         "(the corner radius as a fraction of half the smaller side)")
    return f * min(width, height) / 2


def rounded_rectangle(width: float, height: float, corner_fraction: float, k: int = 32) -> np.ndarray:
    """``k`` points (a multiple of 4) on a rectangle with quarter-circle corners; CCW.

    The corner radius is ``corner_fraction`` × half the smaller side (1 gives a stadium, or a
    circle when width = height). Each corner arc gets k/4 points at the midpoints of k/4 equal
    angular steps, so no two points coincide even when a straight side has zero length; the
    straight sides are single chords (they are exact).
    """
    width, height = _check_size("width", width), _check_size("height", height)
    r = corner_radius(width, height, corner_fraction)
    q = _check_k(k, minimum=4, multiple=4) // 4
    cx, cy = width / 2 - r, height / 2 - r
    step = (np.pi / 2) / q
    parts = []
    for corner, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        theta = corner * np.pi / 2 + (np.arange(q) + 0.5) * step
        parts.append(np.column_stack([sx * cx + r * np.cos(theta), sy * cy + r * np.sin(theta)]))
    return np.concatenate(parts)


def rounded_rectangle_area(width: float, height: float, corner_fraction: float) -> float:
    """Exact area of the smooth rounded rectangle, mm²: width·height − (4 − π)·r²."""
    r = corner_radius(width, height, corner_fraction)
    return width * height - (4 - math.pi) * r * r
