"""Regular woven samples (xrayraster.weave.sample): yarn paths, clipped meshes, the scene."""

from __future__ import annotations

import manifold3d
import numpy as np
import pytest

import xrayraster as xr
from references.solids import is_manifold, solid
from xrayraster.core.errors import WeaveError
from xrayraster.weave import Sample, UnitCell
from xrayraster.weave.sample import PLATEAU
from xrayraster.weave.sweep import CubicSpline3, polygon_area, sample_path, yarn_mesh

COARSE = {"points_per_section": 12, "samples_per_mm": 2.0}


@pytest.fixture(scope="module")
def sample_2x1():
    s = Sample(UnitCell(), cells=(2, 1), **COARSE)
    return s, s.meshes()


@pytest.mark.parametrize("kwargs, field", [
    ({"cells": (0, 1)}, "nx"), ({"cells": (1, 0)}, "ny"), ({"cells": (1,)}, "cells"),
    ({"layers_of_cells": 0}, "layers_of_cells"), ({"points_per_section": 10}, "points_per_section"),
    ({"samples_per_mm": 0.0}, "samples_per_mm"),
])
def test_bad_counts_name_the_field(kwargs, field):
    with pytest.raises(WeaveError, match=field):
        Sample(UnitCell(), **kwargs)


def test_yarn_counts_by_hand():
    # default cell: 4 weft per layer, 5 layers, 4 positions x 4 layer pairs = 16 binders
    s = Sample(UnitCell(), cells=(2, 3), layers_of_cells=2, **COARSE)
    kinds = [y.kind for y in s.yarns()]
    assert kinds.count("weft") == 4 * 5 * 3 * 2      # per layer x layers x ny x nz
    assert kinds.count("binder") == 16 * 2 * 2       # per cell x nx x nz
    assert kinds.count("stuffer") == 0
    cell = UnitCell(weft_layers=4, stuffers=2, margin_z=0.5, thickness=4.2)  # 4 stuffer columns, 2 each
    s = Sample(cell, cells=(3, 1), **COARSE)
    kinds = [y.kind for y in s.yarns()]
    assert kinds.count("stuffer") == 4 * 2 * 3
    assert kinds.count("binder") == 4 * 3 * 3
    assert kinds.count("weft") == 4 * 4


def test_binder_path_is_continuous_and_follows_its_gaps():
    cell = UnitCell()
    s = Sample(cell, cells=(1, 2), **COARSE)
    binders = [y for y in s.yarns() if y.kind == "binder"]
    assert len(binders) == 16                        # one path per binder across both cells, not two
    y0 = binders[0]
    # by hand: weft height 0.6*3.2/5 = 0.384, warp height 0.4*3.2/4 = 0.32, pitch 0.704
    gap_z = {0: 0.4 - 0.16, 2: 0.4 + 2 * 0.704 - 0.16}
    path = (2, 2, 0, 0)                              # the default path of binder 0
    per = len(PLATEAU)
    inside = y0.nodes[per:-per].reshape(8, per, 3)   # a plateau of nodes at each of the 8 weft columns
    np.testing.assert_allclose(inside[:, :, 1].mean(axis=1), (np.arange(8) + 0.5) * 2.5)
    np.testing.assert_allclose(inside[:, :, 1] - inside[:, :, 1].mean(axis=1)[:, None],
                               np.tile(np.array(PLATEAU) * 0.9 * 2.5 / 2, (8, 1)), atol=1e-12)
    for k in range(per):
        np.testing.assert_allclose(inside[:, k, 2], [gap_z[path[j % 4]] for j in range(8)], atol=1e-12)
    np.testing.assert_allclose(y0.nodes[:, 0], 1.25)
    assert y0.nodes[0, 1] < 0 and y0.nodes[-1, 1] > 20.0  # runs past the box before the clip


def test_every_mesh_is_closed_oriented_and_manifold(sample_2x1):
    s, meshes = sample_2x1
    for mesh in [s.matrix_mesh()] + [m for _, m in meshes]:
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume > 0
        assert is_manifold(mesh)


def test_yarns_lie_inside_the_box(sample_2x1):
    s, meshes = sample_2x1
    lo, hi = s.box
    np.testing.assert_allclose(s.box, [[0, 0, 0], [20, 10, 4]])
    for _, mesh in meshes:
        assert np.all(mesh.bounds[0] >= lo - 1e-9) and np.all(mesh.bounds[1] <= hi + 1e-9)
    # every weft and every binder is cut flush by both end faces of the box
    for yarn, mesh in meshes:
        axis = 0 if yarn.kind == "weft" else 1
        assert abs(mesh.bounds[0, axis] - lo[axis]) < 1e-12 and abs(mesh.bounds[1, axis] - hi[axis]) < 1e-12


def test_straight_weft_volume_is_the_prism(sample_2x1):
    _, meshes = sample_2x1
    wefts = [(y, m) for y, m in meshes if y.kind == "weft"]
    for yarn, mesh in wefts:
        expected = polygon_area(yarn.outline) * 20.0          # clipped length = nx * 10 mm
        assert abs(mesh.volume - expected) <= 1e-9 * expected


def test_stuffer_volume_is_the_prism():
    cell = UnitCell(weft_layers=3, stuffers=1, weft_share=0.8, warp_section="ellipse")
    s = Sample(cell, cells=(1, 1), **COARSE)
    stuffers = [(y, m) for y, m in s.meshes() if y.kind == "stuffer"]
    assert len(stuffers) == 4
    for yarn, mesh in stuffers:
        expected = polygon_area(yarn.outline) * cell.size[1]
        assert abs(mesh.volume - expected) <= 1e-9 * expected
        assert mesh.is_watertight and mesh.is_winding_consistent


def test_scene_labels_priorities_and_materials():
    s = Sample(UnitCell(), cells=(1, 1), **COARSE)
    scene = s.scene()
    by_name = {o.name: o for o in scene.objects}
    assert len(scene) == 1 + 20 + 16
    assert by_name["matrix"].label == 1 and by_name["matrix"].priority == 0
    families = {"weft": (2, 1), "binder": (3, 2)}
    for o in scene.objects[1:]:
        label, priority = families[o.name.split("_")[0]]
        assert (o.label, o.priority) == (label, priority)
    default = xr.weave.YarnMaterials().resolve()
    assert scene.materials == (default["matrix"], default["weft"])      # equal weft/warp bundles: one channel
    carbon = xr.Material("carbon", ((6, 1.0),), 1.8)
    scene = s.scene({"weft": carbon})
    assert scene.materials == (default["matrix"], carbon, default["warp"])
    with pytest.raises(WeaveError, match="unknown families"):
        s.scene({"resin": "x"})


@pytest.mark.parametrize("cells", [(1, 1), (2, 1), (1, 2)])
def test_binder_centre_line_does_not_overshoot_its_gaps(cells):
    s = Sample(UnitCell(), cells=cells, **COARSE)
    binders = [y for y in s.yarns() if y.kind == "binder"]
    height = s.cell.warp_height
    worst = 0.0
    for yarn in binders:
        spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
        points, _, _ = sample_path(spline, 50.0)     # the sampled path, dense (0.02 mm)
        lo, hi = yarn.nodes[:, 2].min(), yarn.nodes[:, 2].max()
        worst = max(worst, points[:, 2].max() - hi, lo - points[:, 2].min())
    assert worst < 0.01 * height                     # measured 4e-4 mm = 0.13 % (was 0.23 mm)


def test_no_binder_is_cut_by_the_top_or_bottom_face(sample_2x1):
    s1 = Sample(UnitCell(), cells=(1, 1), **COARSE)
    for s, meshes in [(s1, s1.meshes()), sample_2x1]:
        lo, hi = s.yarn_box
        # an independent clip: x/y faces of the yarn box only, 10 mm of room above and below
        tall = manifold3d.Manifold.cube((hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2] + 20.0)).translate(
            (lo[0], lo[1], lo[2] - 10.0))
        binders = [(y, m) for y, m in meshes if y.kind == "binder"]
        assert len(binders) == 16 * s.cells[0]
        for yarn, mesh in binders:
            assert mesh.bounds[0, 2] > lo[2] + 0.05 and mesh.bounds[1, 2] < hi[2] - 0.05
            tube = yarn_mesh(yarn.nodes, yarn.outline, s.samples_per_mm, end_tangents=yarn.end_tangents,
                             sagitta_mm=s.path_sagitta_mm)
            clipped = solid(tube) ^ tall
            assert abs(mesh.volume - clipped.volume()) <= 1e-9 * mesh.volume
