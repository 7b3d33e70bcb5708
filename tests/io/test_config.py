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

from xrayraster import Detector, Material, Spectrum, cli
from xrayraster.io.scene_file import ConfigError, load_scene_file
from xrayraster.core.geometry import ConeBeamGeometry, ParallelBeamGeometry
from xrayraster.core.files import NEW_FILE_MODE, atomic_write
from xrayraster.io.tiff import write_quicklook

ROOT = Path(__file__).resolve().parents[2]

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
    "top level": ("colour = 1\n" + CONE + BOX, r"scene\.toml: unknown key\(s\) colour; allowed: detector, geometry, materials, objects, physics, source$"),
    "geometry": (with_geometry("num_view = 4"), GEOMETRY_AT + r": unknown key\(s\) num_view; allowed: angles_deg, arc_deg, beam, "),
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
    assert (rod.name, rod.label, rod.priority) == ("rod", 7, 2.5)
    assert rod.material == Material.named("steel") and rod.material.name == "steel"  # a library name, no [materials]
    lo, hi = rod.mesh.bounds
    np.testing.assert_allclose((hi + lo) / 2, [1, 2, 3], atol=1e-9)
    assert hi[1] - lo[1] == pytest.approx(8.0)  # height 4 scaled by 2, turned from z onto y


def test_the_bundled_example_loads(tmp_path):
    loaded = load_scene_file(ROOT / "examples" / "bracket_and_ball.toml")
    assert loaded.geometry.num_views == 4 and [m.name for m in loaded.scene.materials] == ["aluminium", "steel"]
    assert loaded.scene.materials == (Material.element("Al"), Material.from_mass_fractions({"Fe": 0.98, "C": 0.02}, 7.85))
    assert loaded.spectrum == Spectrum.from_tube(80, "W", 12.0, {"Al": 1.0}, mas=5)
    assert loaded.detector == Detector(scintillator=Material.from_formula("CsI", 4.51), scintillator_mm=0.5)


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
        "from xrayraster.core.files import atomic_write\n"
        "out = atomic_write(sys.argv[1], lambda tmp: open(tmp, 'wb').write(b'x'))\n"
        "print(oct(stat.S_IMODE(os.stat(out).st_mode)), oct(os.umask(0)))\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out.bin")], env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == [oct(mode), oct(umask)]


# ------------------------------------------------------------------ 8. [materials], [source], [detector]

MATS = """
[materials.a]
element = "Al"

[materials.b]
formula = "H2O"
density = 1.0
"""
MONO = """
[source]
monochromatic_kev = 60.0
photons_per_mm2_at_1m = 1e6
"""


def test_materials_become_material_objects_named_by_their_table(tmp_path):
    loaded = load(tmp_path, CONE + MATS + """
[materials.c]
mass_fractions = { C = 0.404, H = 0.481, Cl = 0.019, O = 0.096 }
density = 1.2

[materials.heavy_al]
element = "Al"
density = 3.0
""" + BALL)
    a, b = loaded.scene.materials
    assert (a.name, b.name) == ("a", "b")
    assert a == Material.element("Al") and a.density == pytest.approx(2.6989)  # xraylib's density
    assert b == Material.from_formula("H2O", 1.0)
    assert loaded.materials["c"] == Material.from_mass_fractions({"C": 0.404, "H": 0.481, "Cl": 0.019, "O": 0.096}, 1.2)
    assert loaded.materials["heavy_al"].density == 3.0
    assert [o.material for o in loaded.scene.objects] == [a, b]
    assert loaded.spectrum is None and loaded.detector is None


def test_equal_compositions_under_different_names_share_a_channel(tmp_path):
    loaded = load(tmp_path, CONE + """
[materials.water]
formula = "H2O"
density = 1.0

[materials.tap_water]
formula = "H2O"
density = 1.0
""" + BALL.replace('material = "a"', 'material = "water"').replace('material = "b"', 'material = "tap_water"'))
    assert len(loaded.scene.materials) == 1 and loaded.scene.materials[0].name == "water"
    assert loaded.scene.channel(loaded.scene.objects[1]) == 0


def test_without_materials_a_material_stays_a_name(tmp_path):
    loaded = load(tmp_path, CONE + MONO + BALL)
    assert loaded.scene.materials == ("a", "b") and loaded.materials is None
    assert loaded.spectrum == Spectrum.monochromatic(60.0, 1e6)


def test_source_kinds(tmp_path):
    tube = load(tmp_path, CONE + MATS + """
[source]
kvp = 60
anode = "W"
anode_angle_deg = 10
filters = { Al = 2.0, Cu = 0.1 }
mas = 2
bin_kev = 1.0
""" + BALL).spectrum
    assert tube == Spectrum.from_tube(60, "W", 10, {"Al": 2.0, "Cu": 0.1}, mas=2, bin_kev=1.0)
    Spectrum.from_arrays([30.0, 50.0], [10.0, 20.0]).to_file(tmp_path / "spectra" / "s.txt")
    from_file = load(tmp_path, CONE + MATS + '[source]\nspectrum_file = "spectra/s.txt"\n' + BALL).spectrum
    assert from_file == Spectrum.from_arrays([30.0, 50.0], [10.0, 20.0])  # relative to the scene file


def test_detector_with_every_field(tmp_path):
    det = load(tmp_path, CONE + MATS + MONO + """
[detector]
mode = "counting"
scintillator = "b"
scintillator_mm = 0.3
blur_sigma_px = 0.8
electronic_noise = 2
dark = 10
""" + BALL).detector
    assert det == Detector("counting", Material.from_formula("H2O", 1.0), 0.3, 0.8, None, 2.0, 10.0)
    inline = load(tmp_path, CONE + MONO + '[detector]\nscintillator = { formula = "CsI", density = 4.51 }\nscintillator_mm = 0.5\n' + BALL)
    assert inline.detector == Detector(scintillator=Material.from_formula("CsI", 4.51), scintillator_mm=0.5)
    assert inline.detector.scintillator.name == "CsI"


MAT_AT = r"scene\.toml \[materials\.m\]"
SRC_AT = r"scene\.toml \[source\]"
DET_AT = r"scene\.toml \[detector\]"
PHYSICS_ERRORS = {
    "undefined material": (CONE + MATS.replace("[materials.b]", "[materials.bb]") + BALL,
                           BALL_AT + r": material 'b' is not defined in \[materials\] \(defined: a, bb\) nor a library material "
                           r"\(air, water, .*\); add a \[materials\.b\] table"),
    "materials not a table": ("materials = 3\n" + CONE + BALL, r"scene\.toml: materials must be a table"),
    "material not a table": (CONE + "[materials]\nm = 3\n" + BALL, MAT_AT + r": must be a table"),
    "material no kind": (CONE + "[materials.m]\ndensity = 1.0\n" + BOX, MAT_AT + r": give exactly one of element, formula, mass_fractions \(got none\)"),
    "material two kinds": (CONE + '[materials.m]\nelement = "Al"\nformula = "H2O"\ndensity = 1\n' + BOX,
                           MAT_AT + r": give exactly one of element, formula, mass_fractions \(got element and formula\)"),
    "material unknown key": (CONE + '[materials.m]\nelement = "Al"\ncolour = 1\n' + BOX,
                             MAT_AT + r": unknown key\(s\) colour; allowed: density, element, formula, mass_fractions"),
    "formula without density": (CONE + '[materials.m]\nformula = "H2O"\n' + BOX, MAT_AT + r": missing 'density'"),
    "density string": (CONE + '[materials.m]\nformula = "H2O"\ndensity = "1"\n' + BOX, MAT_AT + r": density must be a number, got '1'"),
    "density zero": (CONE + '[materials.m]\nelement = "Al"\ndensity = 0\n' + BOX, MAT_AT + r": density must be > 0, got 0"),
    "element number": (CONE + "[materials.m]\nelement = 13\n" + BOX, MAT_AT + r": element must be a non-empty string, got 13"),
    "unknown element": (CONE + '[materials.m]\nelement = "Xx"\n' + BOX, MAT_AT + r": element: unknown chemical symbol 'Xx'"),
    "bad formula": (CONE + '[materials.m]\nformula = "H2Oo"\ndensity = 1\n' + BOX, MAT_AT + r": formula: cannot parse 'H2Oo'"),
    "fractions not a table": (CONE + '[materials.m]\nmass_fractions = [1]\ndensity = 1\n' + BOX, MAT_AT + r": mass_fractions must be a table"),
    "fraction string": (CONE + '[materials.m]\nmass_fractions = { C = "1" }\ndensity = 1\n' + BOX,
                        MAT_AT + r": mass_fractions\.C must be a number, got '1'"),
    "fraction negative": (CONE + '[materials.m]\nmass_fractions = { C = -1, H = 2 }\ndensity = 1\n' + BOX,
                          MAT_AT + r": mass_fractions\.C must be >= 0, got -1"),
    "fractions in percent": (CONE + '[materials.m]\nmass_fractions = { C = 40, H = 60 }\ndensity = 1\n' + BOX,
                             MAT_AT + r": composition: mass fractions sum to 100, not 1"),
    "source not a table": ("source = 1\n" + CONE + BOX, r"scene\.toml: source must be a table"),
    "source none": (CONE + "[source]\nmas = 1\n" + BOX, SRC_AT + r": give exactly one source kind: .* \(got none\)"),
    "source two kinds": (CONE + '[source]\nkvp = 80\nspectrum_file = "s.txt"\n' + BOX, SRC_AT + r": .*\(got kvp and spectrum_file\)"),
    "source stray key": (CONE + MONO + "mas = 2\n" + BOX, SRC_AT + r": mas do\(es\) not apply to a monochromatic_kev source; allowed with"),
    "source unknown key": (CONE + "[source]\nkvp = 80\nkv = 80\n" + BOX, SRC_AT + r": unknown key\(s\) kv; allowed: anode, "),
    "kvp string": (CONE + '[source]\nkvp = "80"\n' + BOX, SRC_AT + r": kvp must be a number, got '80'"),
    "mas zero": (CONE + "[source]\nkvp = 80\nmas = 0\n" + BOX, SRC_AT + r": mas must be > 0, got 0"),
    "bad anode": (CONE + '[source]\nkvp = 80\nanode = "Pb"\n' + BOX, SRC_AT + r": anode 'Pb' is not a SpekPy anode"),
    "filters not a table": (CONE + '[source]\nkvp = 80\nfilters = "Al"\n' + BOX, SRC_AT + r": filters must be a table"),
    "filter negative": (CONE + "[source]\nkvp = 80\nfilters = { Al = -1 }\n" + BOX, SRC_AT + r": filters\.Al must be >= 0, got -1"),
    "unknown filter": (CONE + "[source]\nkvp = 80\nfilters = { Unobtainium = 1 }\n" + BOX, SRC_AT + r": filters: 'Unobtainium' is not a SpekPy material"),
    "mono without photons": (CONE + "[source]\nmonochromatic_kev = 60\n" + BOX, SRC_AT + r": missing 'photons_per_mm2_at_1m'"),
    "mono out of range": (CONE + "[source]\nmonochromatic_kev = 1000\nphotons_per_mm2_at_1m = 1\n" + BOX,
                          SRC_AT + r": monochromatic_kev must be in \[0\.1, 800\] keV"),
    "missing spectrum file": (CONE + '[source]\nspectrum_file = "nope.txt"\n' + BOX, SRC_AT + r": spectrum file .*nope\.txt: no such file"),
    "detector unknown key": (CONE + "[detector]\nnoise = 1\n" + BOX, DET_AT + r": unknown key\(s\) noise; allowed: blur_sigma_px, dark, "),
    "detector mode": (CONE + '[detector]\nmode = "photon"\n' + BOX, DET_AT + r": mode must be 'integrating' or 'counting', got 'photon'"),
    "scintillator undefined": (CONE + '[detector]\nscintillator = "lyso"\nscintillator_mm = 1\n' + BOX,
                               DET_AT + r": scintillator 'lyso' is not defined in \[materials\] \(defined: none\) nor a "
                                        r"library material \(air, .*csi"),
    "scintillator number": (CONE + "[detector]\nscintillator = 5\n" + BOX, DET_AT + r": scintillator must be a material name"),
    "scintillator inline bad": (CONE + '[detector]\nscintillator = { formula = "CsI" }\nscintillator_mm = 1\n' + BOX,
                                DET_AT + r" scintillator: missing 'density'"),
    "scintillator without thickness": (CONE + MATS + '[detector]\nscintillator = "a"\n' + BOX,
                                       DET_AT + r": give both scintillator and scintillator_mm > 0, or neither"),
    "thickness without scintillator": (CONE + "[detector]\nscintillator_mm = 1\n" + BOX, DET_AT + r": give both scintillator"),
    "blur negative": (CONE + "[detector]\nblur_sigma_px = -1\n" + BOX, DET_AT + r": blur_sigma_px must be >= 0, got -1"),
    "noise string": (CONE + '[detector]\nelectronic_noise = "2"\n' + BOX, DET_AT + r": electronic_noise must be a number, got '2'"),
    "dark inf": (CONE + "[detector]\ndark = inf\n" + BOX, DET_AT + r": dark must be finite, got inf"),
}


@pytest.mark.parametrize("text, message", PHYSICS_ERRORS.values(), ids=PHYSICS_ERRORS.keys())
def test_materials_source_and_detector_errors_name_the_table_and_field(text, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        load(tmp_path, text)
