"""Partial overlaps as signed intersection meshes (xrayraster/scene/overlap_terms.py): the terms of
axis-aligned boxes against their intersections by hand, inclusion–exclusion's identity for the
space each object owns, and the scenes one pass cannot render."""

from __future__ import annotations

import numpy as np
import trimesh

import xrayraster as xr


def box(scene, lo, hi, priority, name, material=None):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    scene.add(trimesh.creation.box(hi - lo).apply_translation((lo + hi) / 2), material or name, priority=priority,
              name=name)
    return lo, hi


def shared(*boxes):
    """The volume of the boxes' intersection, by hand (mm³)."""
    lo = np.max([b[0] for b in boxes], axis=0)
    hi = np.min([b[1] for b in boxes], axis=0)
    return float(np.prod(np.clip(hi - lo, 0, None)))


def scene_of_three():
    scene = xr.Scene()
    boxes = [box(scene, [-8, -8, -8], [8, 8, 8], 0, "matrix"),
             box(scene, [-4, -1, -1], [4, 1, 1], 1, "a"),
             box(scene, [-1, -4, -1.5], [1, 4, 0.5], 2, "b"),
             box(scene, [-0.5, -0.5, -4], [1.5, 0.5, 4], 3, "c")]
    return scene, boxes


def test_terms_are_the_intersections_with_the_sign_of_inclusion_exclusion():
    scene, boxes = scene_of_three()
    one_pass = scene.one_pass()
    assert one_pass.nesting == [None, 0, 0, 0]  # the bars subtract from the matrix
    got = {t.members: (t.sign, t.mesh.volume) for t in one_pass.terms}
    assert set(got) == {(1, 2), (1, 3), (2, 3), (1, 2, 3)}  # lowest rank first
    for members, (sign, volume) in got.items():
        assert sign == (-1) ** (len(members) - 1)
        assert abs(volume - shared(*(boxes[k] for k in members))) <= 1e-9


def test_signed_volumes_give_each_object_the_space_it_owns():
    """Owned volume = own volume + the signed volumes of the terms it is lowest in; the container
    loses each object's volume and each term's signed volume (by hand: each bar minus what the
    higher ones take; the matrix minus the union of the bars)."""
    scene, (m, a, b, c) = scene_of_three()
    terms = scene.one_pass().terms
    owned = {k: o.mesh.volume + sum(t.sign * t.mesh.volume for t in terms if t.members[0] == k)
             for k, o in enumerate(scene.objects)}
    union = sum(shared(x) for x in (a, b, c)) - shared(a, b) - shared(a, c) - shared(b, c) + shared(a, b, c)
    matrix = shared(m) - sum(o.mesh.volume for o in scene.objects[1:]) - sum(t.sign * t.mesh.volume for t in terms)
    assert abs(matrix - (shared(m) - union)) <= 1e-9
    assert abs(owned[1] - (shared(a) - shared(a, b) - shared(a, c) + shared(a, b, c))) <= 1e-9
    assert abs(owned[2] - (shared(b) - shared(b, c))) <= 1e-9
    assert abs(owned[3] - shared(c)) <= 1e-9


def test_one_pass_declines_what_terms_cannot_write():
    # Four bars through one point: a term of four objects.
    scene, _ = scene_of_three()
    box(scene, [-0.2, -0.2, -0.2], [3, 0.2, 0.2], 4, "d")
    assert scene.one_pass() is None
    # A member of a partial overlap that contains an object (the container would lose it twice).
    scene = xr.Scene()
    box(scene, [-4, -1, -1], [4, 1, 1], 1, "a")
    box(scene, [2, -3, -1], [3, 3, 1], 2, "b")
    box(scene, [-3, -0.5, -0.5], [-2, 0.5, 0.5], 3, "inside_a")
    assert scene.one_pass() is None
    # Partial overlaps between objects of different containers.
    scene = xr.Scene()
    box(scene, [-8, -8, -8], [0, 8, 8], 0, "left")
    box(scene, [-2, -1, -1], [-0.5, 1, 1], 1, "in_left")
    box(scene, [-1, -1, -1], [1, 1, 1], 2, "across")  # pokes out of left: not nested in it
    assert scene.one_pass() is None
    # Containment alone, and nothing: no terms.
    scene = xr.Scene()
    box(scene, [-4, -4, -4], [4, 4, 4], 0, "matrix")
    box(scene, [-1, -1, -1], [1, 1, 1], 1, "ball")
    assert scene.one_pass().terms == () and scene.one_pass().nesting == scene.nesting()
