"""Mesh loading/checking (xrayraster.scene.mesh), transforms (xrayraster.core.transform) and scenes (xrayraster.scene.scene).

Inputs come from trimesh.creation; expected volumes, bounds and transformed points are hand values
(a 2×3×4 box has volume 24 mm³), and outward orientation is checked per triangle against the
centre of a convex solid, independently of Mesh.volume.
"""

from __future__ import annotations

import math
import warnings

import manifold3d
import numpy as np
import pytest
import trimesh

from xrayraster import Mesh, MeshError, Scene, SceneError, Transform, load_mesh
import xrayraster.core.transform as transform_module

BOX_EXTENTS = (2.0, 3.0, 4.0)
BOX_VOLUME = 24.0


def _box(extents=BOX_EXTENTS, centre=(0.0, 0.0, 0.0)):
    b = trimesh.creation.box(extents=extents)
    b.apply_translation(centre)
    return np.array(b.vertices), np.array(b.faces)


def _all_faces_outward(mesh: Mesh, centre) -> bool:
    """For a convex solid containing `centre`: every triangle normal points away from it."""
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    outward = np.einsum("ij,ij->i", normal, (a + b + c) / 3 - np.asarray(centre))
    return bool(np.all(outward > 0))


def _load_quietly(*args, **kwargs):
    """load_mesh with every warning turned into an error (proves a repair was silent)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_mesh(*args, **kwargs)


# --------------------------------------------------------------------------- loading and checks


def test_closed_box_loads_unchanged():
    """Control: a clean box keeps 8 vertices, 12 triangles, volume 24, outward faces; arrays read-only."""
    v, f = _box()
    m = _load_quietly((v, f), name="box")
    assert m.vertices.shape == (8, 3) and m.faces.shape == (12, 3)
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int64
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)
    assert _all_faces_outward(m, (0, 0, 0))
    np.testing.assert_array_equal(m.bounds, [[-1, -1.5, -2], [1, 1.5, 2]])
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 5.0


def test_open_box_names_object_and_open_edge_count():
    """Box minus its +x side (2 triangles): the square rim leaves 4 open edges."""
    v, f = _box()
    plus_x = np.all(v[f][:, :, 0] == 1.0, axis=1)
    assert plus_x.sum() == 2
    with pytest.raises(MeshError, match=r"'lid'.*\b4 open edges"):
        load_mesh((v, f[~plus_x]), name="lid")


def test_box_missing_one_triangle_has_three_open_edges():
    v, f = _box()
    with pytest.raises(MeshError, match=r"'hole'.*\b3 open edges"):
        load_mesh((v, f[1:]), name="hole")


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_vertex_is_rejected(bad):
    v, f = _box()
    v[3, 1] = bad
    with pytest.raises(MeshError, match=r"'broken'.*\b1 vertices"):
        load_mesh((v, f), name="broken")


def test_inside_out_mesh_is_flipped_silently():
    """All faces reversed (inside out but consistent): fixed with no warning, volume +24, faces outward."""
    v, f = _box()
    m = _load_quietly((v, f[:, ::-1]), name="inverted")
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)
    assert _all_faces_outward(m, (0, 0, 0))
    assert len(m.faces) == 12


@pytest.mark.parametrize("inverted_first", [False, True], ids=["mostly-outward", "mostly-inward"])
def test_inconsistent_winding_is_repaired_with_warning(inverted_first):
    """A few faces flipped against the rest: UserWarning naming the object, then a positive outward box."""
    v, f = _box()
    f = f[:, ::-1].copy() if inverted_first else f.copy()
    f[[0, 5, 7]] = f[[0, 5, 7]][:, ::-1]
    with pytest.warns(UserWarning, match=r"'patchy'.*winding"):
        m = load_mesh((v, f), name="patchy")
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)
    assert _all_faces_outward(m, (0, 0, 0))


def test_triangles_with_repeated_vertex_index_are_removed():
    """Faces [0,0,1], [2,3,3], [4,5,4] collapse to edges: dropped, and the box is still closed."""
    v, f = _box()
    m = _load_quietly((v, np.vstack([f, [[0, 0, 1], [2, 3, 3], [4, 5, 4]]])), name="degenerate")
    assert len(m.faces) == 12
    assert np.all((m.faces[:, 0] != m.faces[:, 1]) & (m.faces[:, 1] != m.faces[:, 2]) & (m.faces[:, 2] != m.faces[:, 0]))
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)


def test_triangle_collapsing_after_vertex_merge_is_removed():
    """A sliver [0, 8, 1] where vertex 8 is a copy of vertex 0 degenerates after merging; it is dropped."""
    v, f = _box()
    v = np.vstack([v, v[0]])
    m = _load_quietly((v, np.vstack([f, [[0, 8, 1]]])), name="sliver")
    assert m.vertices.shape == (8, 3) and len(m.faces) == 12
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)


def test_only_degenerate_triangles_is_an_error():
    v, _ = _box()
    with pytest.raises(MeshError, match="'flat'"):
        load_mesh((v, [[0, 0, 1], [2, 3, 3]]), name="flat")


def test_unused_vertices_do_not_enlarge_bounds():
    """A stray vertex far away is not part of the surface: bounds stay the box's."""
    v, f = _box()
    m = _load_quietly((np.vstack([v, [100.0, 100.0, 100.0]]), f), name="stray")
    np.testing.assert_array_equal(m.bounds, [[-1, -1.5, -2], [1, 1.5, 2]])


@pytest.mark.parametrize(
    "source",
    [([[0, 0, 0], [1, 0, 0]], [[0, 1]]), ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]]), 42],
    ids=["two-column-faces", "index-out-of-range", "not-a-mesh"],
)
def test_malformed_input_names_object(source):
    with pytest.raises(MeshError, match="'junk'"):
        load_mesh(source, name="junk")


def test_missing_file_names_object(tmp_path):
    with pytest.raises(MeshError, match=r"'ghost'.*no such file"):
        load_mesh(tmp_path / "nope.stl", name="ghost")


def test_binary_stl_round_trip_merges_corners(tmp_path):
    """Binary STL stores each triangle's 3 corners separately (36 for a box): loader merges to 8, closed, volume 24."""
    b = trimesh.creation.box(extents=BOX_EXTENTS)
    b.apply_translation((10.0, 20.0, 30.0))
    path = tmp_path / "box.stl"
    b.export(path, file_type="stl")
    raw = trimesh.load(path, force="mesh", process=False)
    assert len(raw.vertices) == 36  # precondition: the file really is unmerged
    m = _load_quietly(path, name="stl-box")
    assert m.vertices.shape == (8, 3) and len(m.faces) == 12
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-9)
    np.testing.assert_allclose(m.bounds, [[9.0, 18.5, 28.0], [11.0, 21.5, 32.0]], atol=1e-6)
    assert _all_faces_outward(m, (10.0, 20.0, 30.0))


def test_stl_round_trip_sphere_volume(tmp_path):
    """An icosphere through STL (float32 corners) keeps the float64 divergence-theorem volume to float32 precision."""
    s = trimesh.creation.icosphere(subdivisions=3, radius=5.0)
    a, b, c = (s.vertices[s.faces[:, k]] for k in range(3))
    expected = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    path = tmp_path / "ball.stl"
    s.export(path)
    m = _load_quietly(path, name="ball")
    assert len(m.vertices) == len(s.vertices) and len(m.faces) == len(s.faces)
    assert m.volume == pytest.approx(expected, rel=1e-6)
    assert m.volume == pytest.approx(4 / 3 * math.pi * 125, rel=0.01)  # close to the true sphere


def test_unit_scale_metres_to_mm():
    """A 0.002×0.003×0.004 m box with unit_scale=1000 is 24 mm³ with ±(1, 1.5, 2) mm bounds."""
    v, f = _box(extents=(0.002, 0.003, 0.004))
    m = _load_quietly((v, f), name="metres", unit_scale=1000)
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-9)
    np.testing.assert_allclose(m.bounds, [[-1, -1.5, -2], [1, 1.5, 2]], rtol=1e-12)


def test_unit_scale_applies_before_transform():
    """unit_scale first, then transform: a 10 mm shift stays 10 mm (not 10 m)."""
    v, f = _box(extents=(0.002, 0.003, 0.004))
    m = _load_quietly((v, f), unit_scale=1000, transform=Transform.translation((10.0, 0.0, 0.0)))
    np.testing.assert_allclose(m.bounds, [[9, -1.5, -2], [11, 1.5, 2]], rtol=1e-12)


@pytest.mark.parametrize("scale", [0, -1000, float("nan"), float("inf")])
def test_bad_unit_scale(scale):
    v, f = _box()
    with pytest.raises(MeshError, match=r"'m'.*unit_scale"):
        load_mesh((v, f), name="m", unit_scale=scale)


def test_mirror_transform_keeps_mesh_outward():
    """Mirroring x (det < 0) reverses orientation; the loaded mesh is still outward with volume +24."""
    v, f = _box(centre=(5.0, 0.0, 0.0))
    mirror = Transform.scaling((-1.0, 1.0, 1.0))
    assert mirror.flips_orientation
    m = _load_quietly((v, f), name="mirrored", transform=mirror)
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)
    assert _all_faces_outward(m, (-5.0, 0.0, 0.0))
    np.testing.assert_allclose(m.bounds, [[-6, -1.5, -2], [-4, 1.5, 2]], atol=1e-12)


def test_rotated_box_bounds():
    """A quarter turn about z swaps the x and y extents."""
    v, f = _box()
    m = _load_quietly((v, f), transform=Transform.rotation((0, 0, 1), math.pi / 2))
    np.testing.assert_allclose(m.bounds, [[-1.5, -1, -2], [1.5, 1, 2]], atol=1e-12)
    assert m.volume == pytest.approx(BOX_VOLUME, rel=1e-12)


def test_scaling_transform_scales_volume():
    v, f = _box()
    m = _load_quietly((v, f), transform=Transform.scaling((2.0, 0.5, 3.0)))
    assert m.volume == pytest.approx(BOX_VOLUME * 3.0, rel=1e-12)


# --------------------------------------------------------------------------- Transform


@pytest.mark.parametrize(
    "axis, angle, point, expected",
    [
        ((0, 0, 1), math.pi / 2, (1, 0, 0), (0, 1, 0)),
        ((0, 0, 1), math.pi / 2, (0, 1, 0), (-1, 0, 0)),
        ((0, 0, 5), math.pi / 2, (1, 0, 0), (0, 1, 0)),  # axis need not be unit
        ((1, 0, 0), math.pi / 2, (0, 1, 0), (0, 0, 1)),
        ((0, 1, 0), math.pi / 2, (0, 0, 1), (1, 0, 0)),
        ((1, 1, 1), 2 * math.pi / 3, (1, 0, 0), (0, 1, 0)),  # cyclic permutation x→y→z
        ((1, 1, 1), 2 * math.pi / 3, (0, 0, 2), (2, 0, 0)),
        ((0, 0, 1), math.pi, (1, 2, 3), (-1, -2, 3)),
        ((0, 0, -1), math.pi / 2, (1, 0, 0), (0, -1, 0)),
    ],
)
def test_rotation_is_right_handed(axis, angle, point, expected):
    t = Transform.rotation(axis, angle)
    np.testing.assert_allclose(t.apply([point]), [expected], atol=1e-12)
    assert not t.flips_orientation


def test_translation_and_scaling_by_hand():
    pts = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]
    np.testing.assert_allclose(Transform.translation((1, 2, 3)).apply(pts), [[1, 2, 3], [2, 3, 4]])
    np.testing.assert_allclose(Transform.scaling(2).apply(pts), [[0, 0, 0], [2, 2, 2]])
    np.testing.assert_allclose(Transform.scaling((1, 2, 3)).apply([[1, 1, 1], [-2, 0, 5]]), [[1, 2, 3], [-2, 0, 15]])
    np.testing.assert_allclose(Transform().apply(pts), pts)


def test_compose_applies_right_operand_first():
    """(A @ B).apply(p) == A(B(p)): T @ R rotates then shifts; R @ T shifts then rotates."""
    t = Transform.translation((1.0, 0.0, 0.0))
    r = Transform.rotation((0, 0, 1), math.pi / 2)
    np.testing.assert_allclose((t @ r).apply([[1.0, 0.0, 0.0]]), [[1.0, 1.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose((r @ t).apply([[1.0, 0.0, 0.0]]), [[0.0, 2.0, 0.0]], atol=1e-12)
    s = Transform.scaling(3.0)
    np.testing.assert_allclose((s @ t @ r).apply([[0.0, 1.0, 0.0]]), [[0.0, 0.0, 0.0]], atol=1e-12)


def test_transform_repr_round_trip_and_flip_flag():
    t = Transform.translation((1.5, -2.0, 0.25)) @ Transform.rotation((1, 2, 3), 0.7) @ Transform.scaling((-1, 2, 1))
    assert eval(repr(t), vars(transform_module)) == t
    assert t.flips_orientation
    assert not (Transform.scaling((-1, -1, 1))).flips_orientation  # two mirrors = a rotation


@pytest.mark.parametrize(
    "make",
    [
        lambda: Transform.scaling(0.0),
        lambda: Transform(np.eye(3)),
        lambda: Transform(np.where(np.eye(4) == 1, np.nan, 0.0)),
        lambda: Transform([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]),
        lambda: Transform.rotation((0, 0, 0), 1.0),
    ],
    ids=["singular", "3x3", "nan", "projective", "zero-axis"],
)
def test_invalid_transforms_raise(make):
    with pytest.raises(ValueError):
        make()


# --------------------------------------------------------------------------- Scene


def test_empty_scene_requires_objects():
    s = Scene()
    assert len(s) == 0
    with pytest.raises(SceneError, match="empty"):
        s.require_objects()
    with pytest.raises(SceneError):
        s.bounds


def test_duplicate_names_rejected():
    s = Scene()
    s.add(_box(), "carbon", name="weft")
    with pytest.raises(SceneError, match="'weft'"):
        s.add(_box(), "epoxy", name="weft")
    assert len(s) == 1


def test_default_labels_and_names():
    """Labels default to position + 1 and names are unique."""
    s = Scene()
    objs = [s.add(_box(), "m") for _ in range(3)]
    assert [o.label for o in objs] == [1, 2, 3]
    assert len({o.name for o in objs}) == 3


def test_unnamed_object_never_collides_with_a_user_name():
    """`name` is optional: adding an unnamed object must not fail because of an earlier explicit name."""
    s = Scene()
    s.add(_box(), "m", name="object1")
    o = s.add(_box(), "m")
    assert o.name != "object1"
    assert len({x.name for x in s.objects}) == 2


@pytest.mark.parametrize("label", [0, -1, 65536, 1.5])
def test_label_out_of_range(label):
    s = Scene()
    with pytest.raises(SceneError, match="label"):
        s.add(_box(), "m", label=label)


@pytest.mark.parametrize("label", [1, 65535, 7.0])
def test_label_in_range(label):
    s = Scene()
    o = s.add(_box(), "m", label=label)
    assert o.label == int(label) and type(o.label) is int


def test_unhashable_material_and_bad_priority():
    s = Scene()
    with pytest.raises(SceneError, match="material"):
        s.add(_box(), ["not", "hashable"])
    with pytest.raises(SceneError, match="priority"):
        s.add(_box(), "m", priority=float("nan"))


def test_materials_share_channels_in_order_of_first_appearance():
    """Equal materials (even distinct objects) share one channel; channels ordered by first use."""
    s = Scene()
    carbon_1, carbon_2 = tuple(["C", 1.72]), tuple(["C", 1.72])
    assert carbon_1 == carbon_2 and carbon_1 is not carbon_2
    a = s.add(_box(), carbon_1, name="a")
    b = s.add(_box(), "epoxy", name="b")
    c = s.add(_box(), carbon_2, name="c")  # equal, not identical
    d = s.add(_box(), "air", name="d")
    assert s.materials == (("C", 1.72), "epoxy", "air")
    assert [s.channel(o) for o in (a, b, c, d)] == [0, 1, 0, 2]


def test_scene_bounds_cover_all_objects():
    s = Scene()
    s.add(_box(centre=(0, 0, 0)), "m")
    s.add(_box(centre=(10, -5, 1)), "m")
    np.testing.assert_allclose(s.bounds, [[-1, -6.5, -2], [11, 1.5, 3]])
    assert s.num_triangles == 24


def test_scene_accepts_mesh_and_applies_transform():
    """A checked Mesh is used as is; with a transform it is re-checked and moved."""
    m = _load_quietly(_box())
    s = Scene()
    o1 = s.add(m, "m")
    o2 = s.add(m, "m", transform=Transform.translation((0, 0, 10)))
    assert o1.mesh is m
    np.testing.assert_allclose(o2.mesh.bounds, [[-1, -1.5, 8], [1, 1.5, 12]])


def _cube(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return _box(extents=hi - lo, centre=(lo + hi) / 2)


def _pairs(scene):
    return {frozenset(p) for p in scene.overlaps()}


def test_overlapping_boxes_are_reported():
    s = Scene()
    s.add(_cube((0, 0, 0), (2, 2, 2)), "m", name="a")
    s.add(_cube((1, 0.5, 0.5), (3, 1.5, 1.5)), "m", name="b")
    assert _pairs(s) == {frozenset({"a", "b"})}


def test_touching_boxes_are_not_reported():
    """Boxes sharing the face x = 2 have no common interior."""
    s = Scene()
    s.add(_cube((0, 0, 0), (2, 2, 2)), "m", name="a")
    s.add(_cube((2, 0, 0), (4, 2, 2)), "m", name="b")
    assert s.overlaps() == []


def test_far_apart_boxes_are_not_reported():
    s = Scene()
    s.add(_cube((0, 0, 0), (2, 2, 2)), "m", name="a")
    s.add(_cube((50, 50, 50), (52, 52, 52)), "m", name="b")
    assert s.overlaps() == []


def test_sphere_nested_in_box_is_reported():
    s = Scene()
    s.add(_cube((-5, -5, -5), (5, 5, 5)), "matrix", name="box")
    s.add(trimesh.creation.icosphere(radius=2.0), "fibre", name="ball")
    assert _pairs(s) == {frozenset({"box", "ball"})}


def test_disjoint_spheres_with_overlapping_bounding_boxes_are_not_reported():
    """Unit spheres 2.77 apart on the diagonal: boxes overlap, solids do not (exercises the exact test)."""
    s = Scene()
    s.add(trimesh.creation.icosphere(radius=1.0), "m", name="s1")
    s.add(trimesh.creation.icosphere(radius=1.0).apply_translation((1.6, 1.6, 1.6)), "m", name="s2")
    assert s.overlaps() == []


def _l_shape():
    """L-prism [0,4]×[0,2]×[0,2] ∪ [0,2]×[0,4]×[0,2]; its notch is [2,4]×[2,4]×[0,2]."""
    solid = manifold3d.Manifold.cube((4, 2, 2)) + manifold3d.Manifold.cube((2, 4, 2))
    mesh = solid.to_mesh()
    return np.asarray(mesh.vert_properties)[:, :3].astype(np.float64), np.asarray(mesh.tri_verts).astype(np.int64)


def test_box_touching_inside_a_notch_is_not_reported():
    """A box filling the L's notch touches two of its faces and lies inside its bounding box, but shares no volume."""
    s = Scene()
    L = s.add(_l_shape(), "m", name="L")
    assert L.mesh.volume == pytest.approx(4 * 2 * 2 + 2 * 4 * 2 - 2 * 2 * 2, rel=1e-12)
    s.add(_cube((2, 2, 0), (4, 4, 2)), "m", name="notch")
    assert s.overlaps() == []


def test_box_poking_into_a_notch_wall_is_reported():
    """Same notch box shifted 0.5 into the L: overlap volume 2 mm³ is reported."""
    s = Scene()
    s.add(_l_shape(), "m", name="L")
    s.add(_cube((1.5, 2, 0), (3.5, 4, 2)), "m", name="poke")
    assert _pairs(s) == {frozenset({"L", "poke"})}


def test_overlaps_finds_only_the_overlapping_pair_and_updates_after_add():
    """Three objects, one overlapping pair; adding a fourth that overlaps a third invalidates the cache."""
    s = Scene()
    s.add(_cube((0, 0, 0), (2, 2, 2)), "m", name="a")
    s.add(_cube((10, 0, 0), (12, 2, 2)), "m", name="b")
    s.add(_cube((1, 1, 1), (3, 3, 3)), "m", name="c")
    assert _pairs(s) == {frozenset({"a", "c"})}
    s.add(_cube((11, 1, 1), (13, 3, 3)), "m", name="d")
    assert _pairs(s) == {frozenset({"a", "c"}), frozenset({"b", "d"})}
