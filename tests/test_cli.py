"""The command line on the bundled example: file layout, metadata, values, quick-look, entry points,
and bad input (exit code 2, a message naming the problem, no output left behind)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile
import trimesh
from PIL import Image

import xrayraster as xr
from xrayraster import cli
from xrayraster.config import load_scene_file
from xrayraster.io import read_tiff_info

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "bracket_and_ball.toml"


@pytest.fixture(scope="module")
def rendered(tmp_path_factory, gl):
    """``xrayraster render EXAMPLE -o out/bracket.tif --path-lengths --views all``, run in-process once."""
    out = tmp_path_factory.mktemp("cli") / "out" / "bracket.tif"
    assert cli.main(["render", str(EXAMPLE), "-o", str(out), "--path-lengths", "--views", "all"]) == 0
    return out


@pytest.fixture(scope="module")
def reference(gl):
    """Renderer.path_lengths on the same loaded scene and geometry, every view: (views, materials, rows, cols)."""
    loaded = load_scene_file(EXAMPLE)
    with xr.Renderer(loaded.geometry, context=gl) as renderer:
        return np.stack([renderer.path_lengths(loaded.scene, v) for v in range(loaded.geometry.num_views)])


def test_tiff_is_float32_views_by_materials_by_rows_by_cols(rendered):
    with tifffile.TiffFile(rendered) as tif:
        data = tif.asarray()
        assert tif.series[0].axes == "TCYX"
        assert tif.imagej_metadata["unit"] == "mm"
        x_res = tif.pages[0].tags["XResolution"].value
    assert data.dtype == np.float32
    assert data.shape == (4, 2, 256, 320)  # 4 views, aluminium + steel, 256 rows, 320 cols
    assert x_res[0] / x_res[1] == pytest.approx(1 / 0.15, rel=1e-6)  # pixels per mm at the detector


def test_tiff_metadata_describes_the_render(rendered):
    info = read_tiff_info(rendered)
    loaded = load_scene_file(EXAMPLE)
    assert info["units"] == "mm"
    assert info["quantity"] == "path length"
    assert info["axes"] == "view, material, row, col"
    assert info["materials"] == ["aluminium", "steel"]
    assert info["views"] == [0, 1, 2, 3]
    assert info["supersampling"] == 1
    assert info["method"] == "resolve"  # the ball overlaps the bracket
    assert eval(info["geometry"], vars(xr)) == loaded.geometry


def test_values_equal_the_renderer_on_the_same_scene(rendered, reference):
    np.testing.assert_array_equal(tifffile.imread(rendered), reference)
    assert reference[:, 1].max() > 4.5  # the steel ball (5 mm across) is in every view
    assert np.all(reference[:, 0].max(axis=(1, 2)) > 4)  # and the bracket


def test_png_quicklook_is_view_0_summed_over_materials_with_z_up(rendered, reference):
    png = rendered.with_suffix(".png")
    with Image.open(png) as image:
        image.verify()
    with Image.open(png) as image:
        assert image.format == "PNG" and image.mode == "L" and image.size == (320, 256)
        pixels = np.asarray(image)
    total = reference[0].sum(axis=0)[::-1]  # picture row 0 = the highest detector row
    expected = np.round(255 * np.clip(total / total.max(), 0, 1)).astype(np.uint8)
    assert np.abs(pixels.astype(int) - expected).max() <= 1
    assert pixels.max() == 255 and pixels.min() == 0


def test_only_the_outputs_are_written(rendered):
    assert sorted(p.name for p in rendered.parent.iterdir()) == ["bracket.png", "bracket.tif"]


def _console_script() -> str:
    """The installed ``xrayraster`` script of this interpreter's environment."""
    beside = Path(sys.executable).parent / "xrayraster"
    found = str(beside) if beside.exists() else shutil.which("xrayraster")
    if found is None:
        pytest.fail("the 'xrayraster' console script is not installed; run pip install \".[test]\" (see README.md)")
    return found


def test_console_script_renders_selected_views(tmp_path, reference):
    out = tmp_path / "sel.tif"
    run = subprocess.run(
        [_console_script(), "render", str(EXAMPLE), "-o", str(out), "--path-lengths", "--views", "3,1"],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 0, run.stderr
    assert str(out) in run.stdout and "2 view(s) × 2 material(s) × 256×320 px" in run.stdout
    np.testing.assert_array_equal(tifffile.imread(out), reference[[3, 1]])
    assert read_tiff_info(out)["views"] == [3, 1]


def test_python_dash_m_runs_the_cli(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-m", "xrayraster", "--version"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == f"xrayraster {xr.__version__}"


# --------------------------------------------------------------------------- bad input

GEOMETRY = """
[geometry]
source_to_origin = 100.0
source_to_detector = 200.0
detector_shape = [16, 16]
pixel_size = 0.5
"""


def _open_mesh(folder: Path) -> str:
    box = trimesh.creation.box((5.0, 5.0, 5.0))
    open_box = trimesh.Trimesh(box.vertices, box.faces[1:], process=False)  # one triangle missing
    open_box.export(folder / "lid.stl")
    return GEOMETRY + '[[objects]]\nname = "lid"\nmesh = "lid.stl"\nmaterial = "a"\n'


BAD = {
    "missing scene file": (None, ["--views", "0"], r"missing\.toml: no such scene file"),
    "unknown key": (GEOMETRY + '[[objects]]\nmesh = { box = [1, 1, 1] }\nmaterial = "a"\ncolour = "red"\n', [],
                    r"\[\[objects\]\] #1: unknown key\(s\) colour"),
    "view out of range": (EXAMPLE, ["--views", "4"], r"--views \[4\] out of range: the scene has 4 views"),
    "views not integers": (EXAMPLE, ["--views", "first"], r"--views must be comma-separated integers or 'all'"),
    "non-watertight mesh": (_open_mesh, [], r"object 'lid' is not watertight: 3 open edges"),
}


@pytest.mark.parametrize("scene, extra, message", BAD.values(), ids=BAD.keys())
def test_bad_input_exits_2_with_a_message_and_writes_nothing(scene, extra, message, tmp_path, capsys):
    inputs = tmp_path / "in"
    inputs.mkdir()
    if scene is None:
        path = inputs / "missing.toml"
    elif isinstance(scene, Path):
        path = scene
    else:
        text = scene(inputs) if callable(scene) else scene
        path = inputs / "scene.toml"
        path.write_text(text)
    before = sorted(inputs.iterdir())
    out = tmp_path / "out" / "result.tif"

    code = cli.main(["render", str(path), "-o", str(out), "--path-lengths", *extra])

    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("xrayraster: error: ")
    assert re.search(message, err), err
    assert sorted(inputs.iterdir()) == before
    assert not (tmp_path / "out").exists()


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch, gl):
    """Atomic output: a crash while writing keeps the previous file intact and removes the partial one."""
    out = tmp_path / "result.tif"
    out.write_bytes(b"previous result")

    def half_write(path, *args, **kwargs):
        Path(path).write_bytes(b"II*\x00 partial")
        raise OSError("disk full")

    monkeypatch.setattr(tifffile, "imwrite", half_write)
    with pytest.raises(OSError, match="disk full"):
        cli.main(["render", str(EXAMPLE), "-o", str(out), "--path-lengths"])
    assert out.read_bytes() == b"previous result"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.tif"]
