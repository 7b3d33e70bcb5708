"""Every command's input files, bad in each way a user's file can be: exit status 2 and one stderr
line naming the file (never exit 1, 'a bug'), and a UTF-8 byte-order mark accepted in TOML and JSON."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster import cli

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BOM = b"\xef\xbb\xbf"
# A PNG's header: NUL bytes and bytes that are not UTF-8, as any binary file has.
BINARY = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x10" + bytes(range(256))


def weave_text() -> str:
    """A weave file: scan_small.toml's [weave] and [materials] tables (one coarse cell, fast)."""
    text = (EXAMPLES / "scan_small.toml").read_text(encoding="utf-8")
    return text[:text.index("[source]")]


def tiny_stack(directory: Path) -> tuple[Path, Path]:
    """A 4-view, 8×8 projections TIFF with its geometry, and a JSON grid file with an 8³ grid."""
    geometry = xr.ConeBeamGeometry(source_to_origin=50.0, source_to_detector=100.0, detector_shape=(8, 8),
                                   pixel_size=0.5, angles=xr.full_circle(4))
    projections = xr.Projections(np.zeros((4, 8, 8), np.float32), geometry, "lineint", "1", {})
    scan_file = directory / "grid.json"
    scan_file.write_text(json.dumps({"volume": {"shape": [8, 8, 8], "voxel_size": 0.25}}), encoding="utf-8")
    return projections.save(directory / "stack.tif"), scan_file


def tiny_volume(directory: Path) -> Path:
    volume = np.ones((4, 6, 6), np.float32)
    path = directory / "a.tif"
    xr.Volume(volume, xr.VolumeGeometry(shape=(4, 6, 6), voxel_size=0.5), "1/cm", {}).save(path, quicklook=False)
    return path


# command → (the suffix of the input made bad, the valid text it holds in the BOM case (None: a
# binary file, no BOM case), the argument list with the input in its place, what a valid run needs).
COMMANDS = {
    "scan": ("toml", lambda d: (EXAMPLES / "scan_small.toml").read_text(encoding="utf-8"),
             lambda d, bad: ["scan", bad, "-o", d / "out", "--quiet"], ("gl", "cl")),
    "weave": ("toml", lambda d: weave_text(), lambda d, bad: ["weave", bad, "-o", d / "out", "--quiet"], ()),
    "render": ("toml", lambda d: _scene_text(), lambda d, bad: ["render", bad, "-o", d / "out.tif"], ("gl",)),
    "voxelize scene": ("toml", lambda d: _scene_text(),
                       lambda d, bad: ["voxelize", bad, "--grid", EXAMPLES / "bracket_ct.grid.json",
                                       "-o", d / "out.tif"], ("gl",)),
    "voxelize grid file": ("json", lambda d: (EXAMPLES / "bracket_ct.grid.json").read_text(encoding="utf-8"),
                           lambda d, bad: ["voxelize", EXAMPLES / "bracket_ct.toml", "--grid", bad,
                                           "-o", d / "out.tif"], ("gl",)),
    "reconstruct projections": ("tif", None, lambda d, bad: ["reconstruct", bad, "--grid", tiny_stack(d)[1],
                                                             "-o", d / "v.tif"], ()),
    "reconstruct grid file": ("json", lambda d: tiny_stack(d)[1].read_text(encoding="utf-8"),
                              lambda d, bad: ["reconstruct", tiny_stack(d)[0], "--grid", bad, "-o", d / "v.tif"],
                              ("cl",)),
    "compare": ("tif", None, lambda d, bad: ["compare", bad, tiny_volume(d)], ()),
    # Files a scene file names: a mesh (binary STL) and a spectrum (two-column text).
    "render mesh": ("stl", None, lambda d, bad: ["render", _scene_naming(d, mesh=bad), "-o", d / "out.tif"], ()),
    "render spectrum": ("txt", lambda d: "# keV  photons/mm² at 1 m\n59.5 5e6\n60.5 5e6\n",
                        lambda d, bad: ["render", _scene_naming(d, spectrum=bad), "-o", d / "out.tif"], ("gl",)),
}


def _scene_text() -> str:
    """bracket_ct.toml with its mesh path made absolute (the copy lives elsewhere)."""
    text = (EXAMPLES / "bracket_ct.toml").read_text(encoding="utf-8")
    return text.replace('mesh = "meshes/', f'mesh = "{EXAMPLES.as_posix()}/meshes/')


def _scene_naming(directory: Path, *, mesh: Path | None = None, spectrum: Path | None = None) -> Path:
    """A copy of bracket_ct.toml whose bracket's mesh file, or whose source's spectrum file, is the one given."""
    text = _scene_text()
    if mesh is not None:
        text = text.replace(f'{EXAMPLES.as_posix()}/meshes/bracket.stl', mesh.as_posix())
    if spectrum is not None:
        text = text.replace("monochromatic_kev = 60\nphotons_per_mm2_at_1m = 1e7", f'spectrum_file = "{spectrum.as_posix()}"')
    path = directory / "scene.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _bad(kind: str, path: Path, valid) -> None:
    if kind == "binary":
        path.write_bytes(BINARY)
    elif kind == "latin-1":  # text in another encoding: a comment with an accented letter
        path.write_bytes("# réglage du scanner\n".encode("latin-1") + (valid or "x = 1\n").encode("utf-8"))
    elif kind == "directory":
        path.mkdir()
    elif kind == "BOM":
        path.write_bytes(BOM + valid.encode("utf-8"))


CASES = [(command, kind) for command in COMMANDS for kind in ("binary", "latin-1", "directory", "missing", "BOM")
         if kind != "BOM" or COMMANDS[command][1] is not None]


@pytest.mark.parametrize("command, kind", CASES, ids=[f"{c}-{k}" for c, k in CASES])
def test_every_command_refuses_a_bad_input_file_in_one_line(request, tmp_path, capsys, command, kind):
    suffix, valid, argv, needs = COMMANDS[command]
    if kind == "BOM":  # a valid file runs the command; the bad ones fail before any GL or OpenCL
        for capability in needs:
            request.getfixturevalue(capability)
    bad = tmp_path / f"input file.{suffix}"
    _bad(kind, bad, valid(tmp_path) if valid else None)
    code = cli.main([str(a) for a in argv(tmp_path, bad)])
    err = capsys.readouterr().err
    if kind == "BOM":
        assert code == 0, err  # the byte-order mark is dropped, the file read as written
        return
    lines = err.splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("xrayraster: error: ") and str(bad) in lines[0], err
    what = {"binary": r"binary|as a TIFF|no triangles", "latin-1": r"not UTF-8|as a TIFF|no triangles",
            "directory": "is a directory", "missing": "no such file"}[kind]
    assert re.search(what, lines[0]), err


@pytest.mark.parametrize("suffix", ["stl", "obj"])
@pytest.mark.parametrize("kind", ["binary", "latin-1"])
def test_a_mesh_file_that_is_not_text_is_named_without_charset_normalizer(monkeypatch, tmp_path, suffix, kind):
    """trimesh guesses a non-UTF-8 text's encoding only when charset_normalizer is installed (a fresh
    `pip install ".[test]"` has none): what the file holds is said the same on every install."""
    monkeypatch.setitem(sys.modules, "charset_normalizer", None)  # `import charset_normalizer` now fails
    path = tmp_path / f"part.{suffix}"
    _bad(kind, path, "solid part\nendsolid part\n" if suffix == "stl" else "v 0 0 0\n")
    with pytest.raises(xr.MeshError) as caught:
        xr.load_mesh(path, name="part")
    message = str(caught.value)
    assert str(path) in message and "charset_normalizer" not in message
    assert re.search({"binary": "binary", "latin-1": r"not UTF-8 text \(byte 0xe9 at offset 3\)"}[kind], message)


def test_a_binary_stl_reads_as_the_triangles_it_holds(tmp_path):
    """The binary-STL check lets a real one through: a tetrahedron written by hand, byte by byte."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    body = b"".join(np.zeros(3, "<f4").tobytes() + vertices[list(f)].astype("<f4").tobytes() + b"\0\0" for f in faces)
    path = tmp_path / "tetra.stl"
    path.write_bytes(b"\0" * 80 + len(faces).to_bytes(4, "little") + body)
    mesh = xr.load_mesh(path)
    assert len(mesh.faces) == 4 and mesh.volume == pytest.approx(1 / 6)
