"""Random distortions of woven samples (xrayraster.weave.distort): the regular weave at amplitude 0,
reproducibility from the seed, amplitudes as bounds, smoothness across cell borders, closed meshes,
validation and the dict and textomos forms."""

from __future__ import annotations

import hashlib
import itertools
import re

import manifold3d
import numpy as np
import pytest

from references.solids import is_manifold, solid
from xrayraster.core.errors import ConfigError, WeaveError
from xrayraster.weave import Distortion, Sample, UnitCell, read_textomos
from xrayraster.weave.distort import layer_shift
from xrayraster.weave.sample import PLATEAU
from xrayraster.weave.sweep import (
    CubicSpline3,
    ellipse,
    lenticular,
    polygon_area,
    power_ellipse,
    smooth_profile,
    yarn_mesh,
)

COARSE = {"points_per_section": 12, "samples_per_mm": 2.0}
NODES = {"weft_node_mm": (0.12, 0.1, 0.03), "warp_node_mm": (0.08, 0.15, 0.02)}
FULL = Distortion(**NODES, weft_scale=(0.05, 0.08), warp_scale=(0.06, 0.04), weft_rotation_deg=3.0,
                  warp_rotation_deg=2.0, layer_shift_mm=(1.5, 2.0), waviness_mm=0.1, waviness_wavelength_mm=12.0)


def _stl_hashes(sample) -> dict:
    return {yarn.name: hashlib.sha256(mesh.export(file_type="stl")).hexdigest() for yarn, mesh in sample.meshes()}


def _clip(mesh, box) -> manifold3d.Manifold:
    s = solid(mesh)
    assert s.status() == manifold3d.Error.NoError
    return s ^ box


def _regular_node(cell, name: str) -> np.ndarray:
    """The undistorted nodes of a yarn of a 1 × 1 sample, from its name, by hand (no layer shift): a
    weft's at x = (c + 0.5) · warp_spacing for c = -1 .. 4; a binder's plateaus as in test_weave_sample."""
    sx, _, sz = cell.size
    if m := re.fullmatch(r"weft_c(\d+)_l(\d+)_y(-?\d+)", name):
        cz, layer, jy = map(int, m.groups())
        xs = (np.arange(-1, 5) + 0.5) * cell.warp_spacing                  # 1 x 1 cell, 4 warp columns
        return np.column_stack([xs, np.full(6, (jy + 0.5) * cell.weft_spacing),
                                np.full(6, cz * sz + cell.weft_layer_z[layer])])
    m = re.fullmatch(r"binder_c(\d+)_x(-?\d+)_b(\d+)", name)
    cz, cx, b = map(int, m.groups())
    columns = np.arange(-1, 5)
    ys = ((columns + 0.5) * cell.weft_spacing)[:, None] + np.array(PLATEAU) * cell.weft_width / 2
    zs = [cz * sz + cell.gap_z(cell.binder_path[b][j % 4]) for j in columns]
    return np.column_stack([np.full(24, cx * sx + cell.binder_x[b]), ys.ravel(), np.repeat(zs, 4)])


# ---------------------------------------------------------------------------- amplitude 0, seeds


def test_zero_distortion_is_the_regular_weave_bit_for_bit():
    cell = UnitCell()
    zero = Distortion(waviness_wavelength_mm=3.0)        # a wavelength alone distorts nothing
    sample = Sample(cell, cells=(1, 1), distortion=zero, seed=987, **COARSE)
    got = {yarn.name: (yarn, mesh) for yarn, mesh in sample.meshes()}
    # the regular weave built here from its definition: straight wefts 0.5 mm past the box, binder
    # plateaus over the columns -1 .. 4, each swept and clipped to the box
    clip = manifold3d.Manifold.cube((10.0, 10.0, 4.0))
    weft = power_ellipse(cell.weft_width, cell.weft_height, 3.0, 12)
    warp = lenticular(cell.warp_width, cell.warp_height, 12)
    expected = {}
    for layer, z in enumerate(cell.weft_layer_z):
        for j, y in enumerate(cell.weft_y):
            expected[f"weft_c0_l{layer}_y{j}"] = (np.array([[-0.5, y, z], [10.5, y, z]]), weft, None)
    for b in range(16):
        expected[f"binder_c0_x0_b{b}"] = (_regular_node(cell, f"binder_c0_x0_b{b}"), warp, ((0, 1, 0), (0, 1, 0)))
    assert set(got) == set(expected)
    for name, (nodes, outline, ends) in expected.items():
        yarn, mesh = got[name]
        assert np.array_equal(yarn.nodes, nodes) and yarn.section_scale is None
        ref = _clip(yarn_mesh(nodes, outline, 2.0, end_tangents=ends, sagitta_mm=sample.path_sagitta_mm),
                    clip).to_mesh64()
        assert mesh.vertices.tobytes() == np.asarray(ref.vert_properties)[:, :3].tobytes()
        assert mesh.faces.tobytes() == np.asarray(ref.tri_verts, dtype=np.int64).tobytes()


def test_same_seed_gives_identical_mesh_files_and_another_seed_different_ones():
    cell = UnitCell()
    first = _stl_hashes(Sample(cell, cells=(1, 1), distortion=FULL, seed=7, **COARSE))
    again = _stl_hashes(Sample(cell, cells=(1, 1), distortion=FULL, seed=7, **COARSE))
    other = _stl_hashes(Sample(cell, cells=(1, 1), distortion=FULL, seed=8, **COARSE))
    assert first == again
    common = set(first) & set(other)
    assert len(common) >= 30 and all(first[name] != other[name] for name in common)


def test_a_yarns_distortion_does_not_depend_on_the_other_yarns():
    # binder b of cell x0 has the same nodes (the same weft columns) in a 1 x 1 and a 2 x 1 sample,
    # which hold other yarns besides, in another order
    cell = UnitCell()
    d = Distortion(**NODES, warp_scale=(0.1, 0.1), waviness_mm=0.1, waviness_wavelength_mm=12.0)
    one = {y.name: y for y in Sample(cell, cells=(1, 1), distortion=d, seed=3).yarns()}
    two = {y.name: y for y in Sample(cell, cells=(2, 1), distortion=d, seed=3).yarns()}
    for b in range(16):
        name = f"binder_c0_x0_b{b}"
        assert np.array_equal(one[name].nodes, two[name].nodes)
        assert np.array_equal(one[name].section_scale, two[name].section_scale)
    # while two yarns draw differently
    offsets = [one[n].nodes - _regular_node(cell, n) for n in ("binder_c0_x0_b0", "binder_c0_x0_b1")]
    assert np.abs(offsets[0] - offsets[1]).max() > 0.01


# ---------------------------------------------------------------------------- amplitudes are bounds


def test_node_displacements_stay_within_their_amplitudes():
    cell = UnitCell()
    d = Distortion(**NODES)
    moved = {"weft": [], "binder": []}
    for yarn in Sample(cell, cells=(1, 1), distortion=d, seed=11).yarns():
        offset = yarn.nodes - _regular_node(cell, yarn.name)
        moved[yarn.kind].append(offset)
        if yarn.kind == "binder":                          # a plateau moves as one: it stays flat
            groups = offset.reshape(-1, len(PLATEAU), 3)
            assert np.ptp(groups, axis=1).max() < 1e-12
    for kind, amplitude in (("weft", d.weft_node_mm), ("binder", d.warp_node_mm)):
        offsets = np.abs(np.concatenate(moved[kind]))
        assert np.all(offsets <= np.array(amplitude) + 1e-12)
        assert np.all(offsets.max(axis=0) > 0.8 * np.array(amplitude))   # uniform draws fill their range


def test_waviness_is_in_plane_across_the_yarn_and_bounded():
    cell = UnitCell()
    d = Distortion(waviness_mm=0.2, waviness_wavelength_mm=10.0)
    largest = {"weft": 0.0, "binder": 0.0}
    for yarn in Sample(cell, cells=(1, 1), distortion=d, seed=5).yarns():
        offset = yarn.nodes - _regular_node(cell, yarn.name)
        across = 1 if yarn.kind == "weft" else 0            # y for a weft, x for a warp
        assert np.all(np.abs(np.delete(offset, across, axis=1)) < 1e-12)
        assert np.all(np.abs(offset[:, across]) <= 0.2 + 1e-12)
        largest[yarn.kind] = max(largest[yarn.kind], np.abs(offset[:, across]).max())
    assert min(largest.values()) > 0.05


def test_layer_shift_moves_each_layer_of_cells_as_one():
    cell = UnitCell()
    sx = cell.size[0]
    d = Distortion(layer_shift_mm=(2.0, 3.0))
    sample = Sample(cell, cells=(1, 1), layers_of_cells=2, distortion=d, seed=2, **COARSE)
    shifts = {0: set(), 1: set()}
    for yarn in sample.yarns():
        cz = int(yarn.name.split("_")[1][1:])
        if yarn.kind == "weft":                              # its y gives dy; its nodes' x lie on the shifted grid
            jy = int(yarn.name.split("_y")[1])
            dy = yarn.nodes[0, 1] - (jy + 0.5) * cell.weft_spacing
            assert np.ptp(yarn.nodes[:, 1:], axis=0).max() < 1e-12
            shifts[cz].add(("dy", round(float(dy), 9)))
            grid = yarn.nodes[:, 0] / cell.warp_spacing - 0.5
            shifts[cz].add(("x phase", round(float(np.mean(grid - np.round(grid))), 9)))
        else:                                                # its x gives dx; plateaus sit over the shifted columns
            cx, b = map(int, re.fullmatch(r"binder_c\d+_x(-?\d+)_b(\d+)", yarn.name).groups())
            dx = yarn.nodes[0, 0] - (cx * sx + cell.binder_x[b])
            shifts[cz].add(("x phase", round(float(dx / cell.warp_spacing - np.round(dx / cell.warp_spacing)), 9)))
            centres = yarn.nodes.reshape(-1, len(PLATEAU), 3).mean(axis=1)
            shifts[cz].add(("y phase", round(float(np.mean(centres[:, 1] / cell.weft_spacing - 0.5) % 1), 6)))
    for cz in (0, 1):
        kinds = {k for k, _ in shifts[cz]}
        assert kinds == {"dy", "x phase", "y phase"} and len(shifts[cz]) == 3   # one shift per layer
        (dy,) = [v for k, v in shifts[cz] if k == "dy"]
        (y_phase,) = [v for k, v in shifts[cz] if k == "y phase"]
        assert abs(dy) <= 3.0 and abs((dy / cell.weft_spacing) % 1 - y_phase) < 1e-6
    assert shifts[0] != shifts[1]


def _ellipse_cell() -> UnitCell:
    return UnitCell(weft_section="ellipse", warp_section="ellipse")


def test_section_scale_and_rotation_stay_within_bounds_at_every_sample():
    cell = _ellipse_cell()
    d = Distortion(weft_scale=(0.1, 0.2), weft_rotation_deg=5.0)
    k = 16
    sample = Sample(cell, cells=(1, 1), distortion=d, seed=4, points_per_section=k, samples_per_mm=4.0)
    wefts = [y for y in sample.yarns() if y.kind == "weft"]
    widths, heights, turns = [], [], []
    for yarn in wefts:
        mesh = yarn.mesh(4.0)
        rings = mesh.vertices[:-2].reshape(-1, k, 3)
        across = rings[:, 0] - rings[:, k // 2]             # the ellipse's width axis, end to end
        up = rings[:, k // 4] - rings[:, 3 * k // 4]         # its height axis
        widths.append(np.linalg.norm(across, axis=1) / cell.weft_width)
        heights.append(np.linalg.norm(up, axis=1) / cell.weft_height)
        turns.append(np.degrees(np.arctan2(across[:, 2], across[:, 1])))  # a straight weft's frame: U = +y, V = +z
    widths, heights, turns = map(np.concatenate, (widths, heights, turns))
    assert np.all(np.abs(widths - 1) <= 0.1 + 1e-9) and np.abs(widths - 1).max() > 0.07
    assert np.all(np.abs(heights - 1) <= 0.2 + 1e-9) and np.abs(heights - 1).max() > 0.14
    assert np.all(np.abs(turns) <= 5.0 + 1e-9) and np.abs(turns).max() > 3.5


# ---------------------------------------------------------------------------- smoothness, meshes


def test_a_distorted_binder_is_c2_and_continuous_across_a_cell_border():
    d = Distortion(**NODES, warp_scale=(0.1, 0.1), warp_rotation_deg=4.0, waviness_mm=0.1,
                   waviness_wavelength_mm=12.0)
    sample = Sample(UnitCell(), cells=(1, 2), distortion=d, seed=9)
    binders = [y for y in sample.yarns() if y.name.startswith("binder_c0_x0_")]
    assert len(binders) == 16                               # one path through both cells, not two
    for yarn in binders[:4]:
        assert yarn.nodes[0, 1] < 0 and yarn.nodes[-1, 1] > 20
        spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
        h = 2e-3
        t = np.arange(0.0, spline.knots[-1], h)
        p = spline(t)
        second = (p[2:] - 2 * p[1:-1] + p[:-2]) / h**2
        # C²: the second difference changes by at most h × the largest third derivative (a cubic
        # spline's is piecewise constant), at the cell border (y = 10) as anywhere else
        third = np.abs(np.diff(spline.second, axis=0) / np.diff(spline.knots)[:, None]).max()
        jumps = np.linalg.norm(np.diff(second, axis=0), axis=1)
        assert jumps.max() <= 1.05 * np.sqrt(3) * third * h + 1e-6
        border = np.abs(p[1:-2, 1] - 10.0) < 1.0             # the second differences next to the border
        assert border.sum() > 100 and jumps[border].max() <= 1.05 * np.sqrt(3) * third * h + 1e-6
        assert np.linalg.norm(np.diff(p, axis=0), axis=1).max() <= 1.5 * h   # no jump in position
        profile = smooth_profile(spline.knots, yarn.section_scale, t)        # the section: no jump either
        assert np.abs(np.diff(profile, axis=0)).max() < 0.01


def test_distorted_meshes_are_closed_manifold_and_outward():
    sample = Sample(UnitCell(), cells=(1, 1), distortion=FULL, seed=1, **COARSE)
    meshes = sample.meshes()
    lo, hi = sample.yarn_box
    for yarn, mesh in meshes:
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, yarn.name
        assert is_manifold(mesh), yarn.name
        assert np.all(mesh.bounds[0] >= lo - 1e-9) and np.all(mesh.bounds[1] <= hi + 1e-9)


def test_the_box_stays_covered_with_a_layer_shift():
    """Each weft layer still spans the box in y after shifts of up to 4.6 mm (of a 10 mm period)."""
    cell = UnitCell()
    d = Distortion(layer_shift_mm=(5.0, 5.0))
    clip = manifold3d.Manifold.cube((10.0, 10.0, 4.0))
    slivers = []
    for seed in (0, 1, 3):
        assert abs(layer_shift(d, seed, 0)[1]) > 3.0          # shifts that would bare 3 mm of the box
        sample = Sample(cell, cells=(1, 1), distortion=d, seed=seed, **COARSE)
        meshes = sample.meshes()
        kept = {yarn.name for yarn, _ in meshes}
        for yarn in sample.yarns():                          # what was dropped: the slivers, by an own clip
            if yarn.name not in kept:
                full = polygon_area(yarn.outline) * 10.0
                slivers.append(_clip(yarn.mesh(2.0), clip).volume() / full)
        per_layer = {}
        for yarn, mesh in meshes:
            if yarn.kind == "weft":
                per_layer.setdefault(yarn.name.split("_")[2], []).append(tuple(mesh.bounds[:, 1]))
        assert len(per_layer) == 5
        for spans in per_layer.values():
            spans = sorted(spans)
            gaps = [b[0] - a[1] for a, b in itertools.pairwise(spans)]
            # wefts 0.9 of their 2.5 mm spacing wide leave 0.25 mm between them; at a face, a dropped
            # sliver (under 10 % of the section) is less than a fifth of the 2.25 mm width
            assert max(gaps) <= 0.25 + 1e-9
            assert spans[0][0] <= 0.25 + 0.2 * 2.25 and spans[-1][1] >= 10 - 0.25 - 0.2 * 2.25
    assert max(slivers) < 0.1 and sum(v > 0.001 for v in slivers) >= 3


# ---------------------------------------------------------------------------- validation


@pytest.mark.parametrize("kwargs, field", [
    ({"weft_node_mm": (0.1, -0.1, 0.0)}, r"weft_node_mm\[1\]"),
    ({"warp_node_mm": (0.1, 0.1)}, "warp_node_mm"),
    ({"weft_scale": (0.1, float("nan"))}, r"weft_scale\[1\]"),
    ({"warp_scale": (1.0, 0.1)}, r"warp_scale\[0\] must be < 1"),
    ({"weft_rotation_deg": 90.0}, "weft_rotation_deg"),
    ({"warp_rotation_deg": -1.0}, "warp_rotation_deg"),
    ({"layer_shift_mm": "1 1"}, "layer_shift_mm"),
    ({"waviness_mm": float("inf")}, "waviness_mm"),
    ({"waviness_wavelength_mm": 0.0}, "waviness_wavelength_mm"),
])
def test_bad_amplitudes_name_the_field(kwargs, field):
    with pytest.raises(WeaveError, match=field):
        Distortion(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    ({"distortion": Distortion(weft_node_mm=(0.7, 0.0, 0.0))}, r"weft_node_mm\[0\].*along the weft.*0\.625"),
    ({"distortion": Distortion(warp_node_mm=(0.0, 0.35, 0.0))}, r"warp_node_mm\[1\].*along the warp.*0\.34"),
    ({"distortion": Distortion(waviness_mm=0.1, waviness_wavelength_mm=9.0)}, r"waviness_wavelength_mm.*>= 4"),
    ({"distortion": Distortion(layer_shift_mm=(0.0, 5.5))}, r"layer_shift_mm\[1\].*half"),
    ({"distortion": {"waviness_mm": 0.1}}, "distortion must be a Distortion"),
    ({"seed": -1}, "seed"), ({"seed": True}, "seed"), ({"seed": 1.0}, "seed"),
])
def test_sample_level_limits_name_the_field_and_the_fix(kwargs, match):
    with pytest.raises(WeaveError, match=match):
        Sample(UnitCell(), **kwargs)


def test_a_yarn_folded_by_its_distortion_is_named_with_the_seed_and_the_fix():
    # waviness of 5 mm at a 10 mm wavelength bends with radii near λ² / (4π² a) = 0.5 mm, below the
    # weft's 1.125 mm half-width: the mesher's bend limit refuses it
    d = Distortion(waviness_mm=5.0, waviness_wavelength_mm=10.0)
    with pytest.raises(WeaveError, match=r"^yarn [\w-]+: the yarn path bends .* \(distortion seed 4: lower"):
        Sample(UnitCell(), cells=(1, 1), distortion=d, seed=4, **COARSE).meshes()


def test_node_displacement_at_its_along_yarn_limit_keeps_the_nodes_in_order():
    # the default cell: along a weft the nodes are 2.5 mm apart (limit 0.625 mm); along a binder the
    # runs between plateaus are 2.5 - 0.5 * 2.25 = 1.375 mm (limit 0.34375 mm)
    d = Distortion(weft_node_mm=(0.625, 0.0, 0.0), warp_node_mm=(0.0, 0.34375, 0.0))
    for yarn in Sample(UnitCell(), cells=(2, 2), distortion=d, seed=0).yarns():
        axial = yarn.nodes[:, 0 if yarn.kind == "weft" else 1]
        assert np.all(np.diff(axial) > 0)


# ---------------------------------------------------------------------------- dict and textomos forms


def test_dict_form_round_trips_and_refuses_bad_tables():
    assert Distortion.from_dict(FULL.to_dict()) == FULL
    assert Distortion.from_dict({}) == Distortion()
    assert FULL.to_dict()["weft_node_mm"] == [0.12, 0.1, 0.03]
    bad = [({"weft_nodes_mm": [0, 0, 0]}, "unknown key"), ({"warp_scale": [0.1]}, "warp_scale"),
           ({"waviness_mm": "0.1"}, "waviness_mm"), ({"weft_scale": [1.5, 0.0]}, r"weft_scale\[0\]"),
           ({"layer_shift_mm": [-1.0, 0.0]}, r"layer_shift_mm\[0\]")]
    for table, match in bad:
        with pytest.raises(ConfigError, match=rf"\[weave.distortion\].*{match}"):
            Distortion.from_dict(table)
    with pytest.raises(ConfigError, match=r"^scan.toml \[weave.distortion\]"):
        Distortion.from_dict({"weft_rotation_deg": 95.0}, "scan.toml [weave.distortion]")


def test_from_textomos_by_hand():
    # weft: x/y scaling 10 %, 20 % -> textomos factors in (0.9, 1] and (0.8, 1]: spreads 0.1 and 0.2,
    # so amplitudes 0.05 and 0.1 about 1; rotation and node displacement (mm) as they are
    deform = [10.0, 20.0, 5.0, 0.1, 0.2, 0.3, 30.0, 40.0, 6.0, 0.4, 0.5, 0.6]
    d = Distortion.from_textomos(deform)
    assert d == Distortion(weft_scale=(0.05, 0.1), weft_rotation_deg=5.0, weft_node_mm=(0.1, 0.2, 0.3),
                           warp_scale=(0.15, 0.2), warp_rotation_deg=6.0, warp_node_mm=(0.4, 0.5, 0.6))
    assert Distortion.from_textomos([]) == Distortion() and Distortion.from_textomos([]).is_zero
    with pytest.raises(WeaveError, match="12 numbers"):
        Distortion.from_textomos([1.0] * 6)
    with pytest.raises(WeaveError, match=r"deform\[7\].*<= 100"):
        Distortion.from_textomos([0.0] * 7 + [120.0] + [0.0] * 4)
    textile = {"unit_cell_weft_length": 10.0, "unit_cell_warp_length": 10.0, "unit_cell_thickness": 3.0,
               "weft_yarns_per_layer": 4, "warp_yarns_per_layer": 4, "number_of_yarn_layers": 2,
               "weft_width_to_spacing_ratio": 0.9, "warp_width_to_spacing_ratio": 0.8, "weft_to_warp_ratio": 0.6}
    assert read_textomos(textile).distortion == Distortion()
    imported = read_textomos({**textile, "deform": deform})
    assert imported.distortion == d and imported.deform == tuple(deform)
    with pytest.raises(ConfigError, match=r"textomos textile.*deform\[0\]"):
        read_textomos({**textile, "deform": [101.0] + [0.0] * 11})


def test_distortion_is_zero_only_without_amplitudes():
    assert Distortion().is_zero and Distortion(waviness_wavelength_mm=50.0).is_zero
    for field, value in (("warp_node_mm", (0, 0, 1e-9)), ("weft_scale", (0, 0.01)), ("warp_rotation_deg", 0.5),
                         ("layer_shift_mm", (0.1, 0)), ("waviness_mm", 0.01)):
        assert not Distortion(**{field: value}).is_zero


def test_ellipse_outline_used_in_scale_test_has_its_axes_at_the_quarter_points():
    """The section test reads widths and heights from outline points 0, k/4, k/2, 3k/4."""
    p = ellipse(2.0, 0.5, 16)
    np.testing.assert_allclose(p[[0, 4, 8, 12]], [[1, 0], [0, 0.25], [-1, 0], [0, -0.25]], atol=1e-15)
