"""No user file is ever lost (docs/outputs.md): a directory full of a user's files, including the
names xrayraster writes (volume.tif, matrix.stl, scan.json, ...) and links, is given to every
command and every save/export, as the directory itself, a subdirectory of it and a link to it,
in every way a user could. Each attempt either is refused or writes beside the user's files;
afterwards every user file has its original bytes and every link its original target."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import tifffile
import trimesh
from PIL import Image

import xrayraster as xr
from xrayraster import cli
from xrayraster.io.weave_file import load_weave_file
from xrayraster.pipeline.compare import write_histogram_png

from inputs import WEAVE_TOML as WEAVE  # a one-cell weave that meshes in a fraction of a second

ROOT = Path(__file__).resolve().parents[2]
SCAN = ROOT / "examples" / "scan_small.toml"
SCENE = ROOT / "examples" / "bracket_and_ball.toml"
# The names the commands write, each present as the user's own file.
TOOL_NAMES = ("volume.tif", "labels.tif", "projections.tif", "radiograph.tif", "scan.json", "grid.json", "report.json",
              "compare.json", "slices.png", "volume.png", "histograms.png", "matrix.stl", "weft.stl", "warp.stl",
              "scene.toml", "seg_fractions.tif")


def _fill(user: Path, *, nested: bool = True) -> None:
    """A user's directory: foreign files of the tool's names, other files, links, and a
    subdirectory ``sub`` filled the same way."""
    user.mkdir()
    for name in TOOL_NAMES:
        path = user / name
        if name.endswith(".tif"):
            tifffile.imwrite(path, np.arange(24, dtype=np.float32).reshape(2, 3, 4), photometric="minisblack")  # Fiji-like, not ours
        elif name.endswith(".png"):
            Image.fromarray(np.full((4, 4), 7, np.uint8)).save(path)
        elif name.endswith(".stl"):
            trimesh.creation.box((1.0, 1.0, 1.0)).export(path)
        elif name.endswith(".json"):
            path.write_text(json.dumps({"mine": name}))
        else:
            path.write_text(f"# the user's own {name}\n")
    (user / "notes.txt").write_text("results of last week")
    (user / "notes_link.txt").symlink_to("notes.txt")
    (user / "mine.tif").symlink_to("volume.tif")  # a link with an output's suffix, to a user's TIFF
    if nested:
        _fill(user / "sub", nested=False)


def _snapshot(root: Path) -> dict:
    """Every file's bytes and every link's target under ``root`` (links not followed)."""
    state = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        if path.is_symlink():
            state[key] = ("link", os.readlink(path))
        elif path.is_file():
            state[key] = ("file", path.read_bytes())
    return state


@pytest.fixture(scope="module")
def made(gl, cl, tmp_path_factory):
    """What the Python API writes, made once: a weave file, a small scan's result and xr.weave's."""
    root = tmp_path_factory.mktemp("made")
    (root / "weave.toml").write_text(WEAVE)
    return root, xr.scan(SCAN), xr.weave(root / "weave.toml")


@pytest.fixture
def user(tmp_path):
    """The user's directory, a link to it from outside, and its original state."""
    home = tmp_path / "user"
    _fill(home)
    (tmp_path / "link_to_user").symlink_to(home)
    return tmp_path, home, _snapshot(home)


WHERE = ["directory", "subdirectory", "link to it"]


def _where(tmp: Path, home: Path, where: str) -> Path:
    return {"directory": home, "subdirectory": home / "sub", "link to it": tmp / "link_to_user"}[where]


def _kept(home: Path, before: dict) -> None:
    after = _snapshot(home)
    lost = {key: kind for key, (kind, value) in before.items() if after.get(key) != (kind, value)}
    assert not lost, f"user files changed or lost: {sorted(lost)}"


def _cli(argv, capsys) -> tuple[int, str]:
    code = cli.main(argv)
    return code, capsys.readouterr().err


@pytest.mark.parametrize("where", WHERE)
def test_every_command_into_a_users_directory(made, user, where, capsys):
    root, *_ = made
    tmp, home, before = user
    target = _where(tmp, home, where)
    weave = str(root / "weave.toml")
    scan_file = str(SCAN)
    projections = tmp / "p.tif"
    assert cli.main(["render", str(SCENE), "-o", str(projections), "--views", "all", "--path-lengths"]) == 0
    grid = tmp / "grid.json"
    grid.write_text(json.dumps({"volume": {"shape": [8, 8, 8], "voxel_size": 1.0}}))
    capsys.readouterr()

    # (argv, what the one-line refusal must name: the user's entry that would be replaced)
    refused = [
        # Directory commands: at the directory, with and without --force, and at a file-like name.
        (["scan", scan_file, "-o", str(target), "--quiet"], "labels.tif, scan.json, slices.png"),
        (["scan", scan_file, "-o", str(target), "--quiet", "--force"], "labels.tif, scan.json, slices.png, volume.tif"),
        (["scan", scan_file, "-o", str(target / "volume.tif"), "--quiet"], "ends in .tif"),
        (["weave", weave, "-o", str(target), "--quiet"], "grid.json, report.json, scene.toml"),
        (["weave", weave, "-o", str(target), "--quiet", "--force"], "grid.json, report.json, scene.toml"),
        # File commands: every name of the user's that the command would write.
        (["render", str(SCENE), "-o", str(target / "radiograph.tif"), "--path-lengths"], "radiograph.tif"),
        (["render", str(SCENE), "-o", str(target / "volume.tif"), "--path-lengths"], "volume.tif"),
        (["render", str(SCENE), "-o", str(target / "mine.tif"), "--path-lengths"], "volume.tif"),
        (["reconstruct", str(projections), "--grid", str(grid), "-o", str(target / "volume.tif")], "volume.tif"),
        (["reconstruct", str(projections), "--grid", str(grid), "-o", str(target / "slices.tif")], "slices.png"),
        (["voxelize", str(SCENE), "--grid", str(grid), "-o", str(target / "labels.tif")], "labels.tif"),
        (["voxelize", str(SCENE), "--grid", str(grid), "-o", str(target / "seg.tif"), "--fractions", "2"],
         "seg_fractions.tif"),
        (["compare", str(projections), str(projections), "-o", str(target)], "histograms.png"),
        (["compare", str(projections), str(projections), "--png", str(target / "slices.png")], "slices.png"),
        (["compare", str(projections), str(projections), "--json", str(target / "scan.json")], "scan.json"),
    ]
    for argv, named in refused:
        code, err = _cli(argv, capsys)
        assert code == 2 and named in err, (argv, err)
        assert err.count("\n") == 1 and err.startswith("xrayraster: error: "), (argv, err)
        _kept(home, before)

    # What may be written is written beside the user's files, never over them.
    # (A scan beside them: test_force_keeps_the_users_files_beside_a_replaced_output.)
    assert _cli(["weave", weave, "-o", str(target / "woven"), "--quiet"], capsys)[0] == 0
    assert _cli(["weave", weave, "-o", str(target / "woven"), "--quiet"], capsys)[0] == 0  # its own earlier output
    assert _cli(["render", str(SCENE), "-o", str(target / "fresh.tif"), "--path-lengths"], capsys)[0] == 0
    assert _cli(["render", str(SCENE), "-o", str(target / "fresh.tif"), "--path-lengths"], capsys)[0] == 0
    _kept(home, before)


@pytest.mark.parametrize("where", WHERE)
def test_force_keeps_the_users_files_beside_a_replaced_output(made, user, where, capsys):
    root, *_ = made
    tmp, home, before = user
    out = _where(tmp, home, where) / "scan"
    assert _cli(["scan", str(SCAN), "-o", str(out), "--quiet"], capsys)[0] == 0
    (out / "my_segmentation.tif").write_bytes(b"the user's work")
    (out / "my_notes").mkdir()
    code, err = _cli(["scan", str(SCAN), "-o", str(out), "--quiet"], capsys)
    assert code == 2 and "my_notes, my_segmentation.tif" in err and "--force" in err
    assert _cli(["scan", str(SCAN), "-o", str(out), "--quiet", "--force"], capsys)[0] == 0
    assert (out / "my_segmentation.tif").read_bytes() == b"the user's work" and (out / "my_notes").is_dir()
    assert json.loads((out / "scan.json").read_text())["files"] == ["labels.tif", "scan.json", "slices.png",
                                                                    "volume.tif"]
    _kept(home, before)


@pytest.mark.parametrize("where", WHERE)
def test_every_save_and_export_into_a_users_directory(made, user, where):
    root, result, woven = made
    tmp, home, before = user
    target = _where(tmp, home, where)
    sample = load_weave_file(root / "weave.toml")
    attempts = [
        lambda: result.save(target),
        lambda: result.save(target, overwrite=True),  # scan.json, volume.tif ... are the user's
        lambda: result.volume.save(target / "volume.tif"),
        lambda: result.volume.save(target / "mine.tif"),
        lambda: result.volume.save(target / "slices.tif"),  # its quick-look would replace slices.png
        lambda: result.labels.save(target / "labels.tif"),
        lambda: result.labels.save(target / "radiograph.tif", quicklook=False),
        lambda: sample.sample.export(target, materials=sample.materials),
        lambda: sample.sample.export(target, materials=sample.materials, overwrite=True),  # matrix.stl
        lambda: woven.save(target),
        lambda: woven.save(target, overwrite=True),  # report.json, scene.toml ... are the user's
        lambda: write_histogram_png(target / "histograms.png", xr.compare(result.volume.data, result.volume.data)),
    ]
    for attempt in attempts:
        with pytest.raises(xr.ConfigError):
            attempt()
        _kept(home, before)
    assert not (target / "slices.tif").exists() and not (target / "radiograph.tif").is_symlink()

    result.save(target / "scan")
    result.volume.save(target / "fresh.tif")
    result.volume.save(target / "fresh.tif")  # its own earlier output
    sample.sample.export(target / "meshes", materials=sample.materials)
    woven.save(target / "woven")
    woven.save(target / "woven")  # its own earlier output
    _kept(home, before)


def test_a_link_as_an_output_file_is_written_through_and_stays(made, tmp_path):
    _, result, _ = made
    real = result.volume.save(tmp_path / "real.tif", quicklook=False)
    link = tmp_path / "link.tif"
    link.symlink_to(real)
    result.volume.save(link, quicklook=False)
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.tif", "real.tif"]


def test_the_readme_weave_block_keeps_derived_files_outside_the_directory():
    """The README's weave block writes what it derives outside out/weave, so rerunning its first
    line (which replaces out/weave) loses nothing."""
    text = (ROOT / "README.md").read_text()
    block = text.split("## A woven sample", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    outputs = [line.split(" -o ", 1)[1].split()[0] for line in block.splitlines() if " -o " in line]
    weave_dir = outputs[0]
    assert weave_dir == "out/weave" and len(outputs) == 3
    assert all(not Path(o).is_relative_to(weave_dir) for o in outputs[1:])
