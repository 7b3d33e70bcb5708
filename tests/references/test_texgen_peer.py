"""The TexGen peer (references/texgen.py): its overlap measure, its input checks and, where
pytexgen is installed, the frame and pattern mapping of TexGen's layer-to-layer textile and the
same orthogonal and 2D cells from both."""

import math

import numpy as np
import pytest
import trimesh

from references.texgen import (
    texgen_available,
    texgen_layer_to_layer,
    texgen_weave_2d,
    yarn_overlap,
)
from xrayraster.core.errors import WeaveError
from xrayraster.weave import UnitCell


def test_yarn_overlap_sums_shared_volume_and_counts_open_meshes():
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[0.5, 0, 0], [1.5, 1, 1]])  # shares 0.5 x 1 x 1 with a
    c = trimesh.creation.box(bounds=[[0, 1, 0], [2, 2, 1]])      # only touches a and b
    d = trimesh.creation.box(bounds=[[0.25, 0.25, 0.25], [0.75, 0.75, 2]])  # 0.5 x 0.5 x 0.75 in a, 0.25 x 0.5 x 0.75 in b
    hole = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    hole = trimesh.Trimesh(hole.vertices, hole.faces[:-2], process=False)  # one side removed: not closed
    volume, refused = yarn_overlap([a, b, c, d, hole])
    assert refused == 1
    assert volume == pytest.approx(0.5 + 0.5 * 0.5 * 0.75 + 0.25 * 0.5 * 0.75, abs=1e-9)


@pytest.mark.parametrize("kwargs, field", [
    ({"cell": UnitCell(stuffers=1)}, "stuffers"),
    ({"cell": UnitCell(binders=1)}, "binder_position"),  # warp positions 1..3 hold no binder
    ({"cell": UnitCell(warp_positions=1, binders=2, binder_path=((1, 1, 1, 1), (3, 3, 3, 3)))}, "binder_path"),
    ({"cells": (0, 1)}, "cells"),
    ({"resolution": 3}, "resolution"),
    ({"cell": "default"}, "cell"),
    ({"cell": UnitCell(family="orthogonal", warp_positions=2, warp_ratio=2)}, "warp_ratio"),
])
def test_cells_texgen_cannot_build_are_refused_before_texgen_runs(kwargs, field):
    args = {"cell": UnitCell(), "cells": (1, 1), "resolution": 12} | kwargs
    with pytest.raises(WeaveError, match=field):
        texgen_layer_to_layer(**args)


@pytest.mark.skipif(texgen_available() is not None, reason=f"TexGen peer: {texgen_available()}")
def test_texgen_textile_lands_on_our_cell():
    # Unequal spacings and counts in x and y and two cells along x only: a swapped axis, a wrong
    # tile or a wrong binder stack shows in the counts, the box or the binder heights.
    cell = UnitCell(weft_per_layer=4, warp_positions=3, weft_layers=4, warp_spacing=2.0, weft_spacing=3.0,
                    thickness=3.6, margin_z=0.4)
    nx, ny = 2, 1
    result = texgen_layer_to_layer(cell, (nx, ny), resolution=12)
    sx, sy, sz = cell.size
    kinds = list(result.kinds)
    assert kinds.count("weft") == cell.weft_per_layer * cell.weft_layers * ny
    assert kinds.count("binder") == cell.binders * nx
    points = np.vstack([m.vertices for m in result.meshes])
    assert np.all(points.min(axis=0) >= -1e-9)
    assert np.all(points.max(axis=0) <= np.array([nx * sx, ny * sy, sz]) + 1e-9)

    wefts = [m for m, k in zip(result.meshes, kinds) if k == "weft"]
    assert all(m.is_watertight for m in wefts)
    centres = sorted((round(float(m.centroid[1]), 9), round(float(m.centroid[2]), 9)) for m in wefts)
    expected = sorted((round(y, 9), round(z, 9)) for y in cell.weft_y for z in cell.weft_layer_z)
    assert np.allclose(centres, expected, atol=1e-6)
    # TexGen's power ellipse has our superellipse's area, 4ab·Γ(1 + 1/3)²/Γ(1 + 2/3); its 12-point
    # outline is inscribed in it, a few per cent smaller (a swapped height would be 20 % off).
    a, b = cell.weft_width / 2, cell.weft_height / 2
    smooth = 4 * a * b * math.gamma(1 + 1 / 3) ** 2 / math.gamma(1 + 2 / 3)
    for m in wefts:
        assert m.extents[:2] == pytest.approx([nx * sx, cell.weft_width])
        assert 0.9 * smooth < m.volume / (nx * sx) < smooth

    # Every binder sits at its gap's height over the middle of every weft column it crosses.
    matched = set()
    for mesh, kind in zip(result.meshes, kinds):
        if kind != "binder":
            continue
        x = float(mesh.bounds.mean(axis=0)[0])
        cx, pos = int(x // sx), round((x % sx) / cell.warp_spacing - 0.5)
        heights = []
        for j, y in enumerate(cell.weft_y):
            near = mesh.vertices[np.abs(mesh.vertices[:, 1] - y) < 0.3]
            heights.append((near[:, 2].max() + near[:, 2].min()) / 2)
        fits = [b for b in range(cell.binders) if cell.binder_position[b] == pos and
                max(abs(h - cell.gap_z(g)) for h, g in zip(heights, cell.binder_path[b])) < 0.05 * cell.warp_height]
        assert len(fits) == 1
        matched.add((cx, fits[0]))
    assert len(matched) == cell.binders * nx


@pytest.mark.skipif(texgen_available() is not None, reason=f"TexGen peer: {texgen_available()}")
def test_an_orthogonal_cell_matches_texgens():
    """The same orthogonal cell from both (TexGen: its layer-to-layer textile with one binder a
    position moved between the stack's top and bottom): the yarn volume fraction within 3 %, and
    the binders' centre lines, TexGen's path points against ours, 0.1 of the binder's height apart
    in RMS (at most a quarter where TexGen wraps the weft's corner and ours turns on its spline)."""
    from xrayraster.weave import Sample

    cell = UnitCell(family="orthogonal", weft_layers=3, weft_per_layer=4, warp_positions=2)
    theirs = texgen_layer_to_layer(cell, (1, 1), resolution=24)
    sample = Sample(cell, cells=(1, 1))
    assert abs(_yarn_volume_ratio(sample, theirs) - 1) < 0.03

    curves = {round(float(yarn.nodes[0, 0]), 6): _curve(yarn, 10000) for yarn in sample.yarns() if yarn.kind == "binder"}
    lines = [line for line, kind in zip(theirs.centrelines, theirs.kinds) if kind == "binder"]
    assert len(lines) == len(curves) == cell.warp_positions
    for line in lines:
        line = line[(line[:, 1] >= 0) & (line[:, 1] <= cell.size[1])]  # the path inside the cell
        ours = curves[round(float(line[0, 0]), 6)]
        distance = np.min(np.linalg.norm(line[:, None, :] - ours[None, :, :], axis=2), axis=1)
        assert np.sqrt(np.mean(distance**2)) < 0.1 * cell.warp_height
        assert distance.max() < 0.25 * cell.warp_height


@pytest.mark.parametrize("kwargs, message", [
    ({"plies": 2}, "one ply"),
    ({"weft_spacing": 3.0}, "equal spacings"),
    ({"warp_section": "lenticular"}, "ellipse"),
])
def test_2d_cells_texgen_cannot_build_are_refused(kwargs, message):
    cell = UnitCell(family="plain", **{"plies": 1, "warp_section": "ellipse", "weft_section": "ellipse", **kwargs})
    with pytest.raises(WeaveError, match=message):
        texgen_weave_2d(cell)


@pytest.mark.skipif(texgen_available() is not None, reason=f"TexGen peer: {texgen_available()}")
@pytest.mark.parametrize("family", ["plain", "twill", "satin"])
def test_a_2d_cell_matches_texgens(family):
    """The same one-ply cell from both (TexGen's CTextileWeave2D, its pattern swapped to ours): the
    yarn volume fraction within 3 %, and every yarn's centre line, TexGen's path points against our
    spline, within a tenth of a yarn's height (measured: plain 0.0007 mm RMS, 0.001 at most, for
    yarns 0.5 mm high)."""
    from xrayraster.weave import Sample

    cell = UnitCell(family=family, plies=1, warp_section="ellipse", weft_section="ellipse", thickness=1.2)
    theirs = texgen_weave_2d(cell)
    sample = Sample(cell, cells=(1, 1))
    assert abs(_yarn_volume_ratio(sample, theirs) - 1) < 0.03
    curves = {(yarn.family, round(float(yarn.nodes[0, 1 if yarn.family == "weft" else 0]), 6)): _curve(yarn, 20000)
              for yarn in sample.yarns()}
    assert len(theirs.centrelines) == cell.warp_positions + cell.weft_per_layer
    for line, kind in zip(theirs.centrelines, theirs.kinds):
        along = 0 if kind == "weft" else 1
        line = line[(line[:, along] >= 0) & (line[:, along] <= cell.size[along])]  # the path inside the cell
        ours = curves[(kind, round(float(line[0, 1 - along]), 6))]
        distance = np.min(np.linalg.norm(line[:, None, :] - ours[None, :, :], axis=2), axis=1)
        height = cell.weft_height if kind == "weft" else cell.warp_height
        assert distance.max() < 0.1 * height


def _yarn_volume_ratio(sample, theirs) -> float:
    """Our sample's yarn volume over TexGen's (the same cell, so the same box)."""
    return sum(mesh.volume for _, mesh in sample.meshes()) / sum(mesh.volume for mesh in theirs.meshes)


def _curve(yarn, points: int) -> np.ndarray:
    """``points`` points along our yarn's centre line (its spline), end to end."""
    from xrayraster.weave.sweep import CubicSpline3

    spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
    return spline(np.linspace(0.0, spline.length_parameter, points))
