"""One dict form for geometries (TOML scene files, JSON scan files, TIFF metadata) and the
Projections value that carries a stack with its geometry, quantity and unit."""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core.geometry import geometry_from_dict
from xrayraster.io import read_projections, write_projections
from xrayraster.io.grid_file import read_grid_file
from xrayraster.io.scene_file import load_scene_file

CONE = xr.ConeBeamGeometry(100.0, 250.0, (12, 16), (0.5, 0.25), xr.full_circle(90), detector_offset=(1.0, -2.0))
GEOMETRIES = {
    "cone, full circle": CONE,
    "cone, full circle from 30°": xr.ConeBeamGeometry(80.0, 160.0, 8, 0.3, xr.full_circle(7, math.radians(30.0))),
    "parallel, listed angles": xr.ParallelBeamGeometry((4, 6), 0.2, [0.0, 0.1, 1.3, -2.0]),
    "cone, 3 views of 90": CONE[[0, 5, 77]],
    "vector": CONE[:3].to_vec(),
    "volume": xr.VolumeGeometry((5, 6, 7), (0.1, 0.2, 0.3), (1.0, -2.0, 0.5)),
}


@pytest.mark.parametrize("geometry", GEOMETRIES.values(), ids=GEOMETRIES.keys())
def test_dicts_round_trip_through_json(geometry):
    """JSON text and back: the same geometry, to the bit where the views are a circle's, else within
    the float64 ulp that degrees → radians costs (angles are stored in degrees, as in every config)."""
    back = type(geometry).from_dict(json.loads(json.dumps(geometry.to_dict())))
    if hasattr(geometry, "angles") and "angles_deg" in geometry.to_dict():
        np.testing.assert_allclose(back.angles, geometry.angles, rtol=0, atol=4e-16 * 2 * math.pi)
        geometry = dataclasses.replace(geometry, angles=back.angles)
    assert back == geometry


def test_circular_views_are_written_as_a_count():
    assert CONE.to_dict() == {
        "beam": "cone", "source_to_origin": 100.0, "source_to_detector": 250.0, "detector_shape": [12, 16],
        "pixel_size": [0.5, 0.25], "detector_offset": [1.0, -2.0], "source_offset": [0.0, 0.0], "num_views": 90}
    assert GEOMETRIES["cone, 3 views of 90"].to_dict()["angles_deg"] == pytest.approx([0.0, 20.0, 308.0], abs=1e-12)


def test_one_key_set_for_toml_json_and_metadata(tmp_path):
    """The dict a geometry writes is a valid [geometry] table of a scene file and a valid
    'geometry' of a scan file, and both read back the same geometry."""
    d = CONE.to_dict()
    toml = "[geometry]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in d.items())
    toml += '[[objects]]\nmesh = { box = [1, 1, 1] }\nmaterial = "m"\n'
    (tmp_path / "scene.toml").write_text(toml)
    assert tomllib.loads(toml)["geometry"] == d
    assert load_scene_file(tmp_path / "scene.toml").geometry == CONE
    (tmp_path / "scan.json").write_text(json.dumps({"geometry": d, "volume": GEOMETRIES["volume"].to_dict()}))
    assert read_grid_file(tmp_path / "scan.json") == (CONE, GEOMETRIES["volume"])


def test_older_scan_file_spellings_are_still_read(tmp_path):
    older = {"type": "cone", "source_to_origin": 100, "source_to_detector": 250, "detector_shape": [12, 16],
             "pixel_size": [0.5, 0.25], "detector_offset": [1.0, -2.0], "views": 4, "arc_deg": 180, "start_deg": 10}
    (tmp_path / "scan.json").write_text(json.dumps({"geometry": older, "volume": {"shape": 4, "voxel_size": 1}}))
    geometry, volume = read_grid_file(tmp_path / "scan.json")
    np.testing.assert_allclose(np.degrees(geometry.angles), [10, 55, 100, 145], atol=1e-12)
    assert volume == xr.VolumeGeometry((4, 4, 4), 1.0)
    vector = {"type": "vector", "detector_shape": [12, 16], "vectors": GEOMETRIES["vector"].to_dict()["vectors"]}
    (tmp_path / "scan.json").write_text(json.dumps({"geometry": vector, "volume": {"shape": 4, "voxel_size": 1}}))
    assert read_grid_file(tmp_path / "scan.json")[0] == GEOMETRIES["vector"]


@pytest.mark.parametrize("change, message", [
    ({"pixel_size": [0.5, "a"]}, r"here: pixel_size\[1\] must be a number, got 'a'"),
    ({"num_views": 0}, r"here: num_views must be an integer >= 1, got 0"),
    ({"source_to_detector": 50}, r"here: source_to_detector \(50.0 mm\) must exceed source_to_origin"),
    ({"beam": "fan"}, r"here: beam must be 'cone' or 'parallel', got 'fan'"),
    ({"angles_deg": [0, 90]}, r"here: give either 'num_views' \(full circle\) or 'angles_deg', not both"),
    ({"colour": 1}, r"here: unknown key\(s\) colour"),
])
def test_bad_dicts_name_the_place_and_the_field(change, message):
    with pytest.raises(xr.ConfigError, match=message):
        geometry_from_dict({**CONE.to_dict(), **change}, "here")


def test_from_dict_of_the_wrong_class_is_refused():
    with pytest.raises(xr.ConfigError, match="describes a ConeBeamGeometry, not a ParallelBeamGeometry"):
        xr.ParallelBeamGeometry.from_dict(CONE.to_dict())


def test_projections_round_trip_through_a_tiff(tmp_path):
    data = np.random.default_rng(1).random((90, 12, 16), dtype=np.float32)
    p = xr.Projections(data, CONE, "lineint", "1", {"seed": 3, "views": list(range(90))})
    back = read_projections(write_projections(tmp_path / "p.tif", p))
    assert back.geometry == CONE and back.quantity == "lineint" and back.unit == "1"
    assert back.provenance == {"seed": 3, "views": list(range(90))}
    np.testing.assert_array_equal(back.data, data)


@pytest.mark.parametrize("kwargs, message", [
    ({"quantity": "counts"}, "quantity must be one of"),
    ({"unit": "mm"}, "a lineint stack has unit '1', got 'mm'"),
    ({"data": np.zeros((89, 12, 16))}, r"do not match the geometry's 90 views"),
    ({"quantity": "path_length", "unit": "mm"}, r"must be a 4-D stack \(view, material, row, col\)"),
])
def test_projections_refuse_what_does_not_fit(kwargs, message):
    with pytest.raises(xr.ConfigError, match=message):
        xr.Projections(**{"data": np.zeros((90, 12, 16)), "geometry": CONE, "quantity": "lineint", "unit": "1", **kwargs})


def test_fdk_takes_projections_with_their_geometry_and_quantity(cl):
    """A uniform slab's line integrals as transmissions: the same volume from the array (with
    geometry and input given) and from the Projections (carrying both)."""
    geometry = xr.ParallelBeamGeometry((4, 32), 0.5, xr.full_circle(16)[:8] + tuple(a + math.pi for a in xr.full_circle(16)[:8]))
    transmission = np.full((16, 4, 32), 0.5, np.float32)
    grid = xr.VolumeGeometry((2, 16, 16), 0.5)
    from_array = xr.fdk(transmission, geometry, grid, input="transmission", context=cl).data
    from_value = xr.fdk(xr.Projections(transmission, geometry, "transmission", "1"), volume=grid, context=cl).data
    np.testing.assert_array_equal(from_value, from_array)
    with pytest.raises(xr.ReconstructionError, match="input='lineint' but the Projections hold 'transmission'"):
        xr.fdk(xr.Projections(transmission, geometry, "transmission", "1"), volume=grid, input="lineint", context=cl)
    with pytest.raises(xr.ReconstructionError, match="hold 'raw'"):
        xr.fdk(xr.Projections(transmission, geometry, "raw", "counts"), volume=grid, context=cl)
