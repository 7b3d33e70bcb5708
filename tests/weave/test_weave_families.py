"""Weave families (xrayraster.weave.families): each family's binder paths from its definition, its
meshes closed, its bytes fixed by the seed, its yarn volume against the analytic cell, its labels
against an independent inside test, and a scan whose classes read as their materials attenuate."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest
import trimesh

from references.solids import is_manifold
from xrayraster.core.errors import ConfigError, WeaveError
from xrayraster.core.volume import VolumeGeometry
from xrayraster.gl.voxelize import voxelize
from xrayraster.io.weave_file import weave_from_dict
from xrayraster.weave import Sample, UnitCell
from xrayraster.weave.families import FAMILY_NAMES

COARSE = {"points_per_section": 12, "samples_per_mm": 2.0}
NEW = ("orthogonal", "through_thickness_angle_interlock", "offset_angle_interlock", "plain", "twill", "satin")
PLIES = ("plain", "twill", "satin")


def cell_of(family: str, **kwargs) -> UnitCell:
    """A small cell of ``family``: three weft layers, or two plies."""
    return UnitCell(family=family, **({"plies": 2} if family in PLIES else {"weft_layers": 3}), **kwargs)


# -- the paths, from each family's definition ---------------------------------------------------

def test_orthogonal_binders_run_over_the_top_then_under_the_bottom():
    cell = UnitCell(family="orthogonal", weft_layers=4, warp_positions=3)
    assert cell.binders == 3 and cell.binder_position == (0, 1, 2)
    assert cell.binder_path == ((4, 4, 0, 0),) * 3  # gap 4 above the top layer, gap 0 below the bottom
    assert cell.stuffers == 3  # a stuffer in every gap between weft layers
    # The binders' height fits the margins exactly: m = (1 - share) (T - 2m) / (n - 1).
    assert math.isclose(cell.margin_z, cell.warp_height, rel_tol=1e-12)


def test_angle_interlock_binders_climb_a_gap_a_step_through_the_whole_stack():
    through = UnitCell(family="through_thickness_angle_interlock", weft_layers=3, warp_positions=2, binder_step=2)
    assert through.weft_per_layer == 12  # one period: up 3 gaps and down again, 2 columns a gap
    assert through.binder_path == ((0, 0, 1, 1, 2, 2, 3, 3, 2, 2, 1, 1),) * 2
    offset = UnitCell(family="offset_angle_interlock", weft_layers=2, warp_positions=3, binder_offset=1)
    assert offset.binder_path == ((0, 1, 2, 1), (1, 0, 1, 2), (2, 1, 0, 1))  # position p shifted p columns


def test_warp_and_binder_ratios_lay_out_the_warp_columns():
    """Two binder columns, then two stuffer columns, per group (TexGen's binder and warp ratios)."""
    cell = UnitCell(family="orthogonal", weft_layers=3, warp_positions=4, binder_ratio=2, warp_ratio=2,
                    warp_spacing=1.0)
    assert cell.warp_columns == 8 and cell.size[0] == 8.0
    assert cell.binder_x == (0.5, 1.5, 4.5, 5.5) and cell.stuffer_x == (2.5, 3.5, 6.5, 7.5)
    assert sorted(set(UnitCell().binder_x)) == [1.25, 3.75, 6.25, 8.75]  # no stuffers: every column a binder's


def test_the_named_2d_patterns_follow_their_drafts():
    """Plain: every neighbour of a crossing the other way round. Twill over/under: each warp over
    ``over`` consecutive wefts (cyclically), the next warp's run one weft on. Satin of n: each warp
    under exactly one weft, each weft under exactly one warp, neighbouring warps' crossings at least
    two wefts apart (no twill line)."""
    plain = np.array(UnitCell(family="plain").pattern)
    assert np.all(plain != np.roll(plain, 1, 0)) and np.all(plain != np.roll(plain, 1, 1))
    for over, under in ((2, 2), (2, 1), (3, 1)):
        twill = np.array(UnitCell(family="twill", floats=(over, under)).pattern)
        assert twill.shape == (over + under,) * 2
        for i, row in enumerate(twill):
            assert np.array_equal(row, np.roll(twill[0], i)) and row.sum() == over
            start = int(np.flatnonzero(row & ~np.roll(row, 1))[0])  # where the run over starts
            assert np.all(np.roll(row, -start)[:over])
    for n in (5, 7, 8):
        satin = 1 - np.array(UnitCell(family="satin", harness=n).pattern)  # 1 where the warp is under
        assert satin.shape == (n, n) and np.all(satin.sum(0) == 1) and np.all(satin.sum(1) == 1)
        under = satin.argmax(1)
        gaps = np.abs(np.diff(np.append(under, under[0])))
        assert np.all(np.minimum(gaps, n - gaps) >= 2)


def test_ply_yarns_lie_face_to_face_at_every_crossing_of_the_pattern():
    """Each warp's node at a weft crossing is at the ply's mid-plane ± half the weft's height (over
    where the pattern has 1), the weft's at ∓ half the warp's: the two touch there and fill the ply.
    Ply k is shifted by k · ply_shift_mm."""
    cell = UnitCell(family="twill", plies=3, ply_shift_mm=(0.6, 0.9))
    sample = Sample(cell, cells=(1, 1))
    pattern = np.array(cell.pattern)
    for yarn in sample.yarns():
        ply = int(yarn.name.split("_p")[1].split("_")[0])
        index = int(yarn.name.rsplit("_", 1)[1][1:])
        crossings = yarn.nodes[::4]  # a node a crossing, then three between
        shift = np.array(cell.ply_shift_mm) * ply
        if yarn.family == "warp":
            assert np.allclose(crossings[:, 0], (index + 0.5) * cell.warp_spacing + shift[0])
            j = np.rint((crossings[:, 1] - shift[1]) / cell.weft_spacing - 0.5).astype(int)
            over = pattern[index % 4, j % 4]
            assert np.allclose(crossings[:, 2], cell.ply_z(ply) + np.where(over, 0.5, -0.5) * cell.weft_height)
        else:
            assert np.allclose(crossings[:, 1], (index + 0.5) * cell.weft_spacing + shift[1])
            i = np.rint((crossings[:, 0] - shift[0]) / cell.warp_spacing - 0.5).astype(int)
            over = pattern[i % 4, index % 4]
            assert np.allclose(crossings[:, 2], cell.ply_z(ply) + np.where(over, -0.5, 0.5) * cell.warp_height)
    assert math.isclose(cell.weft_height + cell.warp_height, cell.ply_pitch)
    assert math.isclose(cell.ply_pitch * 3 + 2 * cell.margin_z, cell.thickness)


@pytest.mark.parametrize("family", PLIES)
def test_a_float_stays_level_and_the_plain_weave_is_texgens_curve(family):
    """Along every yarn the centre line stays within 2 % of its swing (half the crossing yarn's
    height) of the ply's mid-plane ± that swing; a plain weave's is the smoothstep between
    crossings, as TexGen's in-plane tangents draw it, to 0.5 % of the swing (the spline runs at
    chord-length speed, not evenly along the yarn's axis)."""
    from xrayraster.weave.sweep import CubicSpline3

    cell = cell_of(family)
    for yarn in Sample(cell, cells=(1, 1)).yarns():
        spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
        points = spline(np.linspace(0.0, spline.length_parameter, 4001))
        ply = int(yarn.name.split("_p")[1].split("_")[0])
        swing = (cell.weft_height if yarn.family == "warp" else cell.warp_height) / 2
        assert np.abs(points[:, 2] - cell.ply_z(ply)).max() <= 1.02 * swing
        if family == "plain":
            axis = 1 if yarn.family == "warp" else 0
            crossings = yarn.nodes[::4]
            spacing = crossings[1, axis] - crossings[0, axis]
            k = np.clip(np.searchsorted(crossings[:, axis], points[:, axis], side="right") - 1, 0, len(crossings) - 2)
            t = (points[:, axis] - crossings[k, axis]) / spacing
            want = crossings[k, 2] + (crossings[k + 1, 2] - crossings[k, 2]) * t * t * (3 - 2 * t)
            assert np.abs(points[:, 2] - want).max() < 0.005 * swing


@pytest.mark.parametrize("kwargs, field", [
    ({"family": "knit"}, "family"),
    ({"family": "plain", "weft_layers": 3}, "weft_layers: family 'plain' takes no weft_layers"),
    ({"family": "orthogonal", "plies": 2}, "plies"),
    ({"family": "plain", "floats": (2, 2)}, "floats: family 'plain' takes no floats .* 'twill'"),
    ({"family": "twill", "floats": (2, 2), "pattern": ((1, 0), (0, 1))}, "pattern or floats"),
    ({"family": "satin", "harness": 4}, "harness"),
    ({"family": "plain", "pattern": ((1, 0), (0,))}, r"pattern\[1\]"),
    ({"family": "plain", "pattern": ((1, 2), (0, 1))}, r"pattern\[0\]\[1\]"),
    ({"family": "plain", "warp_positions": 3}, "warp_positions .* the pattern's rows"),
    ({"family": "plain", "ply_shift_mm": (1.0,)}, "ply_shift_mm"),
    ({"family": "orthogonal", "binder_step": 2}, "binder_step"),
    ({"family": "layer_to_layer", "binder_offset": 1}, "binder_offset"),
    ({"family": "through_thickness_angle_interlock", "binder_path": ((0, 1),)}, "binder_path"),
    ({"family": "through_thickness_angle_interlock", "weft_layers": 3, "weft_per_layer": 8}, "weft_per_layer"),
    ({"family": "orthogonal", "binder_path": ((5, 2, 0, 0),) * 4}, r"binder_path\[0\]\[1\]"),
    ({"warp_positions": 3, "binder_ratio": 2}, "binder_ratio"),
    ({"warp_ratio": 0}, "warp_ratio"),
])
def test_a_field_the_family_cannot_take_is_named(kwargs, field):
    with pytest.raises(WeaveError, match=field):
        UnitCell(**kwargs)


def test_a_weave_table_names_an_unknown_family():
    with pytest.raises(ConfigError, match=r"\[weave\] family must be one of 'layer_to_layer', 'orthogonal'"):
        weave_from_dict({"family": "3d"}, {})


@pytest.mark.parametrize("family", FAMILY_NAMES)
def test_the_dict_form_round_trips(family):
    cell = UnitCell(family=family)
    assert UnitCell.from_dict(cell.to_dict()) == cell
    assert cell.to_dict()["family"] == family


# -- meshes -------------------------------------------------------------------------------------

@pytest.fixture(scope="module", params=NEW)
def family_sample(request):
    sample = Sample(cell_of(request.param), cells=(1, 1))  # the default mesh resolution
    return sample, sample.meshes()


def test_every_yarn_is_closed_oriented_and_inside_the_box(family_sample):
    sample, meshes = family_sample
    kinds = {yarn.kind for yarn, _ in meshes}
    assert kinds >= {"weft", "warp" if sample.cell.family in PLIES else "binder"}
    lo, hi = sample.yarn_box
    for yarn, mesh in meshes:
        assert is_manifold(mesh) and mesh.is_winding_consistent and mesh.volume > 0, yarn.name
        assert np.all(mesh.bounds[0] >= lo - 1e-9) and np.all(mesh.bounds[1] <= hi + 1e-9), yarn.name


def _section_area(section, width: float, height: float) -> float:
    """The outline's analytic area (mm²): superellipse 4ab·Γ(1 + 1/n)²/Γ(1 + 2/n) with a, b the
    half-axes; lens of two circular segments of chord ``width`` and height ``height``/2."""
    a, b = width / 2, height / 2
    if section.shape == "power_ellipse":
        n = section.exponent
        return 4 * a * b * math.gamma(1 + 1 / n) ** 2 / math.gamma(1 + 2 / n)
    if section.shape == "lenticular":
        radius = (a * a + b * b) / (2 * b)
        return 2 * (radius * radius * math.acos((radius - b) / radius) - (radius - b) * a)
    raise AssertionError(section.shape)


def _inside_length(nodes: np.ndarray, axis: int, lo: float, hi: float) -> float:
    """Length (mm) of the polyline through ``nodes`` where its ``axis`` coordinate lies in [lo, hi]."""
    t = np.linspace(0.0, 1.0, 2001)
    total = 0.0
    for p, q in zip(nodes[:-1], nodes[1:]):
        points = p + t[:, None] * (q - p)
        keep = (points[:, axis] >= lo) & (points[:, axis] <= hi)
        total += np.linalg.norm(q - p) * keep[:-1].mean()
    return total


def test_the_yarn_volume_is_the_analytic_cells(family_sample):
    """Σ section area × centre-line length in the cell, the binders' length along the straight runs
    between their nodes (the spline through them is smooth, a little longer), against the clipped
    meshes' volume before the overlaps are settled: within 2 % (fibre volume fraction = the fibre
    share of the bundles times this)."""
    sample, meshes = family_sample
    cell = sample.cell
    size = cell.size
    weft_area = _section_area(cell.weft_section, cell.weft_width, cell.weft_height)
    warp_area = _section_area(cell.warp_section, cell.warp_width, cell.warp_height)
    if cell.family in PLIES:  # every yarn undulates
        analytic = sum((weft_area if yarn.family == "weft" else warp_area)
                       * _inside_length(yarn.nodes, 0 if yarn.family == "weft" else 1, 0.0, size[0 if yarn.family == "weft" else 1])
                       for yarn in sample.yarns())
    else:
        analytic = len(cell.weft_y) * cell.weft_layers * weft_area * size[0]
        analytic += len(cell.stuffer_x) * cell.stuffers * warp_area * size[1]
    for yarn in sample.yarns():
        if yarn.kind == "binder":
            analytic += warp_area * _inside_length(yarn.nodes, 1, 0.0, size[1])
    measured = sum(mesh.volume for _, mesh in meshes)
    print(cell.family, "yarn volume fraction", measured / np.prod(size), "analytic", analytic / np.prod(size))
    assert abs(measured / analytic - 1) < 0.02


@pytest.mark.parametrize("family", NEW)
def test_the_same_file_and_seed_give_the_same_bytes(family):
    def digest(seed: int) -> str:
        table = {"family": family, **({"plies": 2, "ply_shift_mm": [0.4, 0.2]} if family in PLIES else {"weft_layers": 3}),
                 "sample": {"cells": [1, 1], "seed": seed, **COARSE},
                 "distortion": {"weft_node_mm": [0.0, 0.05, 0.03], "warp_node_mm": [0.05, 0.0, 0.03],
                                "weft_scale": [0.03, 0.03], "warp_scale": [0.03, 0.03]}}
        sample, _ = weave_from_dict(table, {})
        h = hashlib.sha256()
        for _, mesh in sample.meshes():
            h.update(np.ascontiguousarray(mesh.vertices).tobytes() + np.ascontiguousarray(mesh.faces).tobytes())
        return h.hexdigest()

    assert digest(3) == digest(3) != digest(4)


# -- labels -------------------------------------------------------------------------------------

def test_labels_agree_with_an_independent_inside_test(gl, family_sample):
    """The label volume of the sample's scene at random voxel centres against trimesh's ray-parity
    inside test with the scene's priorities (warp over weft over matrix); only centres within
    1e-3 voxel of a surface may differ."""
    sample, _ = family_sample
    scene = sample.scene()
    lo, hi = sample.box
    grid = VolumeGeometry(shape=(24, 48, 48), voxel_size=float(max(hi - lo) / 46),
                          offset=tuple(((lo + hi) / 2)[::-1]))
    labels = voxelize(scene, grid, context=gl).data
    rng = np.random.default_rng(0)
    idx = np.stack([rng.integers(0, n, 4000) for n in grid.shape], axis=1)
    centres = np.stack([grid.axis_centres(2)[idx[:, 2]], grid.axis_centres(1)[idx[:, 1]],
                        grid.axis_centres(0)[idx[:, 0]]], axis=1)
    want = np.zeros(len(centres), np.int64)
    best = np.full(len(centres), -np.inf)
    for number, obj in enumerate(scene.objects):
        mesh = trimesh.Trimesh(obj.mesh.vertices, obj.mesh.faces, process=False)
        owns = mesh.contains(centres) & (obj.priority + 1e-6 * number > best)
        want[owns], best[owns] = obj.label, obj.priority + 1e-6 * number
    got = labels[idx[:, 0], idx[:, 1], idx[:, 2]]
    differ = np.flatnonzero(got != want)
    if differ.size:
        meshes = [trimesh.Trimesh(o.mesh.vertices, o.mesh.faces, process=False) for o in scene.objects]
        distance = np.min([np.abs(trimesh.proximity.signed_distance(m, centres[differ])) for m in meshes], axis=0)
        assert np.all(distance <= 1e-3 * min(grid.voxel_size)), centres[differ][distance > 1e-3 * min(grid.voxel_size)]
    assert set(np.unique(want)) == {0, 1, 2, 3}


def test_binders_may_be_a_class_of_their_own_and_stuffers_stay_warp():
    sample = Sample(UnitCell(family="orthogonal", weft_layers=3, warp_positions=2), cells=(1, 1), **COARSE)
    kinds = {yarn.name: yarn.kind for yarn in sample.yarns()}
    scene = sample.scene(binder_label=True)
    by_kind = {}
    for obj in scene.objects[1:]:  # the matrix first
        by_kind.setdefault(kinds[obj.name], set()).add((obj.label, obj.priority))
    assert by_kind == {"weft": {(2, 1)}, "stuffer": {(3, 2)}, "binder": {(4, 2)}}
    assert {(o.label, o.priority) for o in sample.scene().objects} == {(1, 0), (2, 1), (3, 2)}  # the default
    parts, _ = sample.parts(per="family", binder_label=True, measure=False)
    assert [(p.name, p.label) for p in parts] == [("matrix", 1), ("weft", 2), ("warp", 3), ("binder", 4)]
