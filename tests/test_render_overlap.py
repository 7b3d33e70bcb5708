"""Priority rule for overlapping objects, against analytic interval splits."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from reference import box_chord, cone_rays, convex_chord, random_rotation

import xrayraster as xr

N, PIXEL, SOD, SDD, THETA = 160, 0.25, 100.0, 200.0, 0.35
GEOM = xr.ConeBeamGeometry(SOD, SDD, (N, N), PIXEL, [THETA])
RAYS = cone_rays(SOD, SDD, (N, N), PIXEL, THETA)


def box_at(scene, size, centre, rotation, material, priority, name):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rotation, centre
    scene.add(trimesh.creation.box(size), material, priority=priority, name=name, transform=xr.Transform(m))


@pytest.mark.parametrize("a_wins", [True, False])
def test_two_overlapping_cubes_split_by_priority(render, a_wins):
    """Same orientation, offset centres: A ∩ B is a box, so each material's length is analytic."""
    rot = random_rotation(np.random.default_rng(11))
    ca, cb = np.array([-1.5, 0.5, 0.0]), rot @ np.array([4.0, 3.0, -2.0]) + np.array([-1.5, 0.5, 0.0])
    scene = xr.Scene()
    box_at(scene, (8, 8, 8), ca, rot, "a", 2 if a_wins else 1, "A")
    box_at(scene, (8, 8, 8), cb, rot, "b", 1 if a_wins else 2, "B")
    assert scene.overlaps() == [("A", "B")]
    got = render(GEOM, scene)
    assert render.method == "resolve"
    # Intersection: in the shared frame the boxes span [-4, 4] and [4,3,-2] ± 4.
    lo, hi = np.maximum([-4, -4, -4], np.array([4, 3, -2]) - 4), np.minimum([4, 4, 4], np.array([4, 3, -2]) + 4)
    c_int = ca + rot @ ((lo + hi) / 2)
    l_a = box_chord(*RAYS, ca, rot, (4, 4, 4))
    l_b = box_chord(*RAYS, cb, rot, (4, 4, 4))
    l_ab = box_chord(*RAYS, c_int, rot, (hi - lo) / 2)
    want_a, want_b = (l_a, l_b - l_ab) if a_wins else (l_a - l_ab, l_b)
    assert np.abs(got[0] - want_a).max() <= 1e-4
    assert np.abs(got[1] - want_b).max() <= 1e-4
    assert l_ab.max() > 1.0  # the overlap is really seen


def test_sphere_nested_in_box_displaces_it(render):
    scene = xr.Scene()
    box_at(scene, (12, 12, 12), np.zeros(3), np.eye(3), "matrix", 0, "box")
    ball = trimesh.creation.icosphere(subdivisions=3, radius=4.5)
    ball.apply_translation([1.0, -0.5, 0.7])
    scene.add(ball, "inclusion", priority=1, name="ball")
    got = render(GEOM, scene)
    assert render.method == "resolve"
    l_ball = convex_chord(*RAYS, ball.vertices, ball.faces)
    l_box = box_chord(*RAYS, np.zeros(3), np.eye(3), (6, 6, 6))
    assert np.abs(got[1] - l_ball).max() <= 1e-4
    assert np.abs(got[0] - (l_box - l_ball)).max() <= 1e-4


def test_lower_priority_inclusion_is_invisible(render):
    scene = xr.Scene()
    box_at(scene, (12, 12, 12), np.zeros(3), np.eye(3), "matrix", 5, "box")
    scene.add(trimesh.creation.icosphere(subdivisions=2, radius=3.0), "inclusion", priority=1, name="ball")
    got = render(GEOM, scene)
    assert np.abs(got[0] - box_chord(*RAYS, np.zeros(3), np.eye(3), (6, 6, 6))).max() <= 1e-4
    assert got[1].max() == 0.0


def test_same_material_objects_share_a_channel_and_methods_agree(render):
    """Disjoint objects: the single pass is chosen, and forcing the resolve pass gives the same result."""
    scene = xr.Scene()
    box_at(scene, (4, 4, 4), np.array([-4.0, 0, 0]), np.eye(3), "carbon", 0, "left")
    box_at(scene, (4, 4, 4), np.array([4.0, 0, 1]), np.eye(3), "carbon", 0, "right")
    box_at(scene, (3, 3, 3), np.array([0.0, 0, -5]), np.eye(3), "epoxy", 0, "low")
    assert scene.materials == ("carbon", "epoxy") and scene.overlaps() == []
    single = render(GEOM, scene)
    assert render.method == "sum" and single.shape == (2, N, N)
    resolved = render(GEOM, scene, overlap="resolve")
    assert render.method == "resolve"
    want = box_chord(*RAYS, np.array([-4.0, 0, 0]), np.eye(3), (2, 2, 2)) + box_chord(
        *RAYS, np.array([4.0, 0, 1]), np.eye(3), (2, 2, 2)
    )
    assert np.abs(single[0] - want).max() <= 1e-4
    assert np.abs(resolved - single).max() <= 1e-5


def test_many_crossings_per_pixel_grow_the_lists(render):
    """A stack of 40 thin overlapping-with-matrix plates: >64 crossings per ray, resolved exactly."""
    scene = xr.Scene()
    box_at(scene, (10, 30, 10), np.zeros(3), np.eye(3), "matrix", 0, "matrix")
    for k in range(40):
        box_at(scene, (8, 0.3, 8), np.array([0, -14 + 0.7 * k, 0]), np.eye(3), "plate", 1, f"p{k}")
    geom = xr.ParallelBeamGeometry((16, 16), 0.5, [0.0])
    got = render(geom, scene)
    centre = got[:, 8, 8]
    assert abs(centre[1] - 40 * 0.3) <= 1e-4
    assert abs(centre[0] - (30 - 40 * 0.3)) <= 1e-4
