"""Priority rule for overlapping objects, against analytic interval splits."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from references.chords import box_chord, cone_rays, convex_chord, random_rotation

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


@pytest.mark.parametrize("overlap, method", [("auto", "nested"), ("resolve", "resolve")])
def test_sphere_nested_in_box_displaces_it(render, overlap, method):
    scene = xr.Scene()
    box_at(scene, (12, 12, 12), np.zeros(3), np.eye(3), "matrix", 0, "box")
    ball = trimesh.creation.icosphere(subdivisions=3, radius=4.5)
    ball.apply_translation([1.0, -0.5, 0.7])
    scene.add(ball, "inclusion", priority=1, name="ball")
    got = render(GEOM, scene, overlap=overlap)
    assert render.method == method
    l_ball = convex_chord(*RAYS, ball.vertices, ball.faces)
    l_box = box_chord(*RAYS, np.zeros(3), np.eye(3), (6, 6, 6))
    assert np.abs(got[1] - l_ball).max() <= 1e-4
    assert np.abs(got[0] - (l_box - l_ball)).max() <= 1e-4


@pytest.mark.parametrize("overlap", ["auto", "resolve"])
def test_lower_priority_inclusion_is_invisible(render, overlap):
    scene = xr.Scene()
    box_at(scene, (12, 12, 12), np.zeros(3), np.eye(3), "matrix", 5, "box")
    scene.add(trimesh.creation.icosphere(subdivisions=2, radius=3.0), "inclusion", priority=1, name="ball")
    got = render(GEOM, scene, overlap=overlap)
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
    got = render(geom, scene, overlap="resolve")
    centre = got[:, 8, 8]
    assert abs(centre[1] - 40 * 0.3) <= 1e-4
    assert abs(centre[0] - (30 - 40 * 0.3)) <= 1e-4
    assert np.abs(render(geom, scene) - got).max() <= 1e-4 and render.method == "nested"


def nested_chain_scene():
    """Box ⊃ slab ⊃ rod, a hidden ball (inside a container that outranks it), a same-material
    block nested in the box, and yarn-like bars cut flush with the box's faces."""
    scene = xr.Scene()
    rot = random_rotation(np.random.default_rng(3))
    box_at(scene, (14, 14, 14), np.zeros(3), rot, "matrix", 0, "box")
    box_at(scene, (10, 6, 10), rot @ [0, -2.5, 0], rot, "slab", 1, "slab")
    box_at(scene, (2, 2, 8), rot @ [1, -2.5, 0], rot, "rod", 2, "rod")
    box_at(scene, (2, 2, 2), rot @ [-3, -2.5, 2], rot, "ball", 0.5, "hidden")  # inside the slab, outranked
    box_at(scene, (3, 3, 3), rot @ [-4, 4.5, 5], rot, "matrix", 1, "same")
    for k in range(3):  # full-length bars: their end faces lie on the box's faces
        box_at(scene, (14, 1.5, 1.5), rot @ [0, 4.5, -4.5 + 3 * k], rot, "yarn", 3, f"bar{k}")
    return scene, rot


def test_nesting_reduces_ownership_to_sums(render):
    scene, _ = nested_chain_scene()
    names = [o.name for o in scene.objects]
    parent = {names[i]: (names[p] if p is not None else None) for i, p in enumerate(scene.nesting())}
    assert parent == {"box": None, "slab": "box", "rod": "slab", "hidden": "hidden", "same": "box",
                      "bar0": "box", "bar1": "box", "bar2": "box"}
    nested = render(GEOM, scene)
    assert render.method == "nested"
    resolved = render(GEOM, scene, overlap="resolve")
    assert np.abs(nested - resolved).max() <= 1e-4
    assert resolved[scene.materials.index("ball")].max() == 0.0  # hidden
    assert nested.min() >= 0.0 and resolved[scene.materials.index("yarn")].max() > 1.0


def test_partial_overlap_is_resolved_and_nested_cannot_be_forced(render):
    scene = xr.Scene()
    box_at(scene, (8, 8, 8), np.zeros(3), np.eye(3), "a", 0, "A")
    box_at(scene, (4, 4, 4), np.array([3.0, 0, 0]), np.eye(3), "b", 1, "B")  # pokes out of A
    assert scene.nesting() is None
    render(GEOM, scene)
    assert render.method == "resolve"
    with pytest.raises(xr.RenderError, match="partial overlaps"):
        render(GEOM, scene, overlap="nested")
