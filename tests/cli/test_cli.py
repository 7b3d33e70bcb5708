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
from xrayraster.io.scene_file import load_scene_file
from xrayraster.io.tiff import read_tiff_info

ROOT = Path(__file__).resolve().parents[2]
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
    assert info["method"] == "nested"  # the ball cuts into the bracket: one pass, their intersection a signed mesh
    assert xr.ConeBeamGeometry.from_dict(info["geometry"]) == loaded.geometry


def test_values_equal_the_renderer_on_the_same_scene(rendered, reference):
    np.testing.assert_array_equal(tifffile.imread(rendered), reference)
    assert reference[:, 1].max() > 4.5  # the steel ball (5 mm across) is in every view
    assert np.all(reference[:, 0].max(axis=(1, 2)) > 4)  # and the bracket


def test_png_quicklook_is_view_0_summed_over_materials_with_z_up(rendered, reference):
    png = rendered.with_suffix(".png")
    with Image.open(png) as image:
        image.verify()
    with Image.open(png) as image:
        factor = int(image.text["upscale"])  # enlarged to >= 512 px, a scale-bar strip below
        assert image.format == "PNG" and image.mode == "L" and factor == 2 and image.size[0] == 320 * factor
        assert image.text["mm_per_pixel"].startswith("0.15 x 0.15") and "mm" in image.text["scale_bar"]
        pixels = np.asarray(image)[: 256 * factor : factor, ::factor]
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
    "missing scene file": (None, ["--views", "0"], r"scene file .*missing\.toml: no such file"),
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


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch, gl, capsys):
    """Atomic output: a crash while writing keeps the previous file intact and removes the partial one."""
    out = tmp_path / "result.tif"
    assert cli.main(["render", str(EXAMPLE), "-o", str(out), "--path-lengths"]) == 0
    previous = out.read_bytes()

    def half_write(path, *args, **kwargs):
        Path(path).write_bytes(b"II*\x00 partial")
        raise OSError("disk full")

    monkeypatch.setattr(tifffile, "imwrite", half_write)
    assert cli.main(["render", str(EXAMPLE), "-o", str(out), "--path-lengths"]) == 1
    assert capsys.readouterr().err == "xrayraster: error: disk full\n"
    assert out.read_bytes() == previous
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.png", "result.tif"]


# --------------------------------------------------------------------------- radiographs (no --path-lengths)


@pytest.fixture(scope="module")
def loaded_example():
    return load_scene_file(EXAMPLE)


@pytest.fixture(scope="module", params=["lineint", "transmission", "raw"])
def radiograph_run(request, tmp_path_factory, gl, loaded_example):
    """``xrayraster render EXAMPLE -o OUT --views all --output KIND`` in-process, and Renderer.project on the same scene."""
    output = request.param
    out = tmp_path_factory.mktemp(f"radio_{output}") / "bracket.tif"
    assert cli.main(["render", str(EXAMPLE), "-o", str(out), "--views", "all", "--output", output]) == 0
    with xr.Renderer(loaded_example.geometry, context=gl) as renderer:
        shots = [renderer.project(loaded_example.scene, loaded_example.spectrum, v, detector=loaded_example.detector,
                                  output=output) for v in range(4)]
    return output, out, shots


def test_radiograph_tiff_is_float32_views_by_rows_by_cols_equal_to_project(radiograph_run):
    output, out, shots = radiograph_run
    with tifffile.TiffFile(out) as tif:
        data = tif.asarray()
        assert tif.series[0].axes == "TYX"
    assert data.dtype == np.float32 and data.shape == (4, 256, 320)
    np.testing.assert_array_equal(data, np.stack([s.image for s in shots]))
    if output == "lineint":
        assert data.max() > 3 and abs(data.min()) < 1e-6  # steel ball; open beam
    elif output == "transmission":
        assert data.max() == pytest.approx(1.0) and 0 < data.min() < 0.05
    assert sorted(p.name for p in out.parent.iterdir()) == ["bracket.png", "bracket.tif"]


def test_radiograph_metadata_describes_the_physics(radiograph_run, loaded_example):
    output, out, shots = radiograph_run
    info = read_tiff_info(out)
    assert info["output"] == output
    assert info["units"] == {"raw": "keV deposited", "transmission": "1", "lineint": "1"}[output]
    assert info["axes"] == "view, row, col"
    assert info["materials"] == ["aluminium", "steel"]
    assert info["views"] == [0, 1, 2, 3]
    assert info["spectrum"] == loaded_example.spectrum.description and "80 kVp" in info["spectrum"]
    assert eval(info["detector"], {name: getattr(xr, name) for name in xr.__all__}) == loaded_example.detector
    assert info["bins_used"] == [s.bins for s in shots] and 0 < info["bins_used"][0] <= loaded_example.spectrum.n_bins
    assert info["starved_pixels"] == [s.starved for s in shots] == [0, 0, 0, 0]
    assert info["noise"] is False and info["seed"] is None
    assert xr.ConeBeamGeometry.from_dict(info["geometry"]) == loaded_example.geometry


def test_radiograph_png_is_view_0_with_z_up(radiograph_run):
    _, out, shots = radiograph_run
    with Image.open(out.with_suffix(".png")) as image:
        factor = int(image.text["upscale"])
        pixels = np.asarray(image)[: 256 * factor : factor, ::factor]
    view0 = shots[0].image.astype(np.float64)[::-1]
    expected = np.round(255 * np.clip(view0 / view0.max(), 0, 1)).astype(np.uint8)
    assert pixels.shape == (256, 320) and np.abs(pixels.astype(int) - expected).max() <= 1


def test_the_summary_line(tmp_path, capsys, gl):
    out = tmp_path / "b.tif"
    assert cli.main(["render", str(EXAMPLE), "-o", str(out), "--views", "1,2"]) == 0
    line = capsys.readouterr().out
    assert line.startswith(f"{out}: 2 view(s) × 256×320 px lineint radiograph [1], range ")
    assert "energy bins" in line and "starved" not in line and f"quick-look {out.with_suffix('.png')}" in line


@pytest.mark.slow
def test_noise_with_a_seed_is_reproducible_to_the_byte(tmp_path, gl, loaded_example):
    def run(name, *extra):
        out = tmp_path / name
        assert cli.main(["render", str(EXAMPLE), "-o", str(out), "--views", "0,2", "--noise", *extra]) == 0
        return out

    a, b, c, default = run("a.tif", "--seed", "7"), run("b.tif", "--seed", "7"), run("c.tif", "--seed", "8"), run("d.tif")
    assert a.read_bytes() == b.read_bytes()
    assert not np.array_equal(tifffile.imread(a), tifffile.imread(c))
    assert read_tiff_info(a)["seed"] == 7 and read_tiff_info(a)["noise"] is True
    assert read_tiff_info(default)["seed"] == 0
    with xr.Renderer(loaded_example.geometry, context=gl) as renderer:
        expected = [renderer.project(loaded_example.scene, loaded_example.spectrum, v, detector=loaded_example.detector,
                                     noise=True, seed=7).image for v in (0, 2)]
    np.testing.assert_array_equal(tifffile.imread(a), np.stack(expected))


def test_a_spectrum_file_and_a_counting_detector(tmp_path, gl):
    xr.Spectrum.from_arrays([40.0, 60.0], [1e5, 2e5]).to_file(tmp_path / "s.txt")
    scene = tmp_path / "scene.toml"
    scene.write_text(GEOMETRY + """
[materials.water]
formula = "H2O"
density = 1.0

[source]
spectrum_file = "s.txt"

[detector]
mode = "counting"

[[objects]]
mesh = { box = [5, 5, 5] }
material = "water"
""")
    out = tmp_path / "raw.tif"
    assert cli.main(["render", str(scene), "-o", str(out), "--output", "raw"]) == 0
    info = read_tiff_info(out)
    assert info["units"] == "counts" and info["spectrum"] == "from file s.txt" and info["bins_used"] == [2]
    assert tifffile.imread(out).shape == (16, 16)  # one view: tifffile squeezes the length-1 view axis on reading


RADIOGRAPH_BAD = {
    "no source": (GEOMETRY + '[materials.a]\nelement = "Al"\n[[objects]]\nmesh = { box = [1, 1, 1] }\nmaterial = "a"\n', [],
                  r"radiographs need a \[source\] table \(the X-ray spectrum\); add it \(docs/scene-format\.md\), "
                  r"or pass --path-lengths"),
    "no materials": (GEOMETRY + "[source]\nkvp = 60\n[[objects]]\nmesh = { box = [1, 1, 1] }\nmaterial = \"a\"\n", [],
                     r"radiographs need a \[materials\] table"),
    "neither": (GEOMETRY + '[[objects]]\nmesh = { box = [1, 1, 1] }\nmaterial = "a"\n', [],
                r"radiographs need a \[source\] table .* and a \[materials\] table .*; add them"),
    "output with path lengths": (EXAMPLE, ["--path-lengths", "--output", "raw"], r"--output appl\(y/ies\) to radiographs"),
    "seed without noise": (EXAMPLE, ["--seed", "3"], r"--seed needs --noise"),
    "bad output kind": (EXAMPLE, ["--output", "counts"], None),
}


@pytest.mark.parametrize("scene, extra, message", RADIOGRAPH_BAD.values(), ids=RADIOGRAPH_BAD.keys())
def test_radiograph_bad_input_exits_2_and_says_what_to_add(scene, extra, message, tmp_path, capsys):
    if isinstance(scene, str):
        path = tmp_path / "scene.toml"
        path.write_text(scene)
    else:
        path = scene
    out = tmp_path / "out" / "r.tif"
    if message is None:  # argparse refuses it
        with pytest.raises(SystemExit) as exc:
            cli.main(["render", str(path), "-o", str(out), *extra])
        assert exc.value.code == 2 and "invalid choice: 'counts'" in capsys.readouterr().err
    else:
        assert cli.main(["render", str(path), "-o", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("xrayraster: error: ") and re.search(message, err), err
    assert not (tmp_path / "out").exists()
