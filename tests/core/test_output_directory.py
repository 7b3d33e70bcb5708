"""core.files.atomic_directory (a directory of outputs appears whole or not at all) and
ConeBeamGeometry.framing (a detector that sees the whole sample), checked from first principles."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core.files import HOST_TAG, NEW_DIR_MODE, atomic_directory


MARK = {"marker": "report.json", "generator": "xrayraster weave"}


def _write_output(directory: Path, **files: str) -> None:
    """An output as a command writes it: its files and the marker (atomic_directory adds "files")."""
    for name, text in files.items():
        (directory / name).write_text(text)
    (directory / "report.json").write_text(json.dumps({"generator": "xrayraster weave"}))


def _earlier_output(out: Path, **files: str) -> None:
    with atomic_directory(out, **MARK) as tmp:
        _write_output(tmp, **files)


def test_new_directory_appears_whole_and_records_its_names(tmp_path):
    out = tmp_path / "deep" / "meshes"
    with atomic_directory(out, **MARK) as tmp:
        assert tmp.parent == out.parent and not out.exists()   # built beside, under another name
        _write_output(tmp, **{"matrix.stl": "m"})
    assert sorted(p.name for p in out.iterdir()) == ["matrix.stl", "report.json"]
    assert json.loads((out / "report.json").read_text())["files"] == ["matrix.stl", "report.json"]
    assert out.stat().st_mode & 0o777 == NEW_DIR_MODE
    assert [p.name for p in out.parent.iterdir()] == ["meshes"]        # no temporary left


def test_failure_leaves_the_old_output_untouched(tmp_path):
    out = tmp_path / "meshes"
    _earlier_output(out, **{"matrix.stl": "old"})
    with pytest.raises(RuntimeError), atomic_directory(out, **MARK) as tmp:
        _write_output(tmp, **{"matrix.stl": "new"})
        raise RuntimeError("the work failed")
    assert (out / "matrix.stl").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["meshes"]


def test_an_earlier_output_is_replaced_not_merged(tmp_path):
    out = tmp_path / "meshes"
    _earlier_output(out, **{"yarn_7.stl": "from a bigger run"})
    with atomic_directory(out, **MARK) as tmp:
        _write_output(tmp, **{"yarn_1.stl": "new"})
    assert sorted(p.name for p in out.iterdir()) == ["report.json", "yarn_1.stl"]
    assert [p.name for p in tmp_path.iterdir()] == ["meshes"]


@pytest.mark.parametrize("make", ["file", "foreign directory", "unrecorded marker", "other generator"])
def test_refuses_to_replace_what_it_did_not_write(tmp_path, make):
    out = tmp_path / "meshes"
    if make == "file":
        out.write_text("precious")
    else:
        out.mkdir()
        (out / "thesis.tex").write_text("precious")
        if make == "unrecorded marker":  # a marker without the list of names: nothing in it is known to be ours
            (out / "report.json").write_text(json.dumps({"generator": "xrayraster weave"}))
        if make == "other generator":
            (out / "report.json").write_text(json.dumps({"generator": "xrayraster scan", "files": ["thesis.tex"]}))
    with pytest.raises(xr.ConfigError, match="is a file" if make == "file" else "thesis.tex"), \
            atomic_directory(out, **MARK):
        pytest.fail("the body must not run")
    assert out.exists() and (out.read_text() if make == "file" else (out / "thesis.tex").read_text()) == "precious"


def test_a_file_added_to_an_earlier_output_is_kept_and_the_replacement_refused(tmp_path):
    out = tmp_path / "meshes"
    _earlier_output(out, **{"matrix.stl": "old"})
    (out / "notes.txt").write_text("mine")
    with pytest.raises(xr.ConfigError, match=r"notes\.txt.*--force"), atomic_directory(out, **MARK):
        pytest.fail("the body must not run")
    assert (out / "notes.txt").read_text() == "mine" and (out / "matrix.stl").read_text() == "old"


def test_overwrite_replaces_ours_and_keeps_every_foreign_entry(tmp_path):
    out = tmp_path / "meshes"
    _earlier_output(out, **{"matrix.stl": "old", "yarn_7.stl": "from a bigger run"})
    (out / "notes.txt").write_text("mine")
    (out / "data").mkdir()
    (out / "data" / "x.stl").write_text("mine too")
    with atomic_directory(out, **MARK, overwrite=True) as tmp:
        _write_output(tmp, **{"matrix.stl": "new"})
    assert sorted(p.name for p in out.iterdir()) == ["data", "matrix.stl", "notes.txt", "report.json"]
    assert (out / "matrix.stl").read_text() == "new" and (out / "notes.txt").read_text() == "mine"
    assert (out / "data" / "x.stl").read_text() == "mine too"
    assert json.loads((out / "report.json").read_text())["files"] == ["matrix.stl", "report.json"]
    with pytest.raises(xr.ConfigError, match="data, notes.txt"), atomic_directory(out, **MARK):
        pytest.fail("the body must not run")  # the foreign entries still block a plain replacement


@pytest.mark.parametrize("known_before", [True, False])
def test_overwrite_never_replaces_a_foreign_file_of_an_output_name(tmp_path, known_before):
    out = tmp_path / "meshes"
    out.mkdir()
    (out / "matrix.stl").write_text("the user's own mesh")
    names = ("matrix.stl",) if known_before else ()
    with pytest.raises(xr.ConfigError, match="matrix.stl"), \
            atomic_directory(out, **MARK, overwrite=True, names=names) as tmp:
        assert not known_before, "a clash known before the work must be refused before it"
        _write_output(tmp, **{"matrix.stl": "ours"})
    assert (out / "matrix.stl").read_text() == "the user's own mesh"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meshes"]


def test_a_file_written_into_the_directory_during_the_work_is_kept(tmp_path):
    out = tmp_path / "meshes"
    _earlier_output(out, **{"matrix.stl": "old"})
    with pytest.raises(xr.ConfigError, match="late.txt"), atomic_directory(out, **MARK) as tmp:
        (out / "late.txt").write_text("written while the command ran")
        _write_output(tmp, **{"matrix.stl": "new"})
    assert (out / "late.txt").read_text() == "written while the command ran"
    assert (out / "matrix.stl").read_text() == "old"


def test_a_link_is_followed_and_stays(tmp_path):
    real = tmp_path / "real"
    _earlier_output(real, **{"matrix.stl": "old"})
    link = tmp_path / "link"
    link.symlink_to(real)
    with atomic_directory(link, **MARK) as tmp:
        _write_output(tmp, **{"matrix.stl": "new"})
    assert link.is_symlink() and link.resolve() == real.resolve()
    assert (real / "matrix.stl").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]


def test_a_dangling_link_and_a_file_name_are_refused(tmp_path):
    (tmp_path / "link").symlink_to(tmp_path / "nowhere")
    with pytest.raises(xr.ConfigError, match="does not exist"), atomic_directory(tmp_path / "link", **MARK):
        pytest.fail("the body must not run")
    with pytest.raises(xr.ConfigError, match=r"ends in \.tif"), atomic_directory(tmp_path / "vol.tif", **MARK):
        pytest.fail("the body must not run")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link"]


def test_a_killed_runs_temporary_directory_goes_a_live_ones_stays(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        stale = tmp_path / f".meshes.{HOST_TAG}.{dead.pid}.abc123_x"
        running = tmp_path / f".meshes.{HOST_TAG}.{live.pid}.def456"
        for folder in (stale, running):
            folder.mkdir()
            (folder / "matrix.stl").write_text("partial")
        _earlier_output(tmp_path / "meshes", **{"matrix.stl": "new"})
        assert not stale.exists() and (running / "matrix.stl").exists()
    finally:
        live.kill()
        live.wait()


@pytest.mark.parametrize("radius, half_height, magnification", [(7.07, 2.0, 2.0), (1.0, 10.0, 1.3), (50.0, 1.0, 4.0)])
def test_framing_sees_the_whole_cylinder_from_every_view(radius, half_height, magnification):
    g = xr.ConeBeamGeometry.framing(radius, half_height, num_views=12, magnification=magnification, columns=200)
    assert g.detector_shape[1] == 200 and g.num_views == 12
    phi = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    rim = np.concatenate([np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, z)])
                          for z in (-half_height, half_height)])
    vec = g.to_vec().array
    rows, cols = g.detector_shape
    worst = 0.0
    for s, d, u, v in (np.split(row, 4) for row in vec):
        n = np.cross(u, v)
        t = ((d - s) @ n) / ((rim - s) @ n)              # where each ray s -> p meets the detector plane
        hit = s + t[:, None] * (rim - s) - d
        c = hit @ u / (u @ u)                            # pixel units from the detector centre
        r = hit @ v / (v @ v)
        assert np.all(np.abs(c) <= cols / 2) and np.all(np.abs(r) <= rows / 2)
        worst = max(worst, np.abs(c).max() / (cols / 2))
    assert worst > 0.97                                  # and it is not needlessly wide (2 % margin)
    assert math.isclose(g.source_to_detector / g.source_to_origin, magnification)


def test_framing_rejects_bad_values():
    with pytest.raises(xr.GeometryError, match="magnification"):
        xr.ConeBeamGeometry.framing(5.0, 1.0, magnification=1.0)
    with pytest.raises(xr.GeometryError, match="radius"):
        xr.ConeBeamGeometry.framing(-5.0, 1.0)
