"""The woven unit-cell spec: sizes by hand arithmetic, the default binder pattern's properties, every
bad field named, the dict round trip, and the textomos mapping on a hand-made config."""

from __future__ import annotations

import json
import tomllib

import pytest

from xrayraster.core.errors import ConfigError, WeaveError, XrayrasterError
from xrayraster.weave import Section, UnitCell, read_textomos
from xrayraster.weave.textomos import TEXTOMOS_KEYS


def test_derived_sizes_by_hand():
    c = UnitCell(weft_per_layer=6, weft_layers=3, warp_positions=5, warp_spacing=2.0, weft_spacing=1.5,
                 warp_width_fraction=0.75, weft_width_fraction=0.5, weft_share=0.5, thickness=3.0, margin_z=0.5)
    # stack = 3 - 2*0.5 = 2; weft height = 0.5*2/3; warp height = 0.5*2/2 = 0.5
    assert c.size == pytest.approx((10.0, 9.0, 3.0))
    assert c.stack_thickness == pytest.approx(2.0)
    assert (c.warp_width, c.weft_width) == pytest.approx((1.5, 0.75))
    assert c.weft_height == pytest.approx(1 / 3)
    assert c.warp_height == pytest.approx(0.5)
    assert c.weft_layer_z == pytest.approx((0.5 + 1 / 6, 0.5 + 1 / 6 + 5 / 6, 0.5 + 1 / 6 + 10 / 6))
    # the top weft layer's top face is the stack's top: 0.5 + 2 = 2.5
    assert c.weft_layer_z[-1] + c.weft_height / 2 == pytest.approx(2.5)
    # gaps: 1 sits between weft layers 0 and 1; 0 below the stack, 3 above it
    assert c.gap_z(1) == pytest.approx(0.5 + 1 / 3 + 0.25)
    assert c.gap_z(0) == pytest.approx(0.25) and c.gap_z(3) == pytest.approx(2.75)
    assert c.weft_y == pytest.approx((0.75, 2.25, 3.75, 5.25, 6.75, 8.25))
    assert c.binders == 5 * 2


def test_default_is_a_carbon_cell_of_about_10_10_4_mm():
    c = UnitCell()
    assert all(9.0 <= s <= 11.0 for s in c.size[:2]) and 3.5 <= c.size[2] <= 4.5
    assert 3 <= c.weft_width / c.weft_height <= 10 and 3 <= c.warp_width / c.warp_height <= 10  # flat tows
    assert c.weft_height * c.weft_layers + c.warp_height * (c.weft_layers - 1) == pytest.approx(c.stack_thickness)


@pytest.mark.parametrize("kw", [{}, {"weft_per_layer": 6, "weft_layers": 4, "warp_positions": 3, "thickness": 5.0, "margin_z": 0.6},
                                {"weft_per_layer": 5, "weft_layers": 2, "warp_positions": 2, "thickness": 3.0,
                                 "margin_z": 0.8}])
def test_default_binder_path_is_layer_to_layer_and_staggered(kw):
    c = UnitCell(**kw)
    n, w = c.weft_layers, c.weft_per_layer
    assert len(c.binder_path) == c.binders == c.warp_positions * (n - 1)
    depths = {}
    for pos, path in zip(c.binder_position, c.binder_path):
        assert len(path) == w
        low, high = min(path), max(path)
        assert set(path) == {low, high} and high - low == 2  # under weft layer k, over weft layer k + 1
        depths.setdefault(pos, []).append(low)
    for pos, lows in depths.items():
        assert sorted(lows) == list(range(n - 1)), "each position links every adjacent pair of weft layers once"
    # binders of one position never share a gap in a column
    for pos in depths:
        for j in range(w):
            gaps = [p[j] for q, p in zip(c.binder_position, c.binder_path) if q == pos]
            assert len(gaps) == len(set(gaps))
    # staggered: the positions' patterns are not all in phase
    first = {pos: path for pos, path in reversed(list(zip(c.binder_position, c.binder_path)))}
    if c.warp_positions > 1:
        assert len({tuple(g - min(p) for g in p) for p in first.values()}) > 1


BAD = [
    ({"weft_width_fraction": 1.2}, "weft_width_fraction"),
    ({"warp_width_fraction": 0.0}, "warp_width_fraction"),
    ({"weft_layers": 0}, "weft_layers"),
    ({"weft_layers": 1}, "weft_layers"),
    ({"weft_per_layer": 0}, "weft_per_layer"),
    ({"warp_positions": 0}, "warp_positions"),
    ({"binders": 0}, "binders"),
    ({"warp_spacing": -1.0}, "warp_spacing"),
    ({"weft_spacing": 0.0}, "weft_spacing"),
    ({"thickness": -4.0}, "thickness"),
    ({"margin_z": -0.1}, "margin_z"),
    ({"weft_share": 1.0}, "weft_share"),
    ({"stuffers": 9}, "stuffers"),
    ({"thickness": 0.8, "margin_z": 0.4}, "thickness"),
    ({"margin_z": 0.1}, "margin_z"),  # default binders loop over the outer layers: 0.1 mm is too thin
    ({"binder_path": ((0, 0, 6, 6),) * 16}, r"binder_path\[0\]\[2\]"),
    ({"binders": 1, "binder_path": ((0, 0, -1, 0),)}, r"binder_path\[0\]\[2\]"),
    ({"binders": 1, "binder_path": ((2, 2, 0),)}, r"binder_path\[0\]"),
    ({"binders": 2, "binder_path": ((2, 2, 0, 0),)}, "binder_path"),
    ({"binders": 2, "binder_position": (0, 0), "binder_path": ((2, 2, 0, 0), (2, 1, 1, 1))}, "binder_path"),
    ({"binders": 1, "binder_position": (4,)}, r"binder_position\[0\]"),
    ({"weft_section": Section("circle")}, "weft_section.shape"),
    ({"warp_section": "hexagon"}, "warp_section.shape"),
    ({"weft_section": Section("power_ellipse")}, "weft_section.exponent"),
    ({"weft_section": Section("power_ellipse", exponent=-2.0)}, "weft_section.exponent"),
    ({"weft_section": Section("power_ellipse", exponent=0.0)}, "weft_section.exponent"),
    ({"warp_section": Section("rounded_rectangle")}, "warp_section.corner"),
    ({"warp_section": Section("rounded_rectangle", corner=1.5)}, "warp_section.corner"),
    ({"warp_section": Section("rounded_rectangle", corner=0.0)}, "warp_section.corner"),
    ({"warp_section": Section("ellipse", exponent=1.0)}, "warp_section.exponent"),
]


@pytest.mark.parametrize("kw, field", BAD, ids=[f"{i}-{f}" for i, (_, f) in enumerate(BAD)])
def test_bad_spec_names_the_field(kw, field):
    with pytest.raises(WeaveError, match=field) as info:
        UnitCell(**kw)
    assert isinstance(info.value, (XrayrasterError, ValueError))


def test_dict_round_trip_is_exact_and_toml_ready():
    cells = [UnitCell(), UnitCell(stuffers=2, weft_section="ellipse",
                                  warp_section=Section("rounded_rectangle", corner=0.5), margin_xy=0.3),
             UnitCell(weft_per_layer=3, weft_layers=2, warp_positions=1, binders=1, binder_path=((2, 1, 0),),
                      thickness=3.0, margin_z=0.8)]
    for c in cells:
        d = c.to_dict()
        assert UnitCell.from_dict(d) == c
        assert UnitCell.from_dict(json.loads(json.dumps(d))) == c
        assert set(d) == {"weft_per_layer", "weft_layers", "warp_positions", "binders", "binder_position",
                          "binder_path", "stuffers", "warp_spacing", "weft_spacing", "warp_width_fraction",
                          "weft_width_fraction", "weft_share", "thickness", "weft_section", "warp_section",
                          "margin_xy", "margin_z", "family", "warp_ratio", "binder_ratio"}
    table = tomllib.loads('weft_layers = 3\nmargin_z = 0.7\nbinder_path = [[2, 2, 0, 0], [3, 3, 1, 1]]\nbinders = 2\n'
                          'weft_section = { shape = "power_ellipse", exponent = 0.8 }\n')
    c = UnitCell.from_dict(table)
    assert c.binder_path == ((2, 2, 0, 0), (3, 3, 1, 1)) and c.weft_section.exponent == 0.8


@pytest.mark.parametrize("d, message", [
    ({"weft_layer": 3}, r"x\.toml \[weave\]: unknown key\(s\) weft_layer"),
    ({"weft_layers": 2.5}, r"x\.toml \[weave\]: weft_layers must be an integer"),
    ({"thickness": "4"}, r"x\.toml \[weave\]: thickness must be a number"),
    ({"binder_path": [[2, 2, "a", 0]] * 16}, r"x\.toml \[weave\]: binder_path\[0\]\[2\]"),
    ({"weft_section": {"shape": "ellipse", "power": 1}}, r"x\.toml \[weave\] weft_section: unknown key"),
    ({"weft_width_fraction": 1.5}, r"x\.toml \[weave\]: weft_width_fraction must be <= 1"),
    ({"binder_path": [[9, 9, 9, 9]] * 16}, r"x\.toml \[weave\]: binder_path\[0\]\[0\] = 9 leaves the weft stack"),
])
def test_from_dict_errors_name_where_and_field(d, message):
    with pytest.raises(ConfigError, match=message):
        UnitCell.from_dict(d, "x.toml [weave]")


def _textomos():
    # Hand-made: 4 warp positions of 2 stacked warps (3 weft layers), 4 weft columns; positions 1 and 3
    # are binders pushed up/down a quarter period apart, 0 and 2 straight.
    return {
        "weave_type": "layer2layer", "unit_cell_weft_length": 8.0, "unit_cell_warp_length": 6.0,
        "unit_cell_thickness": 3.0, "weft_yarns_per_layer": 4, "warp_yarns_per_layer": 4,
        "number_of_yarn_layers": 2, "weft_width_to_spacing_ratio": 0.9, "warp_width_to_spacing_ratio": 0.8,
        "weft_to_warp_ratio": 0.6,
        "weave_pattern": [[1, 0, 1], [1, 2, -1], [3, 1, 1], [3, 3, -1]],
        "tiling": [2, 3, 1], "deform": [1.0] * 12, "shift_unit_cell": True, "textile_resolution": 12,
    }


def test_textomos_mapping_by_hand():
    imported = read_textomos(_textomos())
    c = imported.cell
    assert read_textomos(_textomos()).cell == c
    assert (c.weft_per_layer, c.weft_layers, c.warp_positions, c.binders) == (4, 3, 4, 8)
    assert c.warp_spacing == pytest.approx(2.0) and c.weft_spacing == pytest.approx(1.5)  # 8/4, 6/4
    assert c.size[:2] == pytest.approx((8.0, 6.0))
    assert (c.weft_width_fraction, c.warp_width_fraction, c.weft_share) == (0.9, 0.8, 0.6)
    # textomos' heights: weft 3*0.6/3 = 0.6, warp 3*0.4/2 = 0.6; binders reach the surfaces, so our
    # cell adds a margin of one warp height above and below the 3 mm stack
    assert c.weft_height == pytest.approx(0.6) and c.warp_height == pytest.approx(0.6)
    assert c.margin_z == pytest.approx(0.6) and c.thickness == pytest.approx(4.2)
    by_pos = {}
    for b, (pos, path) in enumerate(zip(c.binder_position, c.binder_path)):
        by_pos.setdefault(pos, []).append(path)
    assert by_pos[0] == [(1, 1, 1, 1), (2, 2, 2, 2)]   # warp k rests in gap k + 1
    assert by_pos[1] == [(2, 1, 0, 1), (3, 2, 1, 2)]   # up at weft 0, down at weft 2
    assert by_pos[3] == [(1, 2, 1, 0), (2, 3, 2, 1)]
    assert imported.tiling == (2, 3, 1) and imported.deform == (1.0,) * 12 and imported.shift_unit_cell is True


def test_textomos_without_surface_loops_has_no_margin():
    d = _textomos()
    d["weave_pattern"] = []
    c = read_textomos(d).cell
    assert c.margin_z == 0.0 and c.thickness == 3.0 and set(c.binder_path) == {(1, 1, 1, 1), (2, 2, 2, 2)}


@pytest.mark.parametrize("change, message", [
    ({"detector_rows": 2048}, r"unknown key\(s\) detector_rows"),
    ({"weave_type": "orthogonal"}, "weave_type must be 'layer2layer'"),
    ({"weave_pattern": [[4, 0, 1]]}, r"weave_pattern\[0\]\[0\] \(warp\) must be an integer in \[0, 3\]"),
    ({"weave_pattern": [[1, 0, 2]]}, r"weave_pattern\[0\]\[2\] must be 1 \(push up\) or -1"),
    ({"weave_pattern": [[1, 0, 1], [1, 0, 1]]}, "leaves the weft stack"),
    ({"deform": [1.0] * 11}, "deform must be a list of 12 numbers"),
    ({"weft_width_to_spacing_ratio": 1.1}, "weft_width_fraction must be <= 1"),
    ({"unit_cell_thickness": -3.0}, "unit_cell_thickness must be > 0"),
])
def test_textomos_is_strict(change, message):
    d = {**_textomos(), **change}
    with pytest.raises(ConfigError, match=message):
        read_textomos(d)
    d = _textomos()
    d.pop("unit_cell_thickness")
    with pytest.raises(ConfigError, match="missing 'unit_cell_thickness'"):
        read_textomos(d)
    assert "weave_pattern" in TEXTOMOS_KEYS
