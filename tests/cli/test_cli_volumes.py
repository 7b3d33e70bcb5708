"""``xrayraster reconstruct`` and ``xrayraster voxelize``: the geometry from a grid file or from the
projections' metadata, volume TIFFs Fiji reads (voxel size, units), the same numbers as ``xr.fdk``
and ``xr.voxelize``, and bad input (exit 2)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import tifffile

import xrayraster as xr
from xrayraster import cli
from xrayraster.io.grid_file import read_grid_file
from xrayraster.io.tiff import read_tiff_info, write_tiff

from references.phantoms import project, sphere

GEOMETRY = xr.ConeBeamGeometry(100, 200, (40, 48), 0.8, xr.full_circle(60), detector_offset=(0.4, -0.3))
VOLUME = xr.VolumeGeometry((12, 20, 24), (0.6, 0.5, 0.5), offset=(0.2, 0.0, -0.1))
GEOMETRY_JSON = {"type": "cone", "source_to_origin": 100, "source_to_detector": 200, "detector_shape": [40, 48],
                 "pixel_size": 0.8, "views": 60, "detector_offset": [0.4, -0.3]}
VOLUME_JSON = {"shape": [12, 20, 24], "voxel_size": [0.6, 0.5, 0.5], "offset": [0.2, 0.0, -0.1]}


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    """Line integrals of a ball, written as 'xrayraster render' writes radiographs."""
    path = tmp_path_factory.mktemp("rec") / "proj.tif"
    p = project([sphere(4.0, 0.03, (1.0, -0.5, 0.3))], GEOMETRY).astype(np.float32)
    write_tiff(path, p, axes="TYX", pixel_size_mm=GEOMETRY.pixel_size,
               info={"output": "lineint", "geometry": GEOMETRY.to_dict(), "views": list(range(60))})
    return path, p


def _scan(tmp_path, **content):
    path = tmp_path / "grid.json"
    path.write_text(json.dumps(content))
    return path


def test_scan_file_geometry_equals_the_python_one(tmp_path):
    geometry, volume = read_grid_file(_scan(tmp_path, geometry=GEOMETRY_JSON, volume=VOLUME_JSON))
    assert volume == VOLUME
    assert geometry.to_vec().array == pytest.approx(GEOMETRY.to_vec().array, abs=1e-12)


@pytest.mark.parametrize("with_geometry", [True, False])
def test_reconstruct_writes_the_fdk_volume_with_its_voxel_size(cl, tmp_path, stack, with_geometry, capsys):
    path, p = stack
    scan = _scan(tmp_path, volume=VOLUME_JSON, **({"geometry": GEOMETRY_JSON} if with_geometry else {}))
    out = tmp_path / "vol.tif"
    assert cli.main(["reconstruct", str(path), "--grid", str(scan), "-o", str(out), "--filter", "hann"]) == 0
    assert "12×20×24 voxels" in capsys.readouterr().out
    with tifffile.TiffFile(out) as tif:
        data = tif.asarray()
        assert tif.series[0].axes == "ZYX"
        assert tif.imagej_metadata["spacing"] == pytest.approx(0.6)
        assert tif.imagej_metadata["unit"] == "mm"
        x_res = tif.pages[0].tags["XResolution"].value
    assert x_res[0] / x_res[1] == pytest.approx(1 / 0.5, rel=1e-6)
    info = read_tiff_info(out)
    assert info["units"] == "1/cm" and xr.VolumeGeometry.from_dict(info["volume_geometry"]) == VOLUME
    want = xr.fdk(p, GEOMETRY, VOLUME, filter="hann", context=cl).data
    np.testing.assert_allclose(data, want, atol=1e-5 * np.abs(want).max())
    assert (out.with_suffix(".png")).is_file()


def test_reconstruct_switches_force_the_weights_and_the_truncation_correction(cl, tmp_path, stack):
    """--displaced on / --truncation on with a width: the same volume as xr.fdk with those options,
    and the choices in the TIFF's metadata."""
    path, p = stack
    out = tmp_path / "vol.tif"
    assert cli.main(["reconstruct", str(path), "--grid", str(_scan(tmp_path, volume=VOLUME_JSON)), "-o", str(out),
                     "--displaced", "on", "--truncation", "on", "--truncation-width", "0.3"]) == 0
    info = read_tiff_info(out)
    assert info["displaced"] is True and info["truncation"] is True and info["truncation_width"] == 0.3
    assert info["truncation_corrected_row_ends"] == 1.0
    want = xr.fdk(p, GEOMETRY, VOLUME, displaced=True, truncation=True, truncation_width=0.3, context=cl).data
    np.testing.assert_allclose(tifffile.imread(out), want, atol=1e-5 * np.abs(want).max())


def test_reconstruct_bad_input_exits_2_and_names_the_fix(tmp_path, stack, capsys):
    path, p = stack
    out = tmp_path / "vol.tif"
    wrong = dict(GEOMETRY_JSON, views=59)
    assert cli.main(["reconstruct", str(path), "--grid", str(_scan(tmp_path, geometry=wrong, volume=VOLUME_JSON)),
                     "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "scan geometries of" in err and "differ (num_views 59 vs 60" in err and "--geometry-from" in err, err
    assert cli.main(["reconstruct", str(path), "--grid", str(_scan(tmp_path, geometry=wrong, volume=VOLUME_JSON)),
                     "--geometry-from", "grid", "-o", str(out)]) == 2
    assert "geometry has 59 views" in capsys.readouterr().err
    bare = tmp_path / "bare.tif"
    tifffile.imwrite(bare, p)
    assert cli.main(["reconstruct", str(bare), "--grid", str(_scan(tmp_path, volume=VOLUME_JSON)), "-o", str(out)]) == 2
    assert "has no 'geometry'" in capsys.readouterr().err
    assert cli.main(["reconstruct", str(path), "--grid", str(_scan(tmp_path, geometry=GEOMETRY_JSON)), "-o", str(out)]) == 2
    assert "needs a 'volume'" in capsys.readouterr().err
    bad = dict(GEOMETRY_JSON, angles_deg=[0, 90])
    assert cli.main(["reconstruct", str(path), "--grid", str(_scan(tmp_path, geometry=bad, volume=VOLUME_JSON)),
                     "-o", str(out)]) == 2
    assert "not both" in capsys.readouterr().err
    raw = tmp_path / "raw.tif"
    write_tiff(raw, p, axes="TYX", pixel_size_mm=(0.8, 0.8), info={"output": "raw", "geometry": GEOMETRY.to_dict()})
    assert cli.main(["reconstruct", str(raw), "--grid", str(_scan(tmp_path, volume=VOLUME_JSON)), "-o", str(out)]) == 2
    assert "raw detector signal" in capsys.readouterr().err
    assert not out.exists()


def test_angles_in_degrees_in_scan_files(tmp_path):
    g, _ = read_grid_file(_scan(tmp_path, geometry=dict(GEOMETRY_JSON, views=4, arc_deg=180, start_deg=10),
                                volume=VOLUME_JSON))
    assert g.angles == pytest.approx([math.radians(a) for a in (10, 55, 100, 145)])


def test_voxelize_writes_labels_fiji_reads(gl, tmp_path, capsys):
    """``xrayraster voxelize`` on the bundled example: the labels of xr.voxelize, uint8 ZYX with the
    voxel size in mm, a label table in the metadata, and exit 2 without a volume."""
    from pathlib import Path

    from xrayraster.io.scene_file import load_scene_file

    example = Path(__file__).resolve().parents[2] / "examples" / "bracket_and_ball.toml"
    volume = {"shape": [32, 48, 40], "voxel_size": [0.3, 0.25, 0.3], "offset": [0.0, 0.5, -0.2]}
    out = tmp_path / "labels.tif"
    assert cli.main(["voxelize", str(example), "--grid", str(_scan(tmp_path, volume=volume)), "-o", str(out)]) == 0
    assert "uint8 labels" in capsys.readouterr().out
    with tifffile.TiffFile(out) as tif:
        data = tif.asarray()
        assert tif.series[0].axes == "ZYX" and data.dtype == np.uint8
        assert tif.imagej_metadata["spacing"] == pytest.approx(0.3) and tif.imagej_metadata["unit"] == "mm"
    info = read_tiff_info(out)
    assert info["labels"] == {"1": ["bracket"], "2": ["ball"]}
    want = xr.voxelize(load_scene_file(example).scene, xr.VolumeGeometry((32, 48, 40), (0.3, 0.25, 0.3), (0.0, 0.5, -0.2)),
                       context=gl).data
    assert np.array_equal(data, want) and set(np.unique(data)) == {0, 1, 2}
    assert cli.main(["voxelize", str(example), "--grid", str(_scan(tmp_path, volume=volume)), "-o", str(out),
                     "--fractions", "2"]) == 0
    shares = tifffile.imread(tmp_path / "labels_fractions.tif")
    assert shares.shape == (32, 3, 48, 40) and read_tiff_info(tmp_path / "labels_fractions.tif")["channel_labels"] == [0, 1, 2]
    np.testing.assert_allclose(shares.sum(axis=1), 1.0, atol=1e-6)
    assert cli.main(["voxelize", str(example), "--grid", str(_scan(tmp_path, geometry=GEOMETRY_JSON)), "-o", str(out)]) == 2
    assert "needs a 'volume'" in capsys.readouterr().err
