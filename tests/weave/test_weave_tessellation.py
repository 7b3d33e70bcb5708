"""The tessellation-error predictions (xrayraster.weave.tessellation) against independent facts: the
exact section areas and prism volumes, the ruled-solid volume of a tube swept round a circular arc,
analytic chords of the smooth sections, dense outlines of the exact curves (parametrised here by
polar angle or arc angle, not as sections.py does) and the binders' smooth fibres."""

from __future__ import annotations

import math

import numpy as np
import pytest

from xrayraster.core.errors import WeaveError
from xrayraster.weave import Sample, Section, UnitCell
from xrayraster.weave.sample import section_outline
from xrayraster.weave.sections import (
    ellipse_area,
    lenticular_area,
    polygon_area,
    power_ellipse_area,
    rounded_rectangle_area,
)
from xrayraster.weave.sweep import (
    CubicSpline3,
    rotation_minimising_frames,
    sample_path,
    sweep,
    yarn_mesh,
)
from xrayraster.weave.tessellation import (
    area_error_mm2,
    binder_bend_radius_mm,
    edge_sagittas_mm,
    path_error_mm,
    resolution_for,
    section_error_mm,
)

CELL = UnitCell()
W, H = CELL.weft_width, CELL.weft_height  # 2.25 × 0.384 mm
SHAPES = {
    "ellipse": (Section("ellipse"), ellipse_area(W, H)),
    "lenticular": (Section("lenticular"), lenticular_area(W, H)),
    "power_ellipse": (Section("power_ellipse", exponent=3.0), power_ellipse_area(W, H, 3.0)),
    "rounded_rectangle": (Section("rounded_rectangle", corner=0.5), rounded_rectangle_area(W, H, 0.5)),
}


def superellipse_curve(a, b, n, m=2**16):
    """``m`` points on |u/a|^n + |v/b|^n = 1 by polar angle, and their outward unit normals (the gradient)."""
    phi = 2 * np.pi * (np.arange(m) + 0.5) / m
    r = (np.abs(np.cos(phi) / a) ** n + np.abs(np.sin(phi) / b) ** n) ** (-1 / n)
    p = r[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    g = np.sign(p) * np.abs(p) ** (n - 1) / np.array([a**n, b**n])
    return p, g / np.linalg.norm(g, axis=1)[:, None]


def lens_curve(a, b, m=2**16):
    """``m`` points on the lens of half-width a and half-height b (two arcs) and their outward unit normals."""
    radius = (a * a + b * b) / (2 * b)
    alpha = math.atan2(a, radius - b)
    theta = np.pi / 2 + alpha * (2 * (np.arange(m // 2) + 0.5) / (m // 2) - 1)
    n = np.column_stack([np.cos(theta), np.sin(theta)])
    upper = radius * n + [0.0, b - radius]
    return np.concatenate([upper, -upper]), np.concatenate([n, -n])


def crossing_error(polygon, points, normals):
    """Largest distance from a smooth-outline point along its inward normal to the convex polygon."""
    edge = np.roll(polygon, -1, axis=0) - polygon
    out_n = np.column_stack([edge[:, 1], -edge[:, 0]]) / np.linalg.norm(edge, axis=1)[:, None]
    outside = points @ out_n.T - np.einsum("ij,ij->i", out_n, polygon)
    closing = normals @ out_n.T
    with np.errstate(divide="ignore", invalid="ignore"):
        entry = np.where(closing > 0, outside / closing, -np.inf)
    return float(np.maximum(entry.max(axis=1), 0.0).max())


def thickness_chord(section, u):
    """The smooth section's chord along its height at width coordinate u (analytic)."""
    a, b, x = W / 2, H / 2, np.abs(u)
    if section.shape == "ellipse":
        return 2 * b * np.sqrt(1 - (x / a) ** 2)
    if section.shape == "power_ellipse":
        return 2 * b * (1 - (x / a) ** section.exponent) ** (1 / section.exponent)
    if section.shape == "lenticular":
        radius = (a * a + b * b) / (2 * b)
        return 2 * (b - radius + np.sqrt(radius * radius - x * x))
    r = section.corner * min(a, b)
    return np.where(x <= a - r, 2 * b, 2 * (b - r + np.sqrt(np.maximum(r * r - (x - a + r) ** 2, 0))))


def polygon_thickness_chord(polygon, u):
    p, q = polygon, np.roll(polygon, -1, axis=0)
    keep = q[:, 0] != p[:, 0]
    p, q = p[keep], q[keep]
    s = (u[:, None] - p[:, 0]) / (q[:, 0] - p[:, 0])
    v = p[:, 1] + s * (q[:, 1] - p[:, 1])
    hit = (s >= 0) & (s <= 1)
    return np.where(hit, v, -np.inf).max(axis=1) - np.where(hit, v, np.inf).min(axis=1)


def order(x, y):
    return -np.polyfit(np.log(x), np.log(y), 1)[0]


# ------------------------------------------------------------------------------------- sections


@pytest.mark.parametrize("name", SHAPES)
def test_straight_yarn_volume_is_polygon_area_times_length_within_the_derived_bound(name):
    section, area = SHAPES[name]
    length, k = 10.0, 12
    polygon = section_outline(section, W, H, k)
    volume = yarn_mesh([[0.0, 0.0, 0.0], [length, 0.0, 0.0]], polygon, 2.0).volume
    assert volume == pytest.approx(polygon_area(polygon) * length, rel=1e-12)
    chord, depth = edge_sagittas_mm(section, W, H, k)
    # each edge's sliver holds the triangle on its chord (c s / 2) and fits in the strip over it (c s)
    assert 0.5 * np.dot(chord, depth) * length <= area * length - volume <= np.dot(chord, depth) * length


def test_straight_wefts_clipped_in_a_sample_keep_polygon_area_times_length():
    sample = Sample(CELL, points_per_section=12, samples_per_mm=2.0)
    polygon = section_outline(CELL.weft_section, W, H, 12)
    chord, depth = edge_sagittas_mm(CELL.weft_section, W, H, 12)
    length = CELL.size[0]
    wefts = [mesh.volume for yarn, mesh in sample.meshes() if yarn.kind == "weft"]
    assert len(wefts) == 20
    assert np.allclose(wefts, polygon_area(polygon) * length, rtol=1e-12, atol=0)
    loss = power_ellipse_area(W, H, 3.0) * length - np.array(wefts)
    assert np.all((0.5 * np.dot(chord, depth) * length <= loss) & (loss <= np.dot(chord, depth) * length))


@pytest.mark.parametrize("name", SHAPES)
def test_area_error_falls_at_second_order_as_predicted(name):
    section, area = SHAPES[name]
    ks = (16, 32, 64, 128)
    measured = [area - polygon_area(section_outline(section, W, H, k)) for k in ks]
    assert order(ks, measured) == pytest.approx(2.0, abs=0.2)
    for k, loss in zip(ks, measured):  # the stated bounds of the prediction: 3/4 … 3/2 of Σ 2cs/3
        assert 0.75 <= loss / area_error_mm2(section, W, H, k) <= 1.5


@pytest.mark.parametrize("n", [1.5, 2.0, 3.0])
@pytest.mark.parametrize("k", [12, 48])
def test_section_error_is_the_largest_crossing_error_at_normal_incidence(n, k):
    """Rays along the exact outline's normals: the entry into the polygon lags the smooth boundary by
    at most section_error_mm, and the worst of 2^16 such rays comes within 1e-3 of it."""
    points, normals = superellipse_curve(W / 2, H / 2, n)
    section = Section("ellipse") if n == 2 else Section("power_ellipse", exponent=n)
    measured = crossing_error(section_outline(section, W, H, k), points, normals)
    predicted = section_error_mm(section, W, H, k)
    assert measured <= predicted * (1 + 1e-9)
    assert predicted <= 1.001 * measured


@pytest.mark.parametrize("name", SHAPES)
def test_section_error_bounds_the_chords_through_the_middle_of_the_yarn(name):
    """Rays through the thickness over the middle half of the width cross twice at near-normal
    incidence θ: chord error <= 2 section_error / cos θ. The lens and the rounded rectangle, whose
    edges all have one depth, reach the bound; the (super)ellipses' deepest edges are at the sides."""
    section, _ = SHAPES[name]
    k = 24
    u = np.linspace(-W / 4, W / 4, 4001)
    error = thickness_chord(section, u) - polygon_thickness_chord(section_outline(section, W, H, k), u)
    slope = np.abs(np.gradient(thickness_chord(section, u) / 2, u)).max()
    bound = 2 * section_error_mm(section, W, H, k) * math.sqrt(1 + slope**2)  # 2 s / cos θ
    assert error.min() >= -1e-15 and error.max() <= bound
    if name in ("lenticular", "rounded_rectangle"):
        assert error.max() >= 0.95 * bound


# ------------------------------------------------------------------------------------- path


def swept_arc(radius, length, rate, polygon):
    """A tube swept along an exact circular arc in the y-z plane (bending toward +z)."""
    steps = round(length * rate)
    phi = np.linspace(0.0, length / radius, steps + 1)
    points = np.column_stack([np.zeros_like(phi), radius * np.sin(phi), radius * (1 - np.cos(phi))])
    tangents = np.column_stack([np.zeros_like(phi), np.cos(phi), np.sin(phi)])
    vertices, faces = sweep(points, polygon, rotation_minimising_frames(points, tangents))
    volume = np.einsum("ij,ij->i", vertices[faces[:, 0]], np.cross(vertices[faces[:, 1]], vertices[faces[:, 2]])).sum() / 6
    return vertices, volume, steps


def test_arc_tube_volume_is_the_ruled_solid_and_converges_at_second_order():
    """Between two rings at angle θ about the bend's axis, the tube is the ruled solid of the segments
    p -> Rot_θ p: its Jacobian is ρ sin θ, so its volume is A·R·sin θ (centroid at radius R) against
    Pappus's A·R·θ. The outermost fibre's chords (radius R + d) miss their arc by (R + d)(1 − cos θ/2)."""
    radius, length, k = 0.5, 1.0, 12
    polygon = section_outline(CELL.warp_section, CELL.warp_width, CELL.warp_height, k)
    area = polygon_area(polygon)
    rates, errors = (2, 4, 8), []
    for rate in rates:
        vertices, volume, steps = swept_arc(radius, length, rate, polygon)
        theta = length / radius / steps
        assert volume == pytest.approx(area * radius * steps * math.sin(theta), rel=1e-12)
        errors.append(1 - volume / (area * length))
        rings = vertices[: (steps + 1) * k].reshape(steps + 1, k, 3)[:, :, 1:] - [0.0, radius]
        fibre = np.linalg.norm(rings[:-1], axis=2) - np.linalg.norm(0.5 * (rings[:-1] + rings[1:]), axis=2)
        assert fibre.max() == pytest.approx(path_error_mm(radius, rate, CELL.warp_height / 2), rel=1e-9)
    assert order(rates, errors) == pytest.approx(2.0, abs=0.1)


def test_path_error_follows_the_sagitta_law():
    radius, d = 0.5, 0.16
    for rate in (20.0, 40.0):
        h = 1 / rate
        assert path_error_mm(radius, rate, d) == pytest.approx(h * h * (radius + d) / (8 * radius**2), rel=2e-3)
    assert path_error_mm(math.inf, 4.0, d) == 0.0


def test_binder_bend_radius_matches_circles_through_sampled_points():
    """The tightest circle through three consecutive points 1/64 mm apart on the binders, in the cell."""
    smallest = math.inf
    for yarn in Sample(CELL).yarns():
        if yarn.kind == "binder":
            p = sample_path(CubicSpline3(yarn.nodes, yarn.end_tangents), 64.0)[0]
            a, b, c = p[:-2], p[1:-1], p[2:]
            twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
            with np.errstate(divide="ignore"):
                r = (np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - b, axis=1) * np.linalg.norm(c - a, axis=1)
                     / (2 * twice_area))
            inside = (b[:, 1] >= 0) & (b[:, 1] <= CELL.size[1])
            smallest = min(smallest, r[inside].min())
    assert binder_bend_radius_mm(CELL) == pytest.approx(smallest, rel=0.01)


# ------------------------------------------------------------------------------------- resolution_for


def binder_fibre_error(cell, rate):
    """Largest distance from the binders' smooth fibres at ± half the warp height to the swept fibres.

    A binder path is planar (x constant), so its rotation-minimising height axis is the in-plane
    normal (0, −T_z, T_y); the mesh joins the sampled fibre points with straight edges."""
    d, worst = cell.warp_height / 2, 0.0
    for yarn in Sample(cell).yarns():
        if yarn.kind != "binder":
            continue
        spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
        points, tangents, params = sample_path(spline, rate)
        frames = rotation_minimising_frames(points, tangents)
        t = np.linspace(0.0, spline.length_parameter, 32 * len(points))
        p, tangent = spline(t), spline(t, 1)
        normal = np.column_stack([np.zeros_like(t), -tangent[:, 2], tangent[:, 1]]) / np.linalg.norm(tangent, axis=1)[:, None]
        step = np.clip(np.searchsorted(params, t, side="right") - 1, 0, len(params) - 2)
        inside = (p[:, 1] >= 0) & (p[:, 1] <= cell.size[1])
        for side in (1.0, -1.0):
            smooth, mesh = p + side * d * normal, points + side * d * frames[:, 2]
            a, b = mesh[step], mesh[step + 1]
            w = np.clip(np.einsum("ij,ij->i", smooth - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
            worst = max(worst, np.linalg.norm(smooth - a - w[:, None] * (b - a), axis=1)[inside].max())
    return worst


def test_resolution_for_gives_the_coarsest_knobs_within_the_tolerance():
    """Each knob is held to half the tolerance, measured here: the sections' crossing error on dense exact
    outlines of both families, and the binders' fibres against the swept ones; one step coarser fails."""
    tolerance = 0.01
    k, rate = resolution_for(CELL, tolerance)
    assert k >= 8 and k % 4 == 0

    weft = superellipse_curve(W / 2, H / 2, 3.0)
    warp = lens_curve(CELL.warp_width / 2, CELL.warp_height / 2)

    def section_measured(kk):
        return max(crossing_error(section_outline(CELL.weft_section, W, H, kk), *weft),
                   crossing_error(section_outline(CELL.warp_section, CELL.warp_width, CELL.warp_height, kk), *warp))

    assert section_measured(k) <= tolerance / 2 < section_measured(k - 4)
    # sample_path rounds the sample count up, so a coarser rate is measured 10 % coarser, not 1e-12
    assert binder_fibre_error(CELL, rate) <= tolerance / 2 < binder_fibre_error(CELL, 0.9 * rate)
    assert path_error_mm(binder_bend_radius_mm(CELL), rate, CELL.warp_height / 2) <= tolerance / 2
    assert path_error_mm(binder_bend_radius_mm(CELL), rate * (1 - 1e-9), CELL.warp_height / 2) > tolerance / 2


def test_resolution_for_straight_binders_needs_one_sample_per_cell_length():
    flat = UnitCell(binder_path=tuple((b // 4 + 1,) * 4 for b in range(16)))
    assert binder_bend_radius_mm(flat) > 1e9
    k, rate = resolution_for(flat, 0.01)
    assert k == resolution_for(CELL, 0.01)[0]
    assert rate == pytest.approx(1 / flat.size[1], rel=1e-11)


# ------------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("call, field", [
    (lambda: section_error_mm(Section("ellipse"), W, H, 10), "points_per_section"),
    (lambda: section_error_mm(Section("ellipse"), W, H, 4), "points_per_section"),
    (lambda: section_error_mm(Section("ellipse"), -1.0, H, 12), "width"),
    (lambda: section_error_mm("ellipse", W, H, 12), "section must be a Section"),
    (lambda: section_error_mm(Section("power_ellipse"), W, H, 12), "exponent"),
    (lambda: section_error_mm(Section("power_ellipse", exponent=0.5), W, H, 12), "exponent"),
    (lambda: path_error_mm(0.1, 4.0, 0.16), "min_bend_radius_mm"),
    (lambda: path_error_mm(0.5, 0.0, 0.16), "samples_per_mm"),
    (lambda: path_error_mm(0.5, 0.5, 0.16), "samples_per_mm"),
    (lambda: path_error_mm(0.5, 4.0, -0.1), "half_extent_mm"),
    (lambda: resolution_for(CELL, 0.0), "tolerance_mm"),
    (lambda: resolution_for(CELL, float("nan")), "tolerance_mm"),
    (lambda: resolution_for(CELL, "0.01"), "tolerance_mm"),
    (lambda: resolution_for({}, 0.01), "cell"),
])
def test_bad_input_names_the_field(call, field):
    with pytest.raises(WeaveError, match=field):
        call()
