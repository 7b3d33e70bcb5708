"""The yarn mesher (xrayraster.weave.sweep) against independent facts: closed-form section areas and
polygon convergence theory, exact prism volumes, Pappus, the helix's torsion, SciPy's spline, and
trimesh's and manifold3d's own checks of every mesh."""

from __future__ import annotations

import math

import manifold3d
import numpy as np
import pytest
import trimesh

from references.solids import solid
from xrayraster.core.errors import WeaveError, XrayrasterError
from xrayraster.weave.sweep import (
    CubicSpline3,
    adaptive_params,
    ellipse,
    ellipse_area,
    lenticular,
    lenticular_area,
    polygon_area,
    power_ellipse,
    power_ellipse_area,
    rotation_minimising_frames,
    rounded_rectangle,
    rounded_rectangle_area,
    sample_path,
    section_outlines,
    smooth_profile,
    sweep,
    yarn_mesh,
)

SECTIONS = {
    "ellipse": (lambda k: ellipse(2.0, 0.8, k), ellipse_area(2.0, 0.8)),
    "lenticular": (lambda k: lenticular(2.0, 0.6, k), lenticular_area(2.0, 0.6)),
    "power_ellipse_n4": (lambda k: power_ellipse(2.0, 0.8, 4.0, k), power_ellipse_area(2.0, 0.8, 4.0)),
    "power_ellipse_n1.5": (lambda k: power_ellipse(2.0, 0.8, 1.5, k), power_ellipse_area(2.0, 0.8, 1.5)),
    "rounded_rectangle": (lambda k: rounded_rectangle(2.0, 0.8, 0.5, k), rounded_rectangle_area(2.0, 0.8, 0.5)),
    "stadium": (lambda k: rounded_rectangle(2.0, 0.8, 1.0, k), rounded_rectangle_area(2.0, 0.8, 1.0)),
}


def check_closed_mesh(vertices, faces):
    """Watertight, consistently wound, outward (positive volume), no degenerate triangles; manifold3d agrees."""
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0
    assert np.all(mesh.area_faces > 0)
    s = solid(mesh)
    assert s.status() == manifold3d.Error.NoError
    assert s.volume() == pytest.approx(mesh.volume, rel=1e-9)
    return mesh


# ---------------------------------------------------------------------------- cross-sections


def test_closed_form_areas_against_independent_formulas():
    # power ellipse with n = 2 is the ellipse; n = 1 is the rhombus (area 2ab).
    assert power_ellipse_area(2.0, 0.8, 2.0) == pytest.approx(ellipse_area(2.0, 0.8), rel=1e-14)
    assert power_ellipse_area(2.0, 0.8, 1.0) == pytest.approx(2 * 1.0 * 0.4, rel=1e-14)
    # a lens as tall as wide is the circle; the stadium 2 x 0.8 is a 1.2 x 0.8 box plus a disc of radius 0.4
    assert lenticular_area(1.0, 1.0) == pytest.approx(math.pi / 4, rel=1e-14)
    assert rounded_rectangle_area(2.0, 0.8, 1.0) == pytest.approx(1.2 * 0.8 + math.pi * 0.16, rel=1e-14)
    # the lens by numerical integration of its upper arc
    x = np.linspace(-1.0, 1.0, 200001)
    radius = (1.0 + 0.09) / 0.6
    upper = np.sqrt(radius**2 - x**2) - (radius - 0.3)
    assert 2 * np.trapezoid(upper, x) == pytest.approx(lenticular_area(2.0, 0.6), rel=1e-9)


@pytest.mark.parametrize("name", SECTIONS)
def test_outline_is_ccw_centred_and_on_its_curve(name):
    make, area = SECTIONS[name]
    p = make(32)
    assert p.shape == (32, 2) and p.dtype == np.float64
    assert polygon_area(p) > 0
    assert np.allclose(p.mean(axis=0), 0.0, atol=1e-12)
    assert 0 < polygon_area(p) < area  # inscribed in a convex shape: polygon smaller


def test_points_lie_on_their_curves():
    p = power_ellipse(2.0, 0.8, 3.0, 40)
    assert np.allclose(np.abs(p[:, 0] / 1.0) ** 3 + np.abs(p[:, 1] / 0.4) ** 3, 1.0, atol=1e-12)
    p = ellipse(2.0, 0.8, 40)
    assert np.allclose((p[:, 0] / 1.0) ** 2 + (p[:, 1] / 0.4) ** 2, 1.0, atol=1e-12)
    p = lenticular(2.0, 0.6, 40)
    radius = (1.0 + 0.09) / 0.6
    centre = np.where(p[:, 1:2] >= 0, [0.0, 0.3 - radius], [0.0, radius - 0.3])
    assert np.allclose(np.linalg.norm(p - centre, axis=1), radius, atol=1e-12)
    assert np.any(np.all(np.isclose(p, [1.0, 0.0]), axis=1)) and np.any(np.all(np.isclose(p, [-1.0, 0.0]), axis=1))


@pytest.mark.parametrize("name", SECTIONS)
def test_polygon_area_converges_at_second_order(name):
    """An inscribed polygon of a piecewise-smooth curve misses O(h^2) of the area: doubling k quarters it."""
    make, area = SECTIONS[name]
    errors = [abs(area - polygon_area(make(k))) for k in (32, 64, 128, 256)]
    ratios = [errors[i] / errors[i + 1] for i in range(3)]
    assert all(3.5 < r < 4.5 for r in ratios), ratios
    assert errors[-1] / area < 2e-4


def test_bad_sections_name_the_argument():
    with pytest.raises(WeaveError, match="width"):
        ellipse(-1.0, 1.0)
    with pytest.raises(WeaveError, match="height"):
        lenticular(1.0, 2.0)
    with pytest.raises(WeaveError, match="exponent"):
        power_ellipse(1.0, 1.0, 0.0)
    with pytest.raises(WeaveError, match="corner_fraction"):
        rounded_rectangle(1.0, 1.0, 0.0)
    with pytest.raises(WeaveError, match="multiple of 4"):
        rounded_rectangle(1.0, 1.0, 0.5, 30)
    with pytest.raises(XrayrasterError):
        ellipse(1.0, 1.0, 2)
    with pytest.raises(ValueError):
        lenticular(1.0, 0.5, 7)


# ---------------------------------------------------------------------------- spline


def wavy_nodes():
    x = np.linspace(0.0, 10.0, 9)
    return np.column_stack([x, 0.6 * np.sin(0.9 * x), 0.4 * np.cos(1.3 * x)])


@pytest.mark.parametrize("end_tangents", [None, ((1.0, 0.0, 0.0), (0.6, 0.8, 0.0))])
def test_spline_interpolates_and_is_c2(end_tangents):
    nodes = wavy_nodes()
    spline = CubicSpline3(nodes, end_tangents)
    assert np.allclose(spline(spline.knots), nodes, atol=1e-12)
    h = 1e-4
    inner = spline.knots[1:-1]
    for derivative in (0, 1, 2):  # value, slope and curvature match from both sides of every inner knot
        left = spline(inner - h, derivative)
        right = spline(inner + h, derivative)
        assert np.allclose(left, right, atol=5e-3), derivative
    # numerically: second differences just left and just right of each knot agree to O(h)
    d = 1e-3
    second_left = (spline(inner, 0) - 2 * spline(inner - d, 0) + spline(inner - 2 * d, 0)) / d**2
    second_right = (spline(inner + 2 * d, 0) - 2 * spline(inner + d, 0) + spline(inner, 0)) / d**2
    assert np.allclose(second_left, second_right, atol=0.05)
    # the third derivative does jump (it is a cubic spline, not a polynomial)
    third = np.diff(spline.second, axis=0) / np.diff(spline.knots)[:, None]
    assert np.max(np.abs(np.diff(third, axis=0))) > 1e-3
    if end_tangents is None:
        assert np.allclose(spline(spline.knots[[0, -1]], 2), 0.0, atol=1e-12)
    else:
        assert np.allclose(spline(spline.knots[[0, -1]], 1), np.array(end_tangents), atol=1e-12)


@pytest.mark.parametrize("bc", ["natural", "clamped"])
def test_spline_matches_scipy(bc):
    interpolate = pytest.importorskip("scipy.interpolate")
    nodes = wavy_nodes()
    ends = ((1.0, 0.0, 0.0), (0.6, 0.8, 0.0))
    spline = CubicSpline3(nodes, None if bc == "natural" else ends)
    reference = interpolate.CubicSpline(spline.knots, nodes, bc_type="natural" if bc == "natural" else
                                        ((1, np.array(ends[0])), (1, np.array(ends[1]))))
    t = np.linspace(0.0, spline.knots[-1], 1001)
    for derivative in (0, 1, 2):
        assert np.allclose(spline(t, derivative), reference(t, derivative), atol=1e-10)


def test_sampling_is_uniform_along_arc_length():
    spline = CubicSpline3(wavy_nodes())
    points, tangents, params = sample_path(spline, 8.0)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    length = steps.sum()
    assert len(points) - 1 == math.ceil(length * 8.0 - 1e-6) or len(points) - 1 == math.ceil(length * 8.0)
    assert np.ptp(steps) / steps.mean() < 1e-3
    assert np.allclose(points, spline(params), atol=0)
    assert np.allclose(points[[0, -1]], wavy_nodes()[[0, -1]], atol=1e-12)
    assert np.allclose(np.linalg.norm(tangents, axis=1), 1.0, atol=1e-14)


def test_spline_refuses_repeated_nodes():
    with pytest.raises(WeaveError, match="coincide"):
        CubicSpline3([[0, 0, 0], [1, 0, 0], [1, 0, 0]])


# ---------------------------------------------------------------------------- frames


def helix(n, a=2.0, c=0.5, turns=3.0):
    t = np.linspace(0.0, 2 * np.pi * turns, n)
    points = np.column_stack([a * np.cos(t), a * np.sin(t), c * t])
    tangents = np.column_stack([-a * np.sin(t), a * np.cos(t), np.full(n, c)]) / math.hypot(a, c)
    return t, points, tangents


def test_rmf_on_a_helix_is_orthonormal_and_turns_against_the_frenet_frame_by_the_torsion():
    a, c = 2.0, 0.5
    t, points, tangents = helix(4001, a, c)
    frames = rotation_minimising_frames(points, tangents, up=None)
    gram = np.einsum("nij,nkj->nik", frames, frames)
    assert np.max(np.abs(gram - np.eye(3))) < 1e-12
    assert np.allclose(np.linalg.det(frames), 1.0, atol=1e-12)
    # An RMF normal r = cos(th) N + sin(th) B obeys th' = -torsion along arc length (r' parallel to T).
    speed = math.hypot(a, c)
    torsion = c / (a * a + c * c)
    s = t * speed
    frenet_n = np.column_stack([-np.cos(t), -np.sin(t), np.zeros_like(t)])
    frenet_b = np.column_stack([c * np.sin(t), -c * np.cos(t), np.full_like(t, a)]) / speed
    theta = np.unwrap(np.arctan2(np.einsum("ij,ij->i", frames[:, 2], frenet_b),
                                 np.einsum("ij,ij->i", frames[:, 2], frenet_n)))
    assert np.allclose(theta - theta[0], -torsion * s, atol=1e-6)


def test_rmf_has_no_twist_along_a_planar_curve():
    theta = np.linspace(0.0, 1.5 * np.pi, 300)
    points = np.column_stack([3 * np.cos(theta) + theta, 2 * np.sin(theta), np.zeros_like(theta)])
    spline_t = np.column_stack([-3 * np.sin(theta) + 1, 2 * np.cos(theta), np.zeros_like(theta)])
    frames = rotation_minimising_frames(points, spline_t, up=(0.0, 0.0, 1.0))
    assert np.max(np.abs(frames[:, 2] - [0.0, 0.0, 1.0])) < 1e-12  # height axis stays +z: zero twist
    gram = np.einsum("nij,nkj->nik", frames, frames)
    assert np.max(np.abs(gram - np.eye(3))) < 1e-12


def test_up_starts_the_height_axis_and_must_cross_the_path():
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.3]])
    tangents = np.array([[1.0, 0.0, 0.3], [1.0, 0.0, 0.3]])
    frames = rotation_minimising_frames(points, tangents, up=(0, 0, 1))
    assert frames[0, 2, 2] > 0.95 and abs(frames[0, 2, 1]) < 1e-15
    with pytest.raises(WeaveError, match="parallel"):
        rotation_minimising_frames(points, [[0, 0, 1.0], [0, 0, 1.0]], up=(0, 0, 2))


# ---------------------------------------------------------------------------- sweep


@pytest.mark.parametrize("name", SECTIONS)
def test_straight_yarn_volume_is_prism_exact(name):
    make, smooth_area = SECTIONS[name]
    outline = make(24)
    nodes = np.array([[0.0, 0.0, 0.0], [2.5, 1.0, 0.5], [4.0, 1.6, 0.8], [10.0, 4.0, 2.0]])  # collinear, uneven
    length = float(np.linalg.norm(nodes[-1] - nodes[0]))
    mesh = yarn_mesh(nodes, outline, samples_per_mm=3.0)
    check_closed_mesh(mesh.vertices, mesh.faces)
    polygon = polygon_area(outline)
    assert mesh.volume == pytest.approx(polygon * length, rel=1e-9)
    # against the smooth section: off by exactly the polygon's area error, nothing more
    assert abs(mesh.volume - smooth_area * length) <= (smooth_area - polygon) * length * (1 + 1e-9)


def test_curved_yarn_is_closed_and_its_volume_obeys_pappus():
    """A section swept round a planar arc of radius R through angle phi encloses A R phi (Pappus)."""
    radius, phi, n = 5.0, 1.2 * np.pi, 400
    t = np.linspace(0.0, phi, n)
    points = np.column_stack([radius * np.cos(t), radius * np.sin(t), np.zeros(n)])
    tangents = np.column_stack([-np.sin(t), np.cos(t), np.zeros(n)])
    outline = lenticular(2.0, 0.6, 32)
    frames = rotation_minimising_frames(points, tangents)
    vertices, faces = sweep(points, outline, frames)
    mesh = check_closed_mesh(vertices, faces)
    # the faceted bend (sections joined across chords of n - 1 equal steps) scales Pappus by sin(d)/d,
    # d = phi / (n - 1); measured exact to rounding
    d = phi / (n - 1)
    expected = polygon_area(outline) * radius * phi * math.sin(d) / d
    assert mesh.volume == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("make", [lambda: ellipse(1.2, 0.5, 20), lambda: power_ellipse(1.2, 0.5, 0.8, 24),
                                  lambda: rounded_rectangle(1.2, 0.5, 1.0, 16)])
def test_wavy_yarn_is_closed_manifold_and_outward(make):
    mesh = yarn_mesh(wavy_nodes(), make(), samples_per_mm=6.0)
    check_closed_mesh(mesh.vertices, mesh.faces)
    assert len(mesh.vertices) == len(mesh.faces) // 2 + 2  # a genus-0 triangle surface: V = F/2 + 2


def rings_in_order(vertices, frames, points, k):
    """Every section lies strictly ahead of the previous section's plane: neighbouring sections do not cross."""
    rings = vertices[: len(points) * k].reshape(len(points), k, 3)
    ahead = np.einsum("nkj,nj->nk", rings[1:] - points[:-1, None], frames[:-1, 0])
    behind = np.einsum("nkj,nj->nk", rings[:-1] - points[1:, None], frames[1:, 0])
    return bool(np.all(ahead > 0) and np.all(behind < 0))


def test_sharp_bend_within_the_limit_does_not_self_intersect_and_beyond_it_is_refused():
    half_width = 1.0
    outline = ellipse(2 * half_width, 0.5, 32)
    for radius, ok in ((1.05 * half_width, True), (0.9 * half_width, False)):
        t = np.linspace(0.0, np.pi / 2, 60)
        points = np.column_stack([radius * np.cos(t), radius * np.sin(t), np.zeros_like(t)])
        tangents = np.column_stack([-np.sin(t), np.cos(t), np.zeros_like(t)])
        frames = rotation_minimising_frames(points, tangents)  # width axis lies in the bend's plane
        if ok:
            vertices, faces = sweep(points, outline, frames)
            check_closed_mesh(vertices, faces)
            assert rings_in_order(vertices, frames, points, len(outline))
        else:
            with pytest.raises(WeaveError, match="bend radius must exceed the section's half-width"):
                sweep(points, outline, frames)
    # the same bend turned on edge: only the half-height (0.25 mm) must fit inside the radius
    points = np.column_stack([0.9 * np.cos(t), np.zeros_like(t), 0.9 * np.sin(t)])
    tangents = np.column_stack([-np.sin(t), np.zeros_like(t), np.cos(t)])
    frames = rotation_minimising_frames(points, tangents, up=(-1.0, 0.0, 0.0))
    vertices, faces = sweep(points, outline, frames)
    check_closed_mesh(vertices, faces)
    assert rings_in_order(vertices, frames, points, len(outline))


def test_spline_yarn_through_a_tight_corner_is_refused_by_name():
    nodes = np.array([[0.0, 0, 0], [2.0, 0, 0], [2.0, 2.0, 0]])  # the natural spline's tightest radius: 0.47 mm
    with pytest.raises(WeaveError, match=r"bends with radius .* mm"):
        yarn_mesh(nodes, ellipse(2.0, 0.4, 16), samples_per_mm=10.0)
    narrow = yarn_mesh(nodes, ellipse(0.8, 0.4, 16), samples_per_mm=10.0)  # half-width 0.4 mm fits the bend
    check_closed_mesh(narrow.vertices, narrow.faces)


def test_sweep_refuses_bad_inputs():
    points = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    frames = rotation_minimising_frames(points, [[1.0, 0, 0], [1.0, 0, 0]])
    with pytest.raises(WeaveError, match="counter-clockwise"):
        sweep(points, ellipse(1.0, 0.5, 12)[::-1], frames)
    with pytest.raises(WeaveError, match="frames"):
        sweep(points, ellipse(1.0, 0.5, 12), frames[:1])
    star = np.array([[1.0, 0], [0.1, 0.1], [0, 1], [-1, 0], [0.3, -0.05], [0, -1]])
    assert polygon_area(star) > 0
    with pytest.raises(WeaveError, match="star-shaped"):
        sweep(points, star, frames)
    with pytest.raises(WeaveError, match="degenerate"):
        sweep(np.array([[0.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0]]), ellipse(1.0, 0.5, 12),
              np.repeat(frames[:1], 3, axis=0))


# ---------------------------------------------------------------------------- varying sections


def test_smooth_profile_is_the_smootherstep_between_knots_and_never_overshoots():
    knots = np.array([0.0, 0.7, 1.0, 2.6, 3.0])
    values = np.array([[1.0, 0.2], [0.9, -0.4], [1.1, 0.1], [0.95, 0.0], [1.05, 0.3]])
    t = np.linspace(0.0, 3.0, 3001)
    got = smooth_profile(knots, values, t)
    assert np.allclose(smooth_profile(knots, values, knots), values, atol=1e-15)
    i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, 3)
    tau = (t - knots[i]) / (knots[i + 1] - knots[i])
    step = 6 * tau**5 - 15 * tau**4 + 10 * tau**3                # Perlin's smootherstep, expanded
    assert np.allclose(got, values[i] + (values[i + 1] - values[i]) * step[:, None], atol=1e-14)
    lo, hi = np.minimum(values[i], values[i + 1]), np.maximum(values[i], values[i + 1])
    assert np.all(got >= lo - 1e-15) and np.all(got <= hi + 1e-15)
    # C²: first and second derivatives vanish on both sides of every knot, so they match there. The
    # one-sided differences are O(h²) and O(h) (under 2e-6 and 0.12 here); a C¹ step such as
    # 3τ² − 2τ³ would leave a second derivative of 6 Δv / L² (over 30 here)
    h = 1e-4
    for knot in knots[1:-1]:
        for side in (smooth_profile(knots, values, knot - np.array([0.0, h, 2 * h])),
                     smooth_profile(knots, values, knot + np.array([0.0, h, 2 * h]))):
            assert np.all(np.abs(side[1] - side[0]) / h < 1e-5)
            assert np.all(np.abs(side[2] - 2 * side[1] + side[0]) / h**2 < 1.0)


def test_a_section_growing_along_a_straight_yarn_is_a_frustum():
    """Outlines scaled by 1 + x/L along x are similar about the apex x = -L: the tube is a pyramid
    frustum, V = L/3 (A0 + A1 + sqrt(A0 A1)) = 7/3 L A0 for A1 = 4 A0, exactly."""
    length, n = 4.0, 9
    x = np.linspace(0.0, length, n)
    points = np.column_stack([x, np.zeros(n), np.zeros(n)])
    frames = rotation_minimising_frames(points, np.tile([1.0, 0.0, 0.0], (n, 1)))
    outline = ellipse(2.0, 1.0, 24)
    scale = np.repeat((1 + x / length)[:, None], 2, axis=1)
    vertices, faces = sweep(points, section_outlines(outline, scale, np.zeros(n)), frames)
    mesh = check_closed_mesh(vertices, faces)
    assert mesh.volume == pytest.approx(7 / 3 * length * polygon_area(outline), rel=1e-12)


def test_section_outlines_scale_then_turn_about_the_origin():
    outline = np.array([[1.0, 0.0], [0.0, 0.5], [-1.0, 0.0], [0.0, -0.5]])
    got = section_outlines(outline, [[2.0, 3.0]], [90.0])
    assert np.allclose(got[0], [[0.0, 2.0], [-1.5, 0.0], [0.0, -2.0], [1.5, 0.0]], atol=1e-15)


def test_a_constant_profile_is_the_plain_sweep_bit_for_bit_and_a_varying_one_is_closed():
    nodes = wavy_nodes()
    outline = power_ellipse(1.2, 0.5, 3.0, 16)
    plain = yarn_mesh(nodes, outline, 4.0)
    same = yarn_mesh(nodes, outline, 4.0, section_scale=np.ones((9, 2)), section_rotation_deg=np.zeros(9))
    assert plain.vertices.tobytes() == same.vertices.tobytes() and np.array_equal(plain.faces, same.faces)
    rng = np.random.default_rng(0)
    varied = yarn_mesh(nodes, outline, 4.0, section_scale=1 + 0.2 * rng.uniform(-1, 1, (9, 2)),
                       section_rotation_deg=rng.uniform(-20, 20, 9))
    check_closed_mesh(varied.vertices, varied.faces)
    with pytest.raises(WeaveError, match="give both"):
        yarn_mesh(nodes, outline, 4.0, section_scale=np.ones((9, 2)))
    with pytest.raises(WeaveError, match=r"\(9, 2\)"):
        yarn_mesh(nodes, outline, 4.0, section_scale=np.ones((8, 2)), section_rotation_deg=np.zeros(8))
    with pytest.raises(WeaveError, match="positive"):
        yarn_mesh(nodes, outline, 4.0, section_scale=np.zeros((9, 2)), section_rotation_deg=np.zeros(9))


def test_the_bend_limit_uses_each_samples_own_section():
    half_width = 1.0
    t = np.linspace(0.0, np.pi / 2, 60)
    radius = 0.9 * half_width                                 # too tight for the full section, fine at 0.8
    points = np.column_stack([radius * np.cos(t), radius * np.sin(t), np.zeros_like(t)])
    frames = rotation_minimising_frames(points, np.column_stack([-np.sin(t), np.cos(t), np.zeros_like(t)]))
    outline = ellipse(2 * half_width, 0.5, 32)
    scale = np.full((60, 2), 0.8)
    vertices, faces = sweep(points, section_outlines(outline, scale, np.zeros(60)), frames)
    check_closed_mesh(vertices, faces)
    scale[30] = 1.0                                           # one full-size section in the bend
    with pytest.raises(WeaveError, match="bend radius must exceed"):
        sweep(points, section_outlines(outline, scale, np.zeros(60)), frames)
    with pytest.raises(WeaveError, match=r"\(n, k, 2\) with n = 60"):
        sweep(points, section_outlines(outline, scale[:59], np.zeros(59)), frames)


def test_within_trims_the_tube_outside_the_box_to_the_same_clipped_solid():
    nodes, outline = wavy_nodes(), ellipse(1.2, 0.5, 16)
    box = np.array([[2.0, -5.0, -5.0], [8.0, 5.0, 5.0]])
    clip = manifold3d.Manifold.cube((6.0, 10.0, 10.0)).translate((2.0, -5.0, -5.0))

    def clipped(mesh):
        return (solid(mesh) ^ clip).volume()

    full = yarn_mesh(nodes, outline, 8.0)
    trimmed = yarn_mesh(nodes, outline, 8.0, within=box)
    check_closed_mesh(trimmed.vertices, trimmed.faces)
    assert len(trimmed.faces) < 0.75 * len(full.faces)           # 4 of the 10 mm lie outside
    assert clipped(trimmed) == pytest.approx(clipped(full), rel=1e-12)
    rings = trimmed.vertices[:-2].reshape(-1, 16, 3)
    assert rings[0, :, 0].max() < 2.0 and rings[1, :, 0].max() >= 2.0        # one ring kept beyond each end face
    assert rings[-1, :, 0].min() > 8.0 and rings[-2, :, 0].min() <= 8.0
    away = yarn_mesh(nodes, outline, 8.0, within=box + [[0, 20, 0], [0, 20, 0]])   # never meets the box
    assert len(away.faces) == len(full.faces)


def _chord_misses(spline, params, outline, scale=None, angle=None, per_interval=64):
    """Largest distance (mm) from any fibre of the smooth tube to the straight chord between the two
    rings around it, measured point by point on a dense resampling (not from the p''/8 rule)."""
    def fibres(t):
        points, tangents = spline(t), spline(t, 1)
        frames = rotation_minimising_frames(points, tangents)
        shape = outline if scale is None else section_outlines(outline, smooth_profile(spline.knots, scale, t),
                                                                smooth_profile(spline.knots, angle, t))
        return points[:, None] + shape[..., :1] * frames[:, None, 1] + shape[..., 1:] * frames[:, None, 2]

    fraction = np.linspace(0.0, 1.0, per_interval + 1)
    dense = params[:-1, None] + (params[1:] - params[:-1])[:, None] * fraction  # (intervals, per + 1)
    curve = fibres(dense.ravel()).reshape(*dense.shape, -1, 3)  # (intervals, per + 1, k, 3)
    a, b = curve[:, :1], curve[:, -1:]  # the rings: dense fibres start and end on them
    ab = b - a
    along = np.clip(np.sum((curve - a) * ab, axis=-1) / np.sum(ab * ab, axis=-1), 0.0, 1.0)
    return float(np.linalg.norm(curve - a - along[..., None] * ab, axis=-1).max())


@pytest.mark.parametrize("varying", [False, True])
def test_adaptive_samples_hold_the_chord_error_with_fewer_rings(varying):
    """A path that runs straight, bends over a 1.5 mm hump and runs straight again (a binder's
    shape), with a constant or a growing-and-turning section: every chord misses its fibre by at
    most the asked sagitta (leading order: within 10 %), the worst by more than half of it (no
    wasted rings), and as many uniform rings miss by over 3 times as much (measured: 4.9 times)."""
    nodes = np.array([[0.0, 0, 0], [4, 0, 0], [6, 0, 0], [7, 0, 0.6], [8, 0, 0.6], [9, 0, 0], [11, 0, 0], [15, 0, 0]])
    spline = CubicSpline3(nodes)
    outline = lenticular(1.8, 0.32, 24)
    scale = np.column_stack([np.linspace(0.9, 1.1, 8), np.linspace(1.1, 0.9, 8)]) if varying else None
    angle = np.linspace(0.0, 20.0, 8) if varying else None
    sagitta, rate = 2e-3, 16.0
    params = adaptive_params(spline, outline, sagitta, rate, section_scale=scale, section_rotation_deg=angle)
    miss = _chord_misses(spline, params, outline, scale, angle)
    assert 0.5 * sagitta < miss <= 1.1 * sagitta
    assert len(params) < 0.25 * len(sample_path(spline, rate)[2])  # the uniform rate's rings (measured 50 vs 248)
    length = np.linalg.norm(np.diff(spline(np.linspace(0.0, spline.knots[-1], 20001)), axis=0), axis=1).sum()
    uniform = sample_path(spline, (len(params) - 1.5) / length)[2]
    assert len(uniform) == len(params)
    assert _chord_misses(spline, uniform, outline, scale, angle) > 3 * miss
    assert np.all(np.diff(params) > 0) and params[0] == spline.knots[0] and params[-1] == spline.knots[-1]
