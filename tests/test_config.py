"""The TOML scene loader refuses every bad value with a ConfigError that names the file, the table
or object and the field (the CLI turns it into exit status 2), and loads good files as documented;
atomic output files get a new file's normal mode. No OpenGL needed."""

from __future__ import annotations

import math
import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from xrayraster import cli
from xrayraster.config import ConfigError, load_scene_file
from xrayraster.geometry import ConeBeamGeometry, ParallelBeamGeometry
from xrayraster.io import NEW_FILE_MODE, atomic_write, write_quicklook

ROOT = Path(__file__).resolve().parent.parent

CONE = """
[geometry]
source_to_origin = 100.0
source_to_detector = 200.0
detector_shape = [16, 16]
pixel_size = 0.5
"""
PARALLEL = """
[geometry]
beam = "parallel"
detector_shape = [16, 16]
pixel_size = 0.5
"""
BOX = """
[[objects]]
mesh = { box = [5, 5, 5] }
material = "a"
"""
BALL = """
[[objects]]
name = "box"
mesh = { box = [5, 5, 5] }
material = "a"

[[objects]]
name = "ball"
mesh = { sphere = 2.0 }
material = "b"
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


def load(tmp_path: Path, text: str):
    return load_scene_file(_write(tmp_path, text))


def with_geometry(line: str, base: str = CONE) -> str:
    """``base`` with one more [geometry] line (or a replacement of the key it sets), and a box."""
    key = line.split("=")[0].strip()
    kept = [l for l in base.splitlines() if l.split("=")[0].strip() != key]
    return "\n".join(kept) + "\n" + line + "\n" + BOX


def with_object(line: str) -> str:
    """Two objects; ``line`` goes into the second, "ball" (replacing the key it sets)."""
    key = line.split("=")[0].strip()
    head, ball = BALL.rsplit("[[objects]]", 1)
    kept = [l for l in ball.splitlines() if l.split("=")[0].strip() != key]
    return CONE + head + "[[objects]]" + "\n".join(kept) + "\n" + line + "\n"


BALL_AT = r"scene\.toml \[\[objects\]\] #2 \(ball\)"
GEOMETRY_AT = r"scene\.toml \[geometry\]"

# ------------------------------------------------------------------ 1. wrong types

WRONG_TYPES = {
    # objects
    "priority string": (with_object('priority = "high"'), BALL_AT + r": priority must be a number, got 'high'"),
    "priority bool": (with_object("priority = true"), BALL_AT + r": priority must be a number, got True"),
    "priority inf": (with_object("priority = inf"), BALL_AT + r": priority must be finite, got inf"),
    "unit_scale string": (with_object('unit_scale = "x"'), BALL_AT + r": unit_scale must be a number, got 'x'"),
    "label string": (with_object('label = "x"'), BALL_AT + r": label must be an integer in \[1, 65535\], got 'x'"),
    "label float": (with_object("label = 2.5"), BALL_AT + r": label must be an integer in \[1, 65535\], got 2\.5"),
    "label bool": (with_object("label = true"), BALL_AT + r": label must be an integer in \[1, 65535\], got True"),
    "label range": (with_object("label = 70000"), BALL_AT + r": label must be an integer in \[1, 65535\], got 70000"),
    "name number": (with_object("name = 3"), r"\[\[objects\]\] #2: name must be a non-empty string, got 3"),
    "material array": (with_object('material = ["a"]'), BALL_AT + r": material must be a name \(a string\), got \['a'\]"),
    "mesh number": (with_object("mesh = 5"), BALL_AT + r": mesh must be a file path or a primitive table .*got 5"),
    "mesh empty path": (with_object('mesh = ""'), BALL_AT + r": mesh must be a file path or a primitive table .*got ''"),
    "translate string": (with_object('translate = "1, 2, 3"'), BALL_AT + r": translate must be \[x, y, z\] in mm, got '1, 2, 3'"),
    "translate element": (with_object('translate = [1, "2", 3]'), BALL_AT + r": translate\[1\] must be a number, got '2'"),
    "rotate_deg table": (with_object("rotate_deg = { x = 1 }"), BALL_AT + r": rotate_deg must be \[x, y, z\] in degrees"),
    # mesh primitives
    "box short": (with_object("mesh = { box = [1, 1] }"), BALL_AT + r" mesh: box must be \[x, y, z\] edge lengths in mm, got \[1, 1\]"),
    "box number": (with_object("mesh = { box = 5 }"), BALL_AT + r" mesh: box must be \[x, y, z\] edge lengths in mm, got 5"),
    "box element": (with_object('mesh = { box = [1, "a", 1] }'), BALL_AT + r" mesh: box\[1\] must be a number, got 'a'"),
    "sphere string": (with_object('mesh = { sphere = "2" }'), BALL_AT + r" mesh: sphere must be a number, got '2'"),
    "subdivisions float": (with_object("mesh = { sphere = 2, subdivisions = 2.5 }"),
                           BALL_AT + r" mesh: subdivisions must be an integer in \[0, 8\], got 2\.5"),
    "cylinder height string": (with_object('mesh = { cylinder = 2, height = "3" }'), BALL_AT + r" mesh: height must be a number, got '3'"),
    # geometry
    "geometry number": (f"geometry = 5\n{BOX}", r"scene\.toml: geometry must be a table \(\[geometry\]\), got 5"),
    "angles_deg string": (with_geometry('angles_deg = "0, 90"', PARALLEL),
                          GEOMETRY_AT + r": angles_deg must be a non-empty array of angles in degrees, got '0, 90'"),
    "angles_deg empty": (with_geometry("angles_deg = []", PARALLEL), GEOMETRY_AT + r": angles_deg must be a non-empty array"),
    "angles_deg element": (with_geometry('angles_deg = [0, "90"]', PARALLEL), GEOMETRY_AT + r": angles_deg\[1\] must be a number, got '90'"),
    "num_views float": (with_geometry("num_views = 2.5"), GEOMETRY_AT + r": num_views must be an integer >= 1, got 2\.5"),
    "num_views zero": (with_geometry("num_views = 0"), GEOMETRY_AT + r": num_views must be an integer >= 1, got 0"),
    "start_angle string": (with_geometry('start_angle_deg = "90"'), GEOMETRY_AT + r": start_angle_deg must be a number, got '90'"),
    "beam number": (with_geometry("beam = 1"), GEOMETRY_AT + r": beam must be 'cone' or 'parallel', got 1"),
    "source_to_origin string": (with_geometry('source_to_origin = "100"'), GEOMETRY_AT + r": source_to_origin must be a number, got '100'"),
    "source_to_detector zero": (with_geometry("source_to_detector = 0"), GEOMETRY_AT + r": source_to_detector must be > 0, got 0"),
    "detector_shape string": (with_geometry('detector_shape = "16x16"'), GEOMETRY_AT + r": detector_shape must be an integer >= 1, got '16x16'"),
    "detector_shape float": (with_geometry("detector_shape = [16, 16.5]"), GEOMETRY_AT + r": detector_shape\[1\] must be an integer >= 1, got 16\.5"),
    "detector_shape three": (with_geometry("detector_shape = [16, 16, 16]"), GEOMETRY_AT + r": detector_shape must be an integer or \[rows, cols\]"),
    "pixel_size string": (with_geometry('pixel_size = "0.5"'), GEOMETRY_AT + r": pixel_size must be a number, got '0\.5'"),
    "pixel_size negative": (with_geometry("pixel_size = [0.5, -0.5]"), GEOMETRY_AT + r": pixel_size\[1\] must be > 0, got -0\.5"),
    "detector_offset table": (with_geometry("detector_offset = { u = 1 }"), GEOMETRY_AT + r": detector_offset must be a number, got \{'u': 1\}"),
    # top-level structure
    "objects number": (CONE.replace("[geometry]", "objects = 5\n[geometry]"), r"scene\.toml: objects must be an array of tables"),
    "objects not tables": (CONE.replace("[geometry]", "objects = [1, 2]\n[geometry]"),
                           r"scene\.toml \[\[objects\]\] #1: must be a table \(\[\[objects\]\]\), got 1"),
}


@pytest.mark.parametrize("text, message", WRONG_TYPES.values(), ids=WRONG_TYPES.keys())
def test_a_wrong_type_is_a_config_error_naming_the_field(text, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        load(tmp_path, text)


def test_the_cli_exits_2_on_a_wrong_type(tmp_path, capsys):
    """No traceback: the message names the file, the object and the field."""
    path = _write(tmp_path, with_object('priority = "high"'))
    code = cli.main(["render", str(path), "-o", str(tmp_path / "out.tif"), "--path-lengths"])
    assert code == 2
    err = capsys.readouterr().err
    assert err == f"xrayraster: error: {path} [[objects]] #2 (ball): priority must be a number, got 'high'\n"
    assert not (tmp_path / "out.tif").exists()


# ------------------------------------------------------------------ 2. vector lengths


@pytest.mark.parametrize("key, form", [("rotate_deg", r"\[x, y, z\] in degrees"), ("translate", r"\[x, y, z\] in mm")])
@pytest.mark.parametrize("value", ["[]", "[30]", "[0, 30]", "[0, 0, 30, 0]"])
def test_placement_vectors_need_exactly_three_numbers(key, form, value, tmp_path):
    with pytest.raises(ConfigError, match=BALL_AT + rf": {key} must be {form}, got {re.escape(value)}"):
        load(tmp_path, with_object(f"{key} = {value}"))


@pytest.mark.parametrize("line, message", [
    ("pixel_size = [0.5, 0.5, 0.5]", r"pixel_size must be a number or \[row, col\] in mm, got \[0\.5, 0\.5, 0\.5\]"),
    ("pixel_size = [0.5]", r"pixel_size must be a number or \[row, col\] in mm, got \[0\.5\]"),
    ("detector_offset = [1, 2, 3]", r"detector_offset must be a number or \[row, col\] in mm, got \[1, 2, 3\]"),
    ("detector_shape = [16]", r"detector_shape must be an integer or \[rows, cols\], got \[16\]"),
])
def test_pairs_need_one_or_two_values(line, message, tmp_path):
    with pytest.raises(ConfigError, match=GEOMETRY_AT + ": " + message):
        load(tmp_path, with_geometry(line))


def test_placement_is_rotation_x_y_z_then_translation(tmp_path):
    """A 1×2×4 box turned 90° about z then moved: its extents swap in x/y and its centre moves."""
    loaded = load(tmp_path, CONE + """
[[objects]]
mesh = { box = [1, 2, 4] }
material = "a"
rotate_deg = [0, 0, 90]
translate = [10, 0, -3]
""")
    lo, hi = loaded.scene.objects[0].mesh.bounds
    np.testing.assert_allclose(hi - lo, [2, 1, 4], atol=1e-9)
    np.testing.assert_allclose((hi + lo) / 2, [10, 0, -3], atol=1e-9)


# ------------------------------------------------------------------ 3, 4. combinations that would be ignored


def test_start_angle_with_explicit_angles_is_refused(tmp_path):
    text = with_geometry("angles_deg = [0, 90]", PARALLEL).replace("[geometry]", "[geometry]\nstart_angle_deg = 45")
    with pytest.raises(ConfigError, match=GEOMETRY_AT + r": 'start_angle_deg' only applies to 'num_views', not to "
                                          r"'angles_deg'; drop 'start_angle_deg' and add it to the angles"):
        load(tmp_path, text)


def test_start_angle_with_num_views_sets_the_first_angle(tmp_path):
    text = with_geometry("num_views = 4").replace("[geometry]", "[geometry]\nstart_angle_deg = 90")
    angles = load(tmp_path, text).geometry.angles
    np.testing.assert_allclose(np.degrees(angles), [90, 180, 270, 360])


@pytest.mark.parametrize("key", ["source_to_origin", "source_to_detector"])
def test_source_distances_are_refused_for_a_parallel_beam(key, tmp_path):
    with pytest.raises(ConfigError, match=GEOMETRY_AT + rf": '{key}' has no meaning for beam = 'parallel' .*"
                                          r"drop it, or set beam = 'cone'"):
        load(tmp_path, with_geometry(f"{key} = 100.0", PARALLEL))


def test_num_views_with_angles_is_still_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"give either 'num_views' \(full circle\) or 'angles_deg', not both"):
        load(tmp_path, with_geometry("angles_deg = [0, 90]", PARALLEL).replace("[geometry]", "[geometry]\nnum_views = 2"))


# ------------------------------------------------------------------ 5. sizes and counts out of range

OUT_OF_RANGE = {
    "sphere negative": ("mesh = { sphere = -2 }", r" mesh: sphere must be > 0, got -2"),
    "sphere zero": ("mesh = { sphere = 0.0 }", r" mesh: sphere must be > 0, got 0\.0"),
    "subdivisions negative": ("mesh = { sphere = 2, subdivisions = -1 }", r" mesh: subdivisions must be an integer in \[0, 8\], got -1"),
    "subdivisions huge": ("mesh = { sphere = 2, subdivisions = 12 }", r" mesh: subdivisions must be an integer in \[0, 8\], got 12"),
    "cylinder radius zero": ("mesh = { cylinder = 0, height = 3 }", r" mesh: cylinder must be > 0, got 0"),
    "cylinder height negative": ("mesh = { cylinder = 2, height = -3 }", r" mesh: height must be > 0, got -3"),
    "cylinder height missing": ("mesh = { cylinder = 2 }", r" mesh: missing 'height'"),
    "sections too few": ("mesh = { cylinder = 2, height = 3, sections = 2 }", r" mesh: sections must be an integer in \[3, 10000\], got 2"),
    "sections huge": ("mesh = { cylinder = 2, height = 3, sections = 1000000 }", r" mesh: sections must be an integer in \[3, 10000\], got 1000000"),
    "box zero": ("mesh = { box = [1, 0, 1] }", r" mesh: box\[1\] must be > 0, got 0"),
    "box negative": ("mesh = { box = [-1, 1, 1] }", r" mesh: box\[0\] must be > 0, got -1"),
    "unit_scale zero": ("unit_scale = 0", r": unit_scale must be > 0, got 0"),
    "unit_scale negative": ("unit_scale = -1.0", r": unit_scale must be > 0, got -1\.0"),
}


@pytest.mark.parametrize("line, message", OUT_OF_RANGE.values(), ids=OUT_OF_RANGE.keys())
def test_sizes_and_counts_out_of_range_are_refused(line, message, tmp_path):
    with pytest.raises(ConfigError, match=BALL_AT + message):
        load(tmp_path, with_object(line))


def test_the_smallest_allowed_primitives_load(tmp_path):
    loaded = load(tmp_path, CONE + """
[[objects]]
mesh = { sphere = 2, subdivisions = 0 }
material = "a"

[[objects]]
mesh = { cylinder = 1, height = 1, sections = 3 }
material = "b"
""")
    assert [len(o.mesh.faces) for o in loaded.scene.objects] == [20, 12]  # icosahedron; triangular prism (caps fanned from their centres)


# ------------------------------------------------------------------ 6. unknown keys everywhere

UNKNOWN = {
    "top level": ("colour = 1\n" + CONE + BOX, r"scene\.toml: unknown key\(s\) colour; allowed: geometry, objects"),
    "geometry": (with_geometry("num_view = 4"), GEOMETRY_AT + r": unknown key\(s\) num_view; allowed: angles_deg, beam, "),
    "geometry subtable": (CONE + "[geometry.detector]\nrows = 4\n" + BOX, GEOMETRY_AT + r": unknown key\(s\) detector; allowed: "),
    "object": (with_object('colour = "red"'), BALL_AT + r": unknown key\(s\) colour; allowed: label, material, mesh, name, "),
    "box": (with_object("mesh = { box = [1, 1, 1], sections = 4 }"), BALL_AT + r" mesh: unknown key\(s\) sections; allowed: box$"),
    "sphere": (with_object("mesh = { sphere = 1, height = 4 }"),
               BALL_AT + r" mesh: unknown key\(s\) height; allowed: sphere, subdivisions$"),
    "cylinder": (with_object("mesh = { cylinder = 1, height = 4, subdivisions = 2 }"),
                 BALL_AT + r" mesh: unknown key\(s\) subdivisions; allowed: cylinder, height, sections$"),
    "no primitive kind": (with_object("mesh = { radius = 1 }"),
                          BALL_AT + r" mesh: unknown key\(s\) radius; allowed: box, cylinder, height, sections, sphere, subdivisions$"),
}


@pytest.mark.parametrize("text, message", UNKNOWN.values(), ids=UNKNOWN.keys())
def test_unknown_keys_are_refused_naming_them_and_the_allowed_ones(text, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        load(tmp_path, text)


@pytest.mark.parametrize("mesh", ["{ }", "{ subdivisions = 2 }", "{ box = [1, 1, 1], sphere = 1 }"])
def test_a_primitive_names_exactly_one_kind(mesh, tmp_path):
    with pytest.raises(ConfigError, match=BALL_AT + r" mesh: a mesh primitive needs exactly one of box, sphere, cylinder"):
        load(tmp_path, with_object(f"mesh = {mesh}"))


# ------------------------------------------------------------------ good files still load as documented


def test_defaults_and_scalar_forms(tmp_path):
    loaded = load(tmp_path, """
[geometry]
source_to_origin = 100
source_to_detector = 250
detector_shape = 32
pixel_size = 0.25
""" + BALL)
    g = loaded.geometry
    assert isinstance(g, ConeBeamGeometry)
    assert g == ConeBeamGeometry(100.0, 250.0, (32, 32), (0.25, 0.25), (0.0,), (0.0, 0.0))
    assert [(o.name, o.material, o.label, o.priority) for o in loaded.scene.objects] == [("box", "a", 1, 0.0), ("ball", "b", 2, 0.0)]


def test_a_parallel_scene_with_every_field(tmp_path):
    loaded = load(tmp_path, """
[geometry]
beam = "parallel"
detector_shape = [8, 12]
pixel_size = [0.5, 0.25]
detector_offset = [0.0, 1.5]
angles_deg = [0, 90.0]

[[objects]]
name = "rod"
mesh = { cylinder = 1.0, height = 4.0, sections = 16 }
material = "steel"
label = 7
priority = 2.5
unit_scale = 2
rotate_deg = [90, 0, 0]
translate = [1, 2, 3]
""")
    assert loaded.geometry == ParallelBeamGeometry((8, 12), (0.5, 0.25), (0.0, math.pi / 2), (0.0, 1.5))
    rod = loaded.scene.objects[0]
    assert (rod.name, rod.material, rod.label, rod.priority) == ("rod", "steel", 7, 2.5)
    lo, hi = rod.mesh.bounds
    np.testing.assert_allclose((hi + lo) / 2, [1, 2, 3], atol=1e-9)
    assert hi[1] - lo[1] == pytest.approx(8.0)  # height 4 scaled by 2, turned from z onto y


def test_the_bundled_example_loads(tmp_path):
    loaded = load_scene_file(ROOT / "examples" / "bracket_and_ball.toml")
    assert loaded.geometry.num_views == 4 and loaded.scene.materials == ("aluminium", "steel")


# ------------------------------------------------------------------ 7. output file mode


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def test_atomic_write_gives_a_new_files_normal_mode(tmp_path):
    assert NEW_FILE_MODE == 0o666 & ~_umask()
    out = atomic_write(tmp_path / "a.bin", lambda tmp: Path(tmp).write_bytes(b"x"))
    assert stat.S_IMODE(out.stat().st_mode) == NEW_FILE_MODE
    png = write_quicklook(tmp_path / "b.png", np.ones((4, 4)))
    assert stat.S_IMODE(png.stat().st_mode) == NEW_FILE_MODE
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "b.png"]


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o027, 0o640), (0o002, 0o664), (0o077, 0o600)])
def test_output_mode_follows_the_umask_and_leaves_it_unchanged(umask, mode, tmp_path):
    """In a fresh interpreter, since the umask is read once, at import."""
    code = (
        "import os, stat, sys\n"
        f"os.umask({umask:#o})\n"
        "from xrayraster.io import atomic_write\n"
        "out = atomic_write(sys.argv[1], lambda tmp: open(tmp, 'wb').write(b'x'))\n"
        "print(oct(stat.S_IMODE(os.stat(out).st_mode)), oct(os.umask(0)))\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out.bin")], env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == [oct(mode), oct(umask)]
