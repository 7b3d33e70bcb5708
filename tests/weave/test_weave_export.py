"""Sample.export and ``xrayraster weave``: mesh files, the report, the scene and scan files they come
with, checked against independent measures (trimesh volumes and ray containment, manifold3d
status, the renderer and voxelizer taking the scene file as it is)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tifffile
import trimesh

import xrayraster as xr
from references.solids import is_manifold
from xrayraster import cli
from xrayraster.io.grid_file import read_grid_file
from xrayraster.io.scene_file import load_scene_file
from xrayraster.weave import Sample, UnitCell

from inputs import WEAVE_TOML

ROOT = Path(__file__).resolve().parents[2]



@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``xrayraster weave weave.toml -o out`` (priority) and ``--resolve boolean --format ply``."""
    root = tmp_path_factory.mktemp("weave")
    (root / "weave.toml").write_text(WEAVE_TOML)
    assert cli.main(["weave", str(root / "weave.toml"), "-o", str(root / "out"), "--quiet"]) == 0
    assert cli.main(["weave", str(root / "weave.toml"), "-o", str(root / "fe"), "--quiet", "--resolve", "boolean",
                     "--format", "ply"]) == 0
    return root


def _report(directory: Path) -> dict:
    return json.loads((directory / "report.json").read_text())


@pytest.mark.parametrize("name", ["out", "fe"])
def test_every_mesh_file_is_closed_manifold_and_outward(exported, name):
    report = _report(exported / name)
    assert {p["name"] for p in report["parts"]} == {"matrix", "weft", "warp", "weft_c0_l1_y2"}
    for part in report["parts"]:
        mesh = trimesh.load(exported / name / part["file"], force="mesh", process=False)
        mesh.merge_vertices()  # STL stores triangle soup
        assert mesh.is_watertight and mesh.is_winding_consistent, part["name"]
        assert mesh.volume > 0 and is_manifold(mesh), part["name"]
        assert mesh.nondegenerate_faces().all(), part["name"]            # trimesh's own test (height > 1e-8)


def test_boolean_export_fractions_equal_the_mesh_volumes(exported):
    """Disjoint meshes: each family's occupied volume is the sum of its files' volumes (trimesh)."""
    report = _report(exported / "fe")
    box = np.array(report["box_mm"])
    box_volume = np.prod(box[1] - box[0])
    measured = {}
    for part in report["parts"]:
        mesh = trimesh.load(exported / "fe" / part["file"], force="mesh", process=False)
        measured[part["family"]] = measured.get(part["family"], 0.0) + mesh.volume
    for family, volume in measured.items():  # the files hold float32 vertices: ~1e-7 relative
        assert report["volume_mm3"][family] == pytest.approx(volume, rel=1e-6)
        assert report["volume_fraction"][family] == pytest.approx(volume / box_volume, rel=1e-6)
    assert sum(report["volume_fraction"].values()) == pytest.approx(1.0, abs=1e-9)
    assert report["interpenetration_mm3"]["after"] <= 1e-9 * report["volume_mm3"]["weft"]


def test_priority_export_fractions_match_point_sampling(exported):
    """Overlapping meshes, settled by priority: random points tested for containment by trimesh's
    ray test (no manifold3d) give the same fractions within the sampling error (σ < 0.004 for
    2·10⁴ points; a regular grid would alias with the layered weave)."""
    report = _report(exported / "out")
    parts = {p["name"]: trimesh.load(exported / "out" / p["file"], force="mesh") for p in report["parts"]}
    lo, hi = np.array(report["box_mm"])
    points = lo + np.random.default_rng(1).random((20_000, 3)) * (hi - lo)
    warp = parts["warp"].contains(points)
    weft = (parts["weft"].contains(points) | parts["weft_c0_l1_y2"].contains(points)) & ~warp
    for family, inside in (("warp", warp), ("weft", weft)):
        assert report["volume_fraction"][family] == pytest.approx(inside.mean(), abs=0.015)
    assert report["volume_fraction"]["matrix"] == pytest.approx(1 - warp.mean() - weft.mean(), abs=0.015)


def test_report_describes_the_sample(exported):
    report = _report(exported / "out")
    assert report["generator"] == "xrayraster weave" and report["seed"] == 7
    assert report["yarns"] == {"weft": 4 * 3, "binder": 2 * 2, "stuffer": 0, "total": 16}
    assert report["cell"]["weft_layers"] == 3 and report["distortion"]["weft_node_mm"] == [0.0, 0.03, 0.02]
    resin = report["materials"]["matrix"]
    assert resin["density"] == 1.08 and resin["mass_fractions"]["Cl"] == pytest.approx(0.019)
    weft = report["materials"]["weft"]
    assert weft["density"] == pytest.approx(0.6 * 1.76 + 0.4 * 1.08, rel=1e-12)
    assert report["interpenetration_mm3"]["before"] >= 0


def test_same_seed_gives_byte_identical_files(exported, tmp_path):
    assert cli.main(["weave", str(exported / "weave.toml"), "-o", str(tmp_path / "again"), "--quiet"]) == 0
    for part in _report(exported / "out")["parts"]:
        a, b = (hashlib.sha256((d / part["file"]).read_bytes()).hexdigest() for d in (exported / "out",
                                                                                      tmp_path / "again"))
        assert a == b, part["file"]


def test_scene_file_loads_as_written(exported):
    loaded = load_scene_file(exported / "out" / "scene.toml")
    assert [o.label for o in loaded.scene.objects] == [1, 2, 3, 2]
    lo, hi = loaded.scene.bounds
    assert np.allclose(lo, -hi, atol=1e-9)                                # centred on the rotation axis
    assert loaded.spectrum is not None and set(loaded.materials) == {"matrix", "weft", "warp", "weft_c0_l1_y2"}


def test_render_and_voxelize_take_the_scene_as_it_is(exported, gl, tmp_path):
    scene = exported / "out" / "scene.toml"
    assert cli.main(["render", str(scene), "-o", str(tmp_path / "r.tif")]) == 0
    out = tmp_path / "labels.tif"
    assert cli.main(["voxelize", str(scene), "--grid", str(exported / "out" / "grid.json"), "-o", str(out)]) == 0
    labels = tifffile.imread(out)
    assert set(np.unique(labels)) == {1, 2, 3}                           # the grid covers the box: no background
    report = _report(exported / "out")
    for family, label in (("weft", 2), ("warp", 3)):
        assert np.mean(labels == label) == pytest.approx(report["volume_fraction"][family], abs=0.03)



def test_an_export_from_before_the_grid_file_was_named_reads_and_is_replaced(exported, tmp_path):
    """Exports once wrote the grid as scan.json: it reads as a grid file, and a new export over the
    old one (recognised by its report) leaves grid.json and no scan.json."""
    old = tmp_path / "old"
    shutil.copytree(exported / "out", old)
    (old / "grid.json").rename(old / "scan.json")
    report = _report(old)
    report["files"] = sorted("scan.json" if f == "grid.json" else f for f in report["files"])
    (old / "report.json").write_text(json.dumps(report))
    assert read_grid_file(old / "scan.json") == read_grid_file(exported / "out" / "grid.json")
    assert cli.main(["weave", str(exported / "weave.toml"), "-o", str(old), "--quiet"]) == 0
    assert (old / "grid.json").exists() and not (old / "scan.json").exists()

@pytest.mark.parametrize("edit, message", [
    (("[weave.sample]", "[weave.sample]\ncell = [1, 1]"), "cell"),
    (('matrix = "resin"', 'matrix = "unobtainium"'), "unobtainium"),
    (('yarn = "weft_c0_l1_y2"', 'yarn = "weft_c0_l7_y2"'), "weft_c0_l7_y2"),
    (("weft_layers = 3", "weft_layers = 0"), "weft_layers"),
    (("[weave.distortion]", "[weave.distortion]\nwobble = 1"), "wobble"),
])
def test_bad_weave_files_name_the_field_and_write_nothing(tmp_path, capsys, edit, message):
    path = tmp_path / "weave.toml"
    path.write_text(WEAVE_TOML.replace(*edit))
    assert cli.main(["weave", str(path), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["weave.toml"]


def test_refuses_to_replace_a_directory_it_did_not_write(tmp_path, capsys):
    (tmp_path / "weave.toml").write_text(WEAVE_TOML)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "notes.txt").write_text("mine")
    assert cli.main(["weave", str(tmp_path / "weave.toml"), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    assert "notes.txt" in capsys.readouterr().err
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["notes.txt"]


def test_python_export_matches_the_command(exported, tmp_path):
    from xrayraster.io.weave_file import load_weave_file

    loaded = load_weave_file(exported / "weave.toml")
    report = loaded.sample.export(tmp_path, materials=loaded.materials, per="yarn")
    assert len(report["parts"]) == 1 + 16
    assert report["volume_mm3"] == pytest.approx(_report(exported / "out")["volume_mm3"], rel=1e-9)
    assert isinstance(loaded.sample, Sample) and isinstance(loaded.sample.cell, UnitCell)


def test_xr_weave_saves_what_the_command_writes(exported, tmp_path):
    result = xr.weave(tomllib.loads(WEAVE_TOML))  # the parsed table; a path works as well
    result.save(tmp_path / "py")
    command = exported / "out"
    names = sorted(p.name for p in command.iterdir())
    assert sorted(p.name for p in (tmp_path / "py").iterdir()) == names
    for name in names:
        if name == "report.json":  # the same but for the time taken
            assert {**_report(tmp_path / "py"), "seconds": 0} == {**_report(command), "seconds": 0}
        else:
            assert (tmp_path / "py" / name).read_bytes() == (command / name).read_bytes(), name
    loaded = load_scene_file(command / "scene.toml")
    assert [o.label for o in result.scene.objects] == [o.label for o in loaded.scene.objects]


def test_xr_weave_is_the_subpackage_too_whichever_is_imported_first():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    code = ("import xrayraster.weave as w; import xrayraster as xr; "
            "assert xr.weave is w and callable(w) and w.UnitCell().weft_layers > 0 and 'Sample' in dir(w)")
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert isinstance(xr.weave.Sample, type) and xr.weave.UnitCell is UnitCell


def test_bundled_weave_example_runs(tmp_path):
    """examples/weave.toml (docs/weave.md's quick start): 2 × 2 cells, distorted, one glass tracer."""
    assert cli.main(["weave", str(ROOT / "examples" / "weave.toml"), "-o", str(tmp_path / "weave"), "--quiet"]) == 0
    report = _report(tmp_path / "weave")
    assert report["yarns"]["total"] == 2 * (4 * 5) + 2 * 16 and report["cells"] == [2, 2]
    glass = report["materials"]["weft_c0_l2_y5"]
    assert glass["mass_fractions"]["Si"] > 0.1 and glass["density"] > report["materials"]["weft"]["density"]
