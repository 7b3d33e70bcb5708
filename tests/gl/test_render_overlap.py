"""Priority rule for overlapping objects, against analytic interval splits: by the per-pixel sort
(resolve) and in one pass (nested, with partial overlaps as signed intersection meshes)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from references.chords import box_chord, box_interval, cone_rays, convex_chord, random_rotation

import xrayraster as xr

N, PIXEL, SOD, SDD, THETA = 160, 0.25, 100.0, 200.0, 0.35
GEOM = xr.ConeBeamGeometry(SOD, SDD, (N, N), PIXEL, [THETA])
RAYS = cone_rays(SOD, SDD, (N, N), PIXEL, THETA)


def box_at(scene, size, centre, rotation, material, priority, name):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rotation, centre
    scene.add(trimesh.creation.box(size), material, priority=priority, name=name, transform=xr.Transform(m))


@pytest.mark.parametrize("overlap, method", [("auto", "nested"), ("resolve", "resolve")])
@pytest.mark.parametrize("a_wins", [True, False])
def test_two_overlapping_cubes_split_by_priority(render, a_wins, overlap, method):
    """Same orientation, offset centres: A ∩ B is a box, so each material's length is analytic."""
    rot = random_rotation(np.random.default_rng(11))
    ca, cb = np.array([-1.5, 0.5, 0.0]), rot @ np.array([4.0, 3.0, -2.0]) + np.array([-1.5, 0.5, 0.0])
    scene = xr.Scene()
    box_at(scene, (8, 8, 8), ca, rot, "a", 2 if a_wins else 1, "A")
    box_at(scene, (8, 8, 8), cb, rot, "b", 1 if a_wins else 2, "B")
    assert scene.overlaps() == [("A", "B")]
    got = render(GEOM, scene, overlap=overlap)
    assert render.method == method
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


def test_a_material_nested_in_two_containers_is_taken_off_each(render):
    """Rods of one material in two blocks of different materials, and a bar only in the first: one
    pass takes a channel whose objects share one container off that container as a whole, and one
    whose objects sit in different containers crossing by crossing. Both against the float64 sweep."""
    rot = random_rotation(np.random.default_rng(7))
    boxes = [  # (centre, rotation, size), by rank
        (rot @ [-4, 0, 0], rot, (7, 12, 12)),
        (rot @ [4, 0, 0], rot, (7, 12, 12)),
        (rot @ [-4, -2, 0], rot, (2, 2, 10)),
        (rot @ [4, 2, 0], rot, (2, 2, 10)),
        (rot @ [-4, 3, 0], rot, (1.5, 1.5, 10)),
    ]
    materials = ["matrix", "resin", "rod", "rod", "bar"]
    scene = xr.Scene()
    for k, ((centre, r, size), material) in enumerate(zip(boxes, materials)):
        box_at(scene, size, centre, r, material, k, f"b{k}")
    got = render(GEOM, scene)
    assert render.method == "nested"
    owned = owned_lengths(boxes, RAYS).reshape(len(boxes), N, N)
    for channel, material in enumerate(scene.materials):
        want = sum(owned[k] for k, mk in enumerate(materials) if mk == material)
        assert np.abs(got[channel] - want).max() <= 1e-4, material
    assert min(owned[k].max() for k in range(5)) > 1.0  # every box is seen


def owned_lengths(boxes, rays):
    """Float64 per-ray length each box owns (the highest rank covering a point owns it): every
    box's one interval along the ray (slab method), swept between the sorted end points."""
    rays = [r.reshape(-1, 3) for r in rays]
    enter, leave = zip(*(box_interval(*rays, centre, rot, np.asarray(size) / 2) for centre, rot, size in boxes))
    enter, leave = np.stack(enter, -1), np.stack(leave, -1)  # (rays, boxes), boxes listed by rank
    points = np.sort(np.concatenate([enter, leave], -1), -1)
    mids, widths = (points[:, 1:] + points[:, :-1]) / 2, np.diff(points, axis=-1)
    inside = (enter[:, None, :] <= mids[..., None]) & (mids[..., None] < leave[:, None, :])
    ranks = np.arange(len(boxes))
    owner = np.where(inside.any(-1), np.argmax(np.where(inside, ranks, -1), -1), -1)
    return np.stack([np.where(owner == k, widths, 0.0).sum(-1) for k in ranks])


@pytest.mark.parametrize("overlap", ["auto", "nested", "resolve"])
def test_pairs_and_a_triple_in_a_container_own_what_the_priority_rule_gives(render, overlap):
    """Three tilted bars that cut each other in pairs and all three at once, inside a matrix block,
    and a fourth of the lowest bar's material: each material's length against the float64 sweep.
    One pass needs pair terms and a triple term here."""
    rot = random_rotation(np.random.default_rng(5))
    boxes = [  # (centre, rotation, size), by rank
        (np.zeros(3), rot, (16, 16, 16)),
        (rot @ [0, 0, 0], rot, (12, 3, 3)),
        (rot @ [1, 1, 0], rot, (3, 12, 3)),
        (rot @ [-1, 0, 1], rot, (3, 3, 12)),
        (rot @ [3, -1.5, -1], rot, (2, 8, 2)),
    ]
    materials = ["matrix", "weft", "warp", "binder", "weft"]
    scene = xr.Scene()
    for k, ((centre, r, size), material) in enumerate(zip(boxes, materials)):
        box_at(scene, size, centre, r, material, k, f"b{k}")
    terms = scene.one_pass().terms
    assert sorted(len(t.members) for t in terms).count(3) >= 1
    got = render(GEOM, scene, overlap=overlap)
    assert render.method == ("nested" if overlap == "auto" else overlap)
    owned = owned_lengths(boxes, RAYS).reshape(len(boxes), N, N)
    want = {m: sum(owned[k] for k, mk in enumerate(materials) if mk == m) for m in scene.materials}
    for channel, material in enumerate(scene.materials):
        assert np.abs(got[channel] - want[material]).max() <= 1e-4, material
    assert min(owned[k].max() for k in range(1, 5)) > 1.0  # every bar is seen


def test_partial_overlaps_render_in_one_pass_unless_four_objects_share_space(render):
    scene = xr.Scene()
    box_at(scene, (8, 8, 8), np.zeros(3), np.eye(3), "a", 0, "A")
    box_at(scene, (4, 4, 4), np.array([3.0, 0, 0]), np.eye(3), "b", 1, "B")  # pokes out of A
    assert scene.nesting() is None and len(scene.one_pass().terms) == 1
    one_pass = render(GEOM, scene)
    assert render.method == "nested"
    assert np.abs(one_pass - render(GEOM, scene, overlap="resolve")).max() <= 1e-4
    for k in range(2):  # four boxes with a common corner: a term of four would be needed
        box_at(scene, (4, 4, 4), np.array([3.0, 1.0 + k, 1.0 - k]), np.eye(3), "c", 2 + k, f"C{k}")
    assert scene.one_pass() is None
    render(GEOM, scene)
    assert render.method == "resolve"
    with pytest.raises(xr.RenderError, match="overlaps that one pass can render"):
        render(GEOM, scene, overlap="nested")


def test_terms_with_more_triangles_than_twice_the_rays_leave_the_sort(render):
    """A 4×4 detector: two overlapping balls' intersection has more triangles than twice the 16 rays,
    which cost less to sort."""
    from xrayraster.gl.pathlengths import TERM_TRIANGLES_PER_RAY

    scene = xr.Scene()
    for k, name in enumerate("ab"):
        scene.add(trimesh.creation.icosphere(3, 4.0).apply_translation([3.0 * k, 0, 0]), name, priority=k, name=name)
    assert sum(len(t.mesh.faces) for t in scene.one_pass().terms) > TERM_TRIANGLES_PER_RAY * 16
    geom = xr.ConeBeamGeometry(SOD, SDD, (4, 4), 10 * PIXEL, [THETA])
    sorted_ = render(geom, scene)
    assert render.method == "resolve"
    assert np.abs(render(geom, scene, overlap="nested") - sorted_).max() <= 1e-4


def test_interpenetrating_scenes_search_for_terms_only_where_they_can_pay():
    """A woven sample's method without the overlap search: auto (which may then draw the terms)
    where its triangles are at most the rays, or up to three times them in a scan of at least
    SEARCH_RAYS_PER_TRIANGLE rays a triangle; else the sort."""
    from xrayraster.gl.pathlengths import SEARCH_RAYS_PER_TRIANGLE, interpenetrating_overlap

    scene = xr.Scene()
    scene.add(trimesh.creation.icosphere(3, 4.0), "a", name="a")  # 1280 triangles
    small = xr.ConeBeamGeometry(SOD, SDD, (32, 32), PIXEL, [THETA])  # 1024 rays
    large = xr.ConeBeamGeometry(SOD, SDD, (32, 40), PIXEL, [THETA])  # 1280 rays
    assert interpenetrating_overlap(scene, small) == "resolve"
    assert interpenetrating_overlap(scene, large) == "auto"
    enough = -(-SEARCH_RAYS_PER_TRIANGLE * 1280 // 1024)  # views of 1024 rays for the search to pay
    for views, method in ((enough, "auto"), (enough - 1, "resolve")):
        geometry = xr.ConeBeamGeometry(SOD, SDD, (32, 32), PIXEL, np.linspace(0.0, 2 * np.pi, views, endpoint=False))
        assert interpenetrating_overlap(scene, geometry) == method
        assert interpenetrating_overlap(scene, geometry, views=1) == "resolve"
    many = np.linspace(0.0, 2 * np.pi, 100 * enough, endpoint=False)
    tiny = xr.ConeBeamGeometry(SOD, SDD, (16, 16), PIXEL, many)  # 5 triangles a ray: never
    assert interpenetrating_overlap(scene, tiny) == "resolve"
