"""The command line never destroys data and fails in one line (issue 11): outputs checked before any
work (suffix, outputs that are inputs, unwritable directories), stale temporaries of killed writers
removed without touching live ones, Ctrl-C (exit 130), exit codes, plain numbers in messages,
scan-geometry conflicts, under-sampled reconstructions, float32-underflowing transmission,
``--grid`` and its deprecated spellings."""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import tifffile

import xrayraster as xr
from xrayraster import cli
from xrayraster.core import fields, files, validate
from xrayraster.core.errors import ConfigError, GeometryError
from xrayraster.io.tiff import read_tiff_info, write_tiff
from xrayraster.physics.radiograph import radiograph

ROOT = Path(__file__).resolve().parents[2]

TINY_SCENE = """
[geometry]
source_to_origin = 100.0
source_to_detector = 200.0
detector_shape = [16, 16]
pixel_size = 0.5
num_views = 4

[[objects]]
mesh = { box = [5, 5, 5] }
material = "aluminium"
"""

PROJ_GEOMETRY = xr.ConeBeamGeometry(100, 200, (16, 16), 0.8, xr.full_circle(8))
SCAN_VOLUME = {"shape": [4, 16, 16], "voxel_size": 0.5}


def _digest(paths) -> dict:
    return {str(p): hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths}


def _tree(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def _projections(folder: Path, geometry=PROJ_GEOMETRY, name="proj.tif") -> Path:
    path = folder / name
    data = np.full((geometry.num_views, *geometry.detector_shape), 0.1, np.float32)
    write_tiff(path, data, axes="TYX", pixel_size_mm=geometry.pixel_size,
               info={"output": "lineint", "geometry": geometry.to_dict()})
    return path


def _grid_file(folder: Path, name="grid.json", **content) -> Path:
    path = folder / name
    path.write_text(json.dumps(content or {"volume": SCAN_VOLUME}))
    return path


@pytest.fixture
def no_work(monkeypatch):
    """Any rendering, reconstruction or voxelization fails the command (exit 1, not 2)."""
    from xrayraster.cli import reconstruct, render, voxelize

    def work(*args, **kwargs):
        raise RuntimeError("the work started")

    monkeypatch.setattr(render, "Renderer", work)
    monkeypatch.setattr(reconstruct, "fdk", work)
    monkeypatch.setattr(voxelize, "voxelize", work)


# --------------------------------------------------------------------------- outputs checked before work


def _case_png_output(tmp):
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    out = tmp / "out.png"
    return ["render", str(scene), "-o", str(out), "--path-lengths"], [scene], rf"-o {out}: the output must be a \.tif"


def _case_no_suffix(tmp):
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    return ["render", str(scene), "-o", str(tmp / "out"), "--path-lengths"], [scene], r"use e\.g\. -o .*out\.tif"


def _case_output_is_projections(tmp):
    proj, scan = _projections(tmp), _grid_file(tmp)
    return (["reconstruct", str(proj), "--grid", str(scan), "-o", str(proj)], [proj, scan],
            rf"-o would overwrite the input {proj}")


def _case_output_resolves_to_projections(tmp):
    proj, scan = _projections(tmp), _grid_file(tmp)
    (tmp / "sub").mkdir()
    out = tmp / "sub" / ".." / "proj.tif"
    return (["reconstruct", str(proj), "--grid", str(scan), "-o", str(out)], [proj, scan],
            rf"-o would overwrite the input {proj}")


def _case_output_links_to_projections(tmp):
    proj, scan = _projections(tmp), _grid_file(tmp)
    (tmp / "link.tif").symlink_to(proj)
    return (["reconstruct", str(proj), "--grid", str(scan), "-o", str(tmp / "link.tif")], [proj, scan],
            r"would overwrite the input")


def _case_output_hardlinks_to_projections(tmp):
    proj, scan = _projections(tmp), _grid_file(tmp)
    os.link(proj, tmp / "hard.tif")  # samefile only: another name, another real path
    return (["reconstruct", str(tmp / "hard.tif"), "--grid", str(scan), "-o", str(proj)],
            [proj, scan], r"would overwrite the input .*hard\.tif")


def _case_quicklook_is_the_grid_file(tmp):
    proj, scan = _projections(tmp), _grid_file(tmp, name="vol.png")
    return (["reconstruct", str(proj), "--grid", str(scan), "-o", str(tmp / "vol.tif")], [proj, scan],
            rf"the output {scan} \(beside -o .*vol\.tif\) would overwrite the input {scan}")


def _case_fractions_is_the_grid_file(tmp):
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    scan = _grid_file(tmp, name="lab_fractions.tif")
    return (["voxelize", str(scene), "--grid", str(scan), "-o", str(tmp / "lab.tif"), "--fractions", "2"],
            [scene, scan], rf"the output {scan} .* would overwrite the input {scan}")


def _case_voxelize_output_is_the_scene(tmp):
    scene = tmp / "scene.tif"  # a TOML scene file with an unlucky name
    scene.write_text(TINY_SCENE)
    scan = _grid_file(tmp)
    return (["voxelize", str(scene), "--grid", str(scan), "-o", str(scene)], [scene, scan],
            rf"-o would overwrite the input {scene}")


def _case_parent_is_a_file(tmp):
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    (tmp / "notes.txt").write_text("keep me")
    out = tmp / "notes.txt" / "sub" / "out.tif"
    return (["render", str(scene), "-o", str(out), "--path-lengths"], [scene, tmp / "notes.txt"],
            rf"cannot write {out}: its directory {out.parent} cannot be created or written \(Not a directory\)")


def _case_under_proc(tmp):
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    out = Path("/proc/xrayraster-no-such-dir/out.tif")
    return ["render", str(scene), "-o", str(out), "--path-lengths"], [scene], rf"cannot write {out}: its directory /proc"


def _case_under_sys(tmp):
    """/sys refuses new entries even to root: the stand-in for a read-only directory (see the report)."""
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    out = Path("/sys/xrayraster-test.tif")
    return ["render", str(scene), "-o", str(out), "--path-lengths"], [scene], r"cannot write /sys/xrayraster-test\.tif: its directory /sys"


def _case_output_is_a_directory(tmp):
    scene = tmp / "scene.toml"
    scene.write_text(TINY_SCENE)
    (tmp / "d.tif").mkdir()
    return (["render", str(scene), "-o", str(tmp / "d.tif"), "--path-lengths"], [scene],
            r"d\.tif: it is a directory")


REFUSED = {f.__name__[len("_case_"):]: f for f in (
    _case_png_output, _case_no_suffix, _case_output_is_projections, _case_output_resolves_to_projections,
    _case_output_links_to_projections, _case_output_hardlinks_to_projections, _case_quicklook_is_the_grid_file,
    _case_fractions_is_the_grid_file, _case_voxelize_output_is_the_scene, _case_parent_is_a_file, _case_under_proc,
    _case_under_sys, _case_output_is_a_directory)}


@pytest.mark.parametrize("case", REFUSED.values(), ids=REFUSED.keys())
def test_an_output_that_would_destroy_data_is_refused_before_work(case, tmp_path, no_work, capsys):
    argv, inputs, message = case(tmp_path)
    before, tree = _digest(inputs), _tree(tmp_path)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("xrayraster: error: "), err
    assert re.search(message, err), err
    assert _digest(inputs) == before  # inputs byte-identical
    assert _tree(tmp_path) == tree  # nothing written, no probe or directory left behind


def test_the_directory_probe_leaves_no_directory_behind_when_the_input_is_bad(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text("[geometry]\n")
    assert cli.main(["render", str(scene), "-o", str(tmp_path / "new" / "deeper" / "out.tif"), "--path-lengths"]) == 2
    assert _tree(tmp_path) == ["scene.toml"]


# --------------------------------------------------------------------------- stale temporaries


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_temporaries_of_dead_writers_go_live_ones_stay(tmp_path):
    out = tmp_path / "r.tif"
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        dead = tmp_path / f".r.tif.{files.HOST_TAG}.{_dead_pid()}.abc123_x.tif"
        alive = tmp_path / f".r.tif.{files.HOST_TAG}.{live.pid}.def456.tif"
        other_host = tmp_path / f".r.tif.0badc0de.{_dead_pid()}.ghi789.tif"
        older_form = tmp_path / ".r.tif.k2j3h4g5.tif"
        other_output = tmp_path / f".s.tif.{files.HOST_TAG}.{_dead_pid()}.jkl012.tif"
        for p in (dead, alive, other_host, older_form, other_output):
            p.write_bytes(b"partial")
        files.atomic_write(out, lambda tmp: Path(tmp).write_bytes(b"new"))
        assert out.read_bytes() == b"new"
        assert not dead.exists()
        assert alive.exists() and other_host.exists() and older_form.exists() and other_output.exists()
    finally:
        live.kill()
        live.wait()


SLOW_WRITER = """
import os, sys, time
import tifffile
from pathlib import Path

def slow(path, *args, **kwargs):
    Path(path).write_bytes(b"II*\\x00 partial")
    print("WRITING", flush=True)
    time.sleep(60)

tifffile.imwrite = slow
from xrayraster.cli import main
sys.exit(main(sys.argv[1:]))
"""

SLOW_RENDER = """
import sys, time
from xrayraster.simulate.renderer import Renderer

def slow(self, *args, **kwargs):
    print("RENDERING", flush=True)
    time.sleep(60)

Renderer.path_lengths = slow
from xrayraster.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _start(script: str, tmp_path: Path, marker: str, *argv) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(script), *argv], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()  # blocks until the child is mid-work (or has died)
    if line.strip() != marker:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"the child did not reach {marker}: {line}{out}{err}")
    return proc


def _temporaries(folder: Path, name: str) -> list[Path]:
    return sorted(folder.glob(f".{name}.*"))


def test_a_sigkilled_render_leaves_a_temporary_the_next_run_removes(tmp_path, gl):
    scene = tmp_path / "scene.toml"
    scene.write_text(TINY_SCENE)
    out = tmp_path / "out" / "r.tif"
    proc = _start(SLOW_WRITER, tmp_path, "WRITING", "render", str(scene), "-o", str(out), "--path-lengths")
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    left = _temporaries(out.parent, "r.tif")
    assert len(left) == 1 and not out.exists()  # what a killed writer leaves

    assert cli.main(["render", str(scene), "-o", str(out), "--path-lengths"]) == 0
    assert _temporaries(out.parent, "r.tif") == []
    assert sorted(p.name for p in out.parent.iterdir()) == ["r.png", "r.tif"]
    assert tifffile.imread(out).shape[-2:] == (16, 16)


@pytest.mark.parametrize("script, marker", [(SLOW_RENDER, "RENDERING"), (SLOW_WRITER, "WRITING")],
                         ids=["mid-render", "mid-write"])
def test_ctrl_c_exits_130_in_one_line_and_writes_nothing(script, marker, tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(TINY_SCENE)
    out = tmp_path / "r.tif"
    proc = _start(script, tmp_path, marker, "render", str(scene), "-o", str(out), "--path-lengths")
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("xrayraster: interrupted"), err
    assert not out.exists() and _temporaries(tmp_path, "r.tif") == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


# --------------------------------------------------------------------------- exit codes and one-line messages


@pytest.mark.parametrize("argv, message", [
    (["--noise", "--seed", "-1"], "argument --seed: must be an integer >= 0, got -1"),
    (["--noise", "--seed", "x"], "argument --seed: must be an integer >= 0, got 'x'"),
    (["--supersampling", "0"], "argument --supersampling: must be an integer >= 1, got 0"),
])
def test_bad_integers_are_argparse_errors(argv, message, tmp_path, capsys, no_work):
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", str(tmp_path / "s.toml"), "-o", str(tmp_path / "o.tif"), *argv])
    assert exc.value.code == 2 and message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_bug_is_one_line_and_its_traceback_needs_v(tmp_path, monkeypatch, capsys):
    from xrayraster.cli import render

    def broken(path):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(render, "load_scene_file", broken)
    argv = ["render", str(tmp_path / "s.toml"), "-o", str(tmp_path / "o.tif"), "--path-lengths"]
    assert cli.main(argv) == 1
    err = capsys.readouterr().err
    assert err == ("xrayraster: unexpected error (a bug, please report it): RuntimeError: boom; second line; "
                   "run with -v for the traceback\n")
    assert cli.main([*argv, "-v"]) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and 'raise RuntimeError("boom' in err
    assert err.splitlines()[-1] == "xrayraster: unexpected error (a bug, please report it): RuntimeError: boom; second line"


def test_messages_show_plain_numbers():
    with pytest.raises(ConfigError) as exc:
        fields.number(np.float32("nan"), "density", "s.toml [materials.a]")
    assert str(exc.value) == "s.toml [materials.a]: density must be finite, got nan"
    with pytest.raises(ConfigError) as exc:
        fields.number(np.float64(-0.0), "kvp", "s.toml [source]", positive=True)
    assert str(exc.value) == "s.toml [source]: kvp must be > 0, got 0.0"
    with pytest.raises(ConfigError) as exc:
        fields.vector([1, np.float32(2.5)], "box", "w", 3, "[x, y, z]")
    assert str(exc.value) == "w: box must be [x, y, z], got [1, 2.5]"
    assert fields.number(np.float32(0.5), "x", "w") == 0.5  # a numpy number is a number
    with pytest.raises(ConfigError) as exc:  # TOML integers have no bound; float() of this one overflows
        fields.number(10**400, "kvp", "s.toml [source]")
    assert str(exc.value) == "s.toml [source]: kvp must be finite, got 100...(401 digits)"
    with pytest.raises(GeometryError) as exc:
        validate.finite("pixel_size", -0.0, positive=True)
    assert str(exc.value) == "pixel_size must be > 0, got 0.0"
    with pytest.raises(GeometryError) as exc:
        validate.positive_ints("detector_shape", (np.int64(16), np.float32(0.5)), 2)
    assert str(exc.value) == "detector_shape[1] must be a positive integer, got 0.5"
    assert validate.show({"a": (np.float32(1.5), "b", np.nan)}) == "{'a': (1.5, 'b', nan)}"


# --------------------------------------------------------------------------- reconstruct: geometry conflicts, sampling


def test_conflicting_scan_geometries_are_refused_unless_one_is_chosen(cl, tmp_path, capsys):
    proj = _projections(tmp_path)
    other = dict(PROJ_GEOMETRY.to_dict(), source_to_origin=110.0)
    scan = _grid_file(tmp_path, geometry=other, volume=SCAN_VOLUME)
    out = tmp_path / "v.tif"
    before = _digest([proj, scan])
    assert cli.main(["reconstruct", str(proj), "--grid", str(scan), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (f"xrayraster: error: the scan geometries of {scan} and {proj} metadata differ "
                   "(source_to_origin 110.0 vs 100.0); choose one with --geometry-from grid or "
                   "--geometry-from projections\n")
    assert not out.exists()
    for source, want in (("grid", xr.ConeBeamGeometry.from_dict(other)), ("projections", PROJ_GEOMETRY)):
        assert cli.main(["reconstruct", str(proj), "--grid", str(scan), "-o", str(out),
                         "--geometry-from", source]) == 0
        line = capsys.readouterr().out
        assert f"geometry from {'grid file ' + str(scan) if source == 'grid' else 'projections ' + str(proj)}" in line
        info = read_tiff_info(out)
        assert xr.ConeBeamGeometry.from_dict(info["geometry"]) == want
        assert info["geometry_source"].startswith({"grid": "grid file", "projections": "projections"}[source])
    assert _digest([proj, scan]) == before


def test_equal_scan_geometries_are_used_without_a_flag(cl, tmp_path, capsys):
    proj = _projections(tmp_path)
    scan = _grid_file(tmp_path, geometry=PROJ_GEOMETRY.to_dict(), volume=SCAN_VOLUME)
    assert cli.main(["reconstruct", str(proj), "--grid", str(scan), "-o", str(tmp_path / "v.tif")]) == 0
    captured = capsys.readouterr()
    assert f"geometry from grid file {scan} (equal to the projections')" in captured.out
    assert captured.err == ""  # 8 views on a grid 16 across: not under-sampled by the rule's quarter


def test_too_few_views_for_the_grid_warn_in_one_line_and_still_succeed(cl, tmp_path, capsys):
    few = xr.ConeBeamGeometry(100, 200, (16, 16), 0.8, xr.full_circle(4))  # the bundled example's 4 views
    proj = _projections(tmp_path, few)
    out = tmp_path / "v.tif"
    assert cli.main(["reconstruct", str(proj), "--grid", str(_grid_file(tmp_path)), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert err == ("xrayraster: warning: 4 views for a grid 16 voxels across is under-sampled: the angular-sampling "
                   "rule asks for about π/2·16 ≈ 25; expect streaks\n")
    assert out.exists()


# --------------------------------------------------------------------------- --grid and its older spellings


def test_reconstruct_scan_file_and_geometry_are_deprecated_spellings_of_grid(cl, tmp_path, capsys):
    proj, scan = _projections(tmp_path), _grid_file(tmp_path)
    for n, flag in enumerate(("--scan-file", "--geometry")):
        out = tmp_path / f"v{n}.tif"
        assert cli.main(["reconstruct", str(proj), flag, str(scan), "-o", str(out)]) == 0
        assert capsys.readouterr().err == f"xrayraster: note: {flag} is deprecated; use --grid {scan}\n"
        assert out.exists()
    # Given twice, the note is still one line.
    assert cli.main(["reconstruct", str(proj), "--scan-file", str(scan), "--scan-file", str(scan),
                     "-o", str(tmp_path / "v2.tif")]) == 0
    assert capsys.readouterr().err == f"xrayraster: note: --scan-file is deprecated; use --grid {scan}\n"
    assert cli.main(["reconstruct", str(proj), "--grid", str(scan), "-o", str(tmp_path / "v3.tif"),
                     "--geometry-from", "scan-file"]) == 2  # the old value means the grid's geometry, which it lacks
    err = capsys.readouterr().err.splitlines()
    assert err == ["xrayraster: note: --geometry-from scan-file is deprecated; use --geometry-from grid",
                   f"xrayraster: error: --geometry-from grid: {scan} has no 'geometry'; add it or drop the flag"]
    with pytest.raises(SystemExit) as exc:
        cli.main(["reconstruct", str(proj), "--geometry", str(scan), "--grid", str(scan), "-o", str(out)])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        cli.main(["reconstruct", str(proj), "-o", str(out)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "the following arguments are required" not in err
    assert err.splitlines()[-1] == "xrayraster reconstruct: error: one of the arguments --grid is required"


def test_voxelize_scan_file_and_volume_are_deprecated_spellings_of_grid(gl, tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(TINY_SCENE)
    scan = _grid_file(tmp_path, volume={"shape": [4, 8, 8], "voxel_size": 1.0})
    for flag, note in (("--grid", ""), ("--scan-file", f"xrayraster: note: --scan-file is deprecated; use --grid {scan}\n"),
                       ("--volume", f"xrayraster: note: --volume is deprecated; use --grid {scan}\n")):
        out = tmp_path / f"labels{flag}.tif"
        assert cli.main(["voxelize", str(scene), flag, str(scan), "-o", str(out)]) == 0
        assert capsys.readouterr().err == note
        assert tifffile.imread(out).shape == (4, 8, 8) and tifffile.imread(out).max() == 1


def test_help_names_grid_only(capsys):
    for command in ("reconstruct", "voxelize"):
        with pytest.raises(SystemExit):
            cli.main([command, "--help"])
        text = capsys.readouterr().out
        assert "--grid GRID.json" in text and "--geometry SCAN" not in text and "--volume" not in text


# --------------------------------------------------------------------------- photon starvation in float32


def test_a_transmission_that_underflows_float32_counts_as_starved():
    steel = xr.Material.from_formula("Fe", 7.87)
    spectrum = xr.Spectrum.from_arrays([60.0], [1e6])
    # mm of iron (μ ≈ 0.95/mm at 60 keV): e^-142 and e^-285 are 0 in float32 but not in float64;
    # e^-950 is 0 even in float64: clamped before the log (counted once, not twice).
    lengths = np.array([[[0.0, 10.0, 150.0, 300.0, 1000.0]]], np.float32)
    got = radiograph(lengths, [steel], spectrum, xr.Detector(), 1.0, output="transmission")
    assert got.image[0, 0] == pytest.approx(1.0) and got.image[0, 1] > 0 and got.image[0, 4] > 0
    assert np.flatnonzero(got.image[0] == 0).tolist() == [2, 3]
    assert got.starved == 3
    line = radiograph(lengths, [steel], spectrum, xr.Detector(), 1.0, output="lineint")
    assert line.starved == 1 and np.all(np.isfinite(line.image))  # −ln stays finite in float32
    assert line.image[0, 3] == pytest.approx(2 * line.image[0, 2], rel=1e-5)


def test_the_cli_reports_underflowing_transmission_as_starved(gl, tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(TINY_SCENE.replace('material = "aluminium"', 'material = "iron"')
                     .replace("box = [5, 5, 5]", "box = [60, 60, 60]")
                     + '\n[materials.iron]\nformula = "Fe"\ndensity = 7.87\n\n[source]\nkvp = 40\n')
    out = tmp_path / "t.tif"
    assert cli.main(["render", str(scene), "-o", str(out), "--output", "transmission"]) == 0
    data = tifffile.imread(out)
    zeros = int(np.count_nonzero(data == 0))
    assert zeros > 0
    assert read_tiff_info(out)["starved_pixels"] == [zeros]
    assert f"{zeros} starved pixel(s)" in capsys.readouterr().out
