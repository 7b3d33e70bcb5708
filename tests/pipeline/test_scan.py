"""xrayraster scan end to end (issue 14, first step): a small woven scan, its classes, its physics,
the alignment of reconstruction and labels, the output directory and the scan-file checks.

The physics tests scan a coarse cell with yarns several voxels thick (so eroded class masks are
not empty) built from examples/scan_small.toml by swapping its cell, geometry and grid; the
example itself runs once through the Python API.
"""

from __future__ import annotations

import importlib
import json
import math
import re
import threading
from pathlib import Path

import numpy as np
import pytest
import tifffile
import xraylib
from scipy import ndimage

import xrayraster as xr
from xrayraster import cli
from xrayraster.pipeline import load_scan_file
from xrayraster.weave.sample import PLATEAU

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "scan_small.toml"
MATRIX, WEFT, WARP = 1, 2, 3

# Two weft layers of two wefts, two binder positions: a 5 x 5 x 4 mm box whose wefts are 0.648 mm and
# warps 0.864 mm thick (5.6 and 7.5 voxels of 0.115 mm). The geometry is
# ConeBeamGeometry.framing(radius = 3.536, half_height = 2, num_views = 90, columns = 64), rounded. The
# grid's z offset puts voxel faces on the sample's top face (z = 2 mm) and on the flat top of the upper
# wefts (0.92 mm = 8 voxels below it), so there the label boundary is the true boundary.
THICK_CELL = """
[weave]
weft_per_layer = 2
weft_layers = 2
warp_positions = 2
thickness = 4.0
margin_z = 0.92
"""
THICK_GEOMETRY = """
[geometry]
beam = "cone"
source_to_origin = 17.68
source_to_detector = 35.36
detector_shape = [46, 64]
pixel_size = 0.23
num_views = 90

[volume]
shape = [44, 64, 64]
voxel_size = 0.115
offset = [0.045, 0.0, 0.0]
"""
VOXEL_MM = 0.115
# The mean chord (mm) through the 5 x 5 mm box over the scan's directions (π·area / perimeter), in
# matrix-like material, hardens the spectrum that the reconstruction's values are weighted by.
HARDENING_MM = np.pi * 25 / 20


def example_text() -> str:
    return EXAMPLE.read_text()


def thick_text() -> str:
    """The example with THICK_CELL for its [weave] table and THICK_GEOMETRY for its geometry and grid."""
    sample_to_source = example_text().split("[weave.sample]", 1)[1].split("# Cone beam framing", 1)[0]
    options = example_text().split("[scan]", 1)[1]
    return f"{THICK_CELL}\n[weave.sample]{sample_to_source}[scan]{options}{THICK_GEOMETRY}"


@pytest.fixture(scope="module")
def scanned(gl, cl, tmp_path_factory):
    """The thick-cell scan through the command line, into a directory holding an earlier scan output."""
    root = tmp_path_factory.mktemp("scan")
    (root / "thick.toml").write_text(thick_text())
    out = root / "out"
    out.mkdir()
    # An earlier scan's record lists its files: those (and only those) may go.
    (out / "scan.json").write_text(json.dumps({"generator": "xrayraster scan", "files": ["scan.json", "stale.txt"]}))
    (out / "stale.txt").write_text("from the earlier scan")
    assert cli.main(["scan", str(root / "thick.toml"), "-o", str(out), "--quiet"]) == 0
    volume = tifffile.imread(out / "volume.tif")
    labels = tifffile.imread(out / "labels.tif")
    metadata = json.loads((out / "scan.json").read_text())
    return root, out, volume, labels, metadata


def effective_attenuation_per_cm(fractions: dict, density: float, spectrum: xr.Spectrum) -> float:
    """μ (cm⁻¹) weighted by the detected spectrum: photons × energy (an energy-integrating detector,
    every photon absorbed), hardened by HARDENING_MM of the matrix; μ/ρ from xraylib's CS_Total."""
    energies = np.asarray(spectrum.energies_kev)
    photons = np.asarray(spectrum.photons)

    def mu(fr, rho):
        return rho * np.array([sum(w * xraylib.CS_Total(xraylib.SymbolToAtomicNumber(el), e) for el, w in fr.items())
                               for e in energies])

    matrix = mu({"C": 0.404, "H": 0.481, "Cl": 0.019, "O": 0.096}, 1.08)
    weights = photons * energies * np.exp(-matrix * HARDENING_MM / 10)
    return float(np.sum(weights * mu(fractions, density)) / np.sum(weights))


def test_three_classes_and_the_files(scanned):
    root, out, volume, labels, metadata = scanned
    assert sorted(np.unique(labels)) == [0, MATRIX, WEFT, WARP]
    assert volume.dtype == np.float32 and volume.shape == labels.shape == (44, 64, 64)
    assert sorted(p.name for p in out.iterdir()) == ["labels.tif", "scan.json", "slices.png", "volume.tif"]
    assert [p.name for p in root.iterdir() if p.name.startswith(".")] == []  # no temporaries left
    with tifffile.TiffFile(out / "volume.tif") as tif:  # Fiji's scale: the voxel size in mm
        assert tif.imagej_metadata["unit"] == "mm"
        assert abs(tif.imagej_metadata["spacing"] - VOXEL_MM) < 1e-9
    assert metadata["generator"] == "xrayraster scan" and metadata["seed"] == 0
    assert set(metadata["seconds"]) == {"sample", "projections", "fdk", "labels", "total"}
    assert metadata["peak_rss_mib"] > 0 and metadata["libraries"]["numpy"] == np.__version__
    assert metadata["volume"]["shape"] == [44, 64, 64] and metadata["geometry"]["num_views"] == 90
    fdk = metadata["reconstruction"]  # a centred full scan; the framed box's corners barely reach the edges
    assert fdk["scan"] == "full" and fdk["displaced"] is False and fdk["truncation"] == "auto"
    assert 0 <= fdk["truncation_corrected_row_ends"] < 0.05


def test_class_means_follow_the_physics(scanned):
    _, _, volume, labels, _ = scanned
    spectrum = load_scan_file(EXAMPLE).spectrum
    expected = {MATRIX: effective_attenuation_per_cm({"C": 0.404, "H": 0.481, "Cl": 0.019, "O": 0.096}, 1.08, spectrum),
                WEFT: effective_attenuation_per_cm({"C": 1.0}, 1.72, spectrum),
                WARP: effective_attenuation_per_cm({"C": 1.0}, 1.82, spectrum)}
    means = {}
    for label in (MATRIX, WEFT, WARP):
        core = ndimage.binary_erosion(labels == label, iterations=2)  # two voxels from every boundary
        assert core.sum() > 50, label
        means[label] = float(volume[core].mean())
    print("per-class means (cm^-1):", means, "expected:", expected)
    assert means[WARP] > means[WEFT] > means[MATRIX]
    for label, mu in expected.items():
        assert abs(means[label] / mu - 1) < 0.15, (label, means[label], mu)


def half_maximum(profile: np.ndarray, lo: int, hi: int, level: float) -> float:
    """The fractional index in [lo, hi] where ``profile`` first crosses ``level`` (linear interpolation)."""
    for k in range(lo, hi):
        a, b = profile[k] - level, profile[k + 1] - level
        if a == 0 or a * b < 0:
            return k + a / (a - b)
    raise AssertionError(f"no crossing of {level} in [{lo}, {hi}]")


def test_labels_and_reconstruction_are_aligned(scanned):
    """Along z from the top: air, the top face, matrix, a weft's top. Lines over the middle of the
    sample whose labels read so with the same boundaries are averaged (noise), and each half-maximum
    edge is compared with the label boundary (half-way between the voxel centres that differ)."""
    _, _, volume, labels, _ = scanned
    down_labels, down = labels[::-1], volume[::-1]  # index 0 at the top
    groups: dict[tuple[int, int], list] = {}
    for iy in range(16, 48):
        for ix in range(16, 48):
            column = down_labels[:, iy, ix]
            top = int(np.argmax(column > 0))
            weft = top + int(np.argmax(column[top:] != MATRIX))
            if column[top] == MATRIX and column[weft] == WEFT and weft - top >= 6 \
                    and np.all(column[weft:weft + 4] == WEFT):
                groups.setdefault((top, weft), []).append(down[:, iy, ix])
    (top, weft), profiles = max(groups.items(), key=lambda item: len(item[1]))
    assert len(profiles) >= 10
    profile = np.mean(profiles, axis=0)
    air, matrix, yarn = profile[:top - 2].mean(), profile[top + 2:weft - 2].mean(), profile[weft + 2:weft + 4].mean()
    face = half_maximum(profile, top - 2, top + 2, (air + matrix) / 2)
    edge = half_maximum(profile, weft - 2, weft + 2, (matrix + yarn) / 2)
    print(f"top face: edge {face:.3f}, label boundary {top - 0.5}; weft: edge {edge:.3f}, label boundary {weft - 0.5}")
    assert abs(face - (top - 0.5)) <= 0.5
    assert abs(edge - (weft - 0.5)) <= 0.5


def test_the_example_scans_in_python(gl, cl):
    result = xr.scan(EXAMPLE)
    assert isinstance(result, xr.ScanResult)
    assert sorted(np.unique(result.labels.data)) == [0, MATRIX, WEFT, WARP]
    assert result.volume.unit == "1/cm" and result.volume.data.shape == (24, 64, 64)
    assert result.labels.geometry == result.volume.geometry
    print("example stage times (s):", result.metadata["seconds"])


def test_beside_a_gpu_the_stages_overlap_and_keep_every_byte(gl, cl, monkeypatch):
    """As beside a GL on a GPU: several views' physics at once and each batch's FDK on a thread while
    the next renders; the volume and labels are the bytes of the scan in turn."""
    import xrayraster.simulate.renderer as renderer_module

    in_turn = xr.scan(EXAMPLE, gl=gl, cl=cl)
    fdk_threads = set()
    add = xr.FDKStream.add

    def watched_add(self, *args, **kwargs):
        fdk_threads.add(threading.current_thread().name)
        return add(self, *args, **kwargs)

    monkeypatch.setattr(renderer_module, "physics_workers", lambda software_gl, threads: 3)
    monkeypatch.setattr(xr.FDKStream, "add", watched_add)
    overlapped = xr.scan(EXAMPLE, gl=gl, cl=cl)
    assert fdk_threads and all(name.startswith("xrayraster-fdk") for name in fdk_threads)
    np.testing.assert_array_equal(overlapped.volume.data, in_turn.volume.data)
    np.testing.assert_array_equal(overlapped.labels.data, in_turn.labels.data)


def test_refuses_a_foreign_directory(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert cli.main(["scan", str(EXAMPLE), "-o", str(out), "--quiet"]) == 2
    assert "notes.txt" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_an_interrupted_scan_leaves_nothing(tmp_path, monkeypatch):
    """Ctrl-C while the result is saved (its volume written, the slices half-written)."""
    grid = xr.VolumeGeometry((2, 3, 4), 0.5)
    result = xr.ScanResult(xr.Volume(np.ones(grid.shape, np.float32), grid),
                           xr.LabelVolume(np.ones(grid.shape, np.uint8), grid), {"generator": "xrayraster scan"})

    def interrupted(path, *args, **kwargs):
        Path(path).write_bytes(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib.import_module("xrayraster.pipeline.scan"), "write_slices", interrupted)
    monkeypatch.setattr("xrayraster.cli.scan.scan", lambda loaded, **options: result)
    assert cli.main(["scan", str(EXAMPLE), "-o", str(tmp_path / "out"), "--quiet"]) == 130
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("[scan]\n", "[scan]\nspeed = 2\n"), r"\[scan\].*speed"),
    (lambda t: t.replace("[source]", "[not_a_source]"), "not_a_source"),
    (lambda t: t.split("[source]")[0] + "[geometry]" + t.split("[geometry]")[1], r"missing \[source\]"),
    (lambda t: t.replace('weft = "weft_carbon"', 'weft = "unobtainium"'), r"\[weave.materials\].*weft.*unobtainium"),
    (lambda t: t.replace("voxel_size = 0.23 ", "voxel_size = -1 "), r"\[volume\].*voxel_size"),
    (lambda t: t.replace('filter = "ram-lak"', 'filter = "lanczos"'), r"\[scan\].*filter"),
    (lambda t: t.replace("[scan]\n", '[scan]\ntruncation = "yes"\n'), r"\[scan\].*truncation"),
    (lambda t: t.replace("[scan]\n", "[scan]\ntruncation_width = 9\n"), r"\[scan\].*truncation_width"),
    (lambda t: t + '\n[physics]\nscatter = "monte-carlo"\n', r"\[physics\]: scatter must be one of none, kernel"),
    (lambda t: t + "\n[physics]\nscatter_scale = 2\n", r"\[physics\].*scatter_scale"),
])
def test_bad_scan_files_name_the_key_before_any_work(tmp_path, capsys, monkeypatch, edit, message):
    def no_work(*args, **kwargs):
        raise AssertionError("work started")

    # The module, not the function of the same name that xrayraster.pipeline exports.
    monkeypatch.setattr(importlib.import_module("xrayraster.pipeline.scan"), "Renderer", no_work)
    path = tmp_path / "bad.toml"
    path.write_text(edit(example_text()))
    assert cli.main(["scan", str(path), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err
    assert re.search(message, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


OBJECTS_SCAN = """
[[objects]]
name = "block"
mesh = { box = [4.0, 3.0, 2.0] }
material = "water"
translate = [1.0, -0.5, 0.25]

[geometry]
beam = "cone"
source_to_origin = 40.0
source_to_detector = 80.0
detector_shape = [24, 48]
pixel_size = 0.4
num_views = 60

[source]
monochromatic_kev = 30.0
photons_per_mm2_at_1m = 1e7

[scan]
noise = false
"""


def test_objects_default_grid_covers_their_bounds_at_the_magnified_pitch(gl, cl, tmp_path):
    path = tmp_path / "block.toml"
    path.write_text(OBJECTS_SCAN)
    loaded = load_scan_file(path)
    voxel = 0.4 * 40.0 / 80.0
    assert loaded.volume.voxel_size == (voxel,) * 3
    assert loaded.volume.shape == (10, 15, 20)  # ceil(extent / voxel) along z, y, x
    assert np.allclose(loaded.volume.offset, (0.25, -0.5, 1.0))  # centred on the block
    result = xr.scan(loaded)
    inside = result.labels.data == 1
    assert inside.all()  # the grid is the block's bounds: every voxel centre lies inside
    mu = 10 * xr.Material.named("water").attenuation_per_mm(30.0)  # cm⁻¹, monochromatic: no hardening
    core = ndimage.binary_erosion(inside, iterations=2)
    assert abs(result.volume.data[core].mean() / mu - 1) < 0.05


def test_with_scatter_the_scan_records_its_ratio_and_reads_mu_lower(gl, cl, tmp_path):
    """The block's scan with [physics] scatter: scan.json's realism names it, the scatter-to-primary
    ratios of its views are recorded (behind 2-4 mm of water at 30 keV: under a percent), and the
    added signal lowers the reconstructed μ where nothing else does."""
    plain, scattered = tmp_path / "plain.toml", tmp_path / "scatter.toml"
    plain.write_text(OBJECTS_SCAN)
    scattered.write_text(OBJECTS_SCAN + '\n[physics]\nscatter = "kernel"\n')
    without, with_ = xr.scan(plain), xr.scan(scattered)
    assert "scatter_to_primary" not in without.metadata["projections"]
    assert with_.metadata["realism"]["scatter"] == "kernel"
    ratio = with_.metadata["projections"]["scatter_to_primary"]
    assert 1e-4 < ratio["covered_mean"] <= ratio["centre_max"] < 0.05
    assert ratio["centre_mean"] <= ratio["centre_max"]
    assert with_.volume.data.mean() < without.volume.data.mean()


def test_mesh_resolution_follows_the_grid(tmp_path):
    """Knobs left open in [weave.sample] are chosen for the grid: the predicted error (tessellation
    theory, tested against measured meshes in test_weave_tessellation.py) stays within the
    tolerance, a coarser grid gets a coarser mesh, and knobs the file gives are kept."""
    from xrayraster.io.scan_file import load_scan_file
    from xrayraster.weave.tessellation import binder_bend_radius_mm, path_error_mm, section_error_mm

    text = example_text()
    fixed = load_scan_file(EXAMPLE)
    assert (fixed.weave.sample.points_per_section, fixed.weave.sample.samples_per_mm) == (12, 2.0)
    assert fixed.mesh_resolution["chosen_from_the_grid"] == []
    chosen = {}
    for voxel in (0.05, 0.2):
        path = tmp_path / f"open_{voxel}.toml"
        open_text = "\n".join(line if not line.startswith("voxel_size") else f"voxel_size = {voxel}"
                              for line in text.splitlines()
                              if not line.startswith(("points_per_section", "samples_per_mm")))
        assert f"voxel_size = {voxel}" in open_text
        path.write_text(open_text)
        loaded = load_scan_file(path)
        record, sample = loaded.mesh_resolution, loaded.weave.sample
        assert record["chosen_from_the_grid"] == ["points_per_section", "samples_per_mm"]
        assert record["tolerance_mm"] == pytest.approx(0.05 * voxel)
        cell = sample.cell
        error = max(section_error_mm(cell.weft_section, cell.weft_width, cell.weft_height, sample.points_per_section),
                    section_error_mm(cell.warp_section, cell.warp_width, cell.warp_height, sample.points_per_section))
        error += path_error_mm(binder_bend_radius_mm(cell), sample.samples_per_mm, cell.warp_height / 2)
        assert error <= record["tolerance_mm"] * (1 + 1e-9)
        chosen[voxel] = (sample.points_per_section, sample.samples_per_mm)
    assert chosen[0.2][0] < chosen[0.05][0] and chosen[0.2][1] < chosen[0.05][1]


def test_saved_projections_are_the_ones_reconstructed(gl, cl, tmp_path):
    """--save-projections writes the line integrals the FDK used: reconstructing the file again on the
    scan's grid gives volume.tif (float32 rounding), and they hold the scan file's 90 views."""
    from xrayraster.io.tiff import read_projections, read_tiff

    out = tmp_path / "scan"
    assert cli.main(["scan", str(EXAMPLE), "-o", str(out), "--quiet", "--save-projections"]) == 0
    projections = read_projections(out / "projections.tif")
    assert projections.quantity == "lineint" and projections.data.shape[0] == 90
    again = xr.fdk(projections, volume=load_scan_file(EXAMPLE).volume)
    volume = read_tiff(out / "volume.tif")[0]
    assert np.allclose(again.data, volume, rtol=0, atol=1e-5 * np.abs(volume).max())


FAMILY_CELLS = {  # the thick cell's box (5 x 5 x 4 mm), in each family's own form
    "orthogonal": 'family = "orthogonal"\nweft_per_layer = 2\nweft_layers = 2\nwarp_positions = 1\n'
                  "margin_z = 0.92\n",
    "through_thickness_angle_interlock": 'family = "through_thickness_angle_interlock"\nweft_layers = 2\n'
                                         "weft_spacing = 1.25\nwarp_positions = 2\nmargin_z = 0.92\n",
    "offset_angle_interlock": 'family = "offset_angle_interlock"\nweft_layers = 2\nweft_spacing = 1.25\n'
                              "warp_positions = 2\nmargin_z = 0.92\n",
    "plain": 'family = "plain"\nplies = 1\nmargin_z = 0.92\n',
    "twill": 'family = "twill"\nplies = 2\nwarp_spacing = 1.25\nweft_spacing = 1.25\nmargin_z = 0.92\n',
    "satin": 'family = "satin"\nplies = 2\nwarp_spacing = 1.0\nweft_spacing = 1.0\nmargin_z = 0.92\n',
}


@pytest.mark.parametrize("family", sorted(FAMILY_CELLS))
def test_every_family_scans_with_its_classes_ordered_as_they_attenuate(gl, cl, tmp_path, family):
    """The thick scan with the cell of another family: its reconstruction's class means, two voxels
    inside each class, read warp (carbon, 1.82 g/cm³) > weft (carbon, 1.72) > matrix (epoxy, 1.08)."""
    path = tmp_path / f"{family}.toml"
    path.write_text(thick_text().replace(THICK_CELL, "\n[weave]\n" + FAMILY_CELLS[family], 1))
    result = xr.scan(load_scan_file(path), gl=gl, cl=cl)
    volume, labels = result.volume.data, result.labels.data
    assert result.metadata["sample"]["cell"]["family"] == family
    means = {}
    for label in (MATRIX, WEFT, WARP):
        core = ndimage.binary_erosion(labels == label, iterations=2)
        assert core.sum() > 50, label
        means[label] = float(volume[core].mean())
    assert means[WARP] > means[WEFT] > means[MATRIX], means


def test_voids_reconstruct_as_air_under_their_own_label(gl, cl, tmp_path):
    """The thick scan with 2 % of matrix voids 0.3 mm in radius: they are labelled void (5, the
    classes below named), and their reconstruction, two voxels inside, reads as air (μ of air at
    these energies is ~5e-4 cm⁻¹, the matrix's ~0.4): under a twentieth of the matrix's mean."""
    path = tmp_path / "voids.toml"
    path.write_text(thick_text().replace("[weave.sample]", "[weave.voids]\nvolume_fraction = 0.02\nradius_mm = 0.3\n"
                                         "radius_spread = 0.1\n\n[weave.sample]", 1))
    result = xr.scan(load_scan_file(path), gl=gl, cl=cl)
    volume, labels = result.volume.data, result.labels.data
    assert result.metadata["labels"] == {"0": "background", "1": "matrix", "2": "weft", "3": "warp", "4": "binder",
                                         "5": "void"}
    assert result.metadata["sample"]["voids"]["volume_fraction"] == 0.02
    void = ndimage.binary_erosion(labels == 5, iterations=1)
    matrix = ndimage.binary_erosion(labels == MATRIX, iterations=2)
    assert void.sum() > 100
    assert abs(float(volume[void].mean())) < 0.05 * float(volume[matrix].mean())


def test_binder_labels_relabel_exactly_the_binders(scanned, gl, cl, tmp_path):
    """The thick scan again with ``labels = ["binder"]``: every voxel the classes labelled warp (its
    warps are all binders) is binder (4), every other voxel as before, and warp stays named (3,
    empty) so the class values run 0-4."""
    root, _, _, classes, _ = scanned
    path = tmp_path / "binder.toml"
    path.write_text(thick_text().replace("[scan]", "[scan]\nlabels = [\"binder\"]", 1))
    result = xr.scan(load_scan_file(path), gl=gl, cl=cl)
    labels = result.labels.data
    assert np.array_equal(labels == 4, classes == WARP) and labels[classes == WARP].size > 1000
    assert np.array_equal(labels[classes != WARP], classes[classes != WARP])
    assert result.metadata["labels"] == {"0": "background", "1": "matrix", "2": "weft", "3": "warp", "4": "binder"}
    assert result.metadata["options"]["labels"] == ["binder"]


@pytest.mark.parametrize("scan_table, message", [
    ('labels = ["instances"]', r"labels\[0\] must be one of classes, binder"),
    ('labels = "binder"', "labels must be a list of label volumes, the classes first"),
    ('labels = ["classes", "binder"]', r"labels\[1\] must be one of instances"),
    ('labels = ["classes", "instances", "instances"]', "names a label volume twice"),
])
def test_bad_label_choices_are_named(tmp_path, scan_table, message):
    path = tmp_path / "bad.toml"
    path.write_text(thick_text().replace("[scan]", f"[scan]\n{scan_table}", 1))
    with pytest.raises(xr.ConfigError, match=message):
        load_scan_file(path)


def test_binder_labels_need_a_woven_sample(tmp_path):
    path = tmp_path / "objects.toml"
    path.write_text('[[objects]]\nname = "ball"\nmaterial = "water"\nmesh = { sphere = { radius = 1.0 } }\n'
                    '[source]\nkvp = 40.0\n[scan]\nlabels = ["binder"]\n')
    with pytest.raises(xr.ConfigError, match=r"labels = \[.binder.\] labels a woven sample.s yarns"):
        load_scan_file(path)


def test_instance_labels_give_every_yarn_its_own_id(scanned, gl, cl, tmp_path):
    """``labels = ["classes", "instances"]``: beside the same class volume, one id per yarn. Every
    yarn voxel of the classes (weft or warp) has an id and every matrix or background voxel none;
    each id's voxels are of one class, the class of its yarn's family as scan.json lists it; every
    yarn of the sample that reaches a voxel centre has its own id; the files are written."""
    root, _, _, classes, _ = scanned
    path = tmp_path / "instances.toml"
    path.write_text(thick_text().replace("[scan]", "[scan]\nlabels = [\"classes\", \"instances\"]", 1))
    result = xr.scan(load_scan_file(path), gl=gl, cl=cl)
    ids, table = result.instances.data, result.metadata["instances"]
    assert np.array_equal(result.labels.data, classes)  # the classes are unchanged
    assert np.array_equal(ids > 0, (classes == WEFT) | (classes == WARP))
    family_class = {"weft": WEFT, "warp": WARP}
    for key, yarn in table.items():
        values = np.unique(classes[ids == int(key)])
        assert values.tolist() == [family_class[yarn["family"]]], (key, yarn)
    assert set(np.unique(ids)) - {0} == {int(k) for k in table}  # every listed yarn reaches a voxel here
    assert len({y["name"] for y in table.values()}) == len(table)
    out = result.save(tmp_path / "out")
    assert (out / "instances.tif").exists() and tifffile.imread(out / "instances.tif").dtype == ids.dtype


def test_direction_labels_follow_the_yarns(scanned, gl, cl, tmp_path):
    """``labels = ["classes", "directions"]``: 0 outside the yarns, a unit vector in them; every weft
    voxel of the regular weave points along x to 1e-3; and the binders of a through-thickness angle
    interlock, over the middle of the columns they climb through, make the path's analytic slope
    (straight from one turn's plateau to the next, docs/weave.md) within 1°."""
    _, _, _, classes, _ = scanned
    path = tmp_path / "directions.toml"
    path.write_text(thick_text().replace("[scan]", "[scan]\nlabels = [\"classes\", \"directions\"]", 1))
    result = xr.scan(load_scan_file(path), gl=gl, cl=cl)
    d = result.directions.astype(np.float64)
    assert result.directions.dtype == np.float16 and d.shape == (3, *classes.shape)
    yarn = (classes == WEFT) | (classes == WARP)
    assert np.all(d[:, ~yarn] == 0)
    assert np.allclose(np.linalg.norm(d[:, yarn], axis=0), 1, atol=2e-3)
    assert np.all(np.abs(d[:, classes == WEFT] - np.array([[1.0], [0.0], [0.0]])) <= 1e-3)
    out = result.save(tmp_path / "out")
    assert np.array_equal(tifffile.imread(out / "directions.tif"), result.directions)

    family = "through_thickness_angle_interlock"
    path = tmp_path / "ttai.toml"
    text = thick_text().replace(THICK_CELL, "\n[weave]\n" + FAMILY_CELLS[family], 1)
    path.write_text(text.replace("[scan]", "[scan]\nlabels = [\"classes\", \"directions\"]", 1))
    loaded = load_scan_file(path)
    result = xr.scan(loaded, gl=gl, cl=cl)
    cell = loaded.weave.sample.cell
    # Straight from the edge of the plateau over the weft it turns under (gap 0) to the start of the
    # one over the weft two columns on (gap 2): plateaus of ±PLATEAU[-1] of the weft's half-width.
    run = 2 * cell.weft_spacing - 2 * PLATEAU[-1] * cell.weft_width / 2
    slope = math.degrees(math.atan((cell.gap_z(2) - cell.gap_z(0)) / run))
    lo, hi = loaded.weave.sample.box
    grid = result.volume.geometry
    z = grid.axis_centres(0)[:, None] + (lo[2] + hi[2]) / 2  # the sample's z and y of each voxel
    y = grid.axis_centres(1)[None, :] + (lo[1] + hi[1]) / 2
    near = np.zeros(z.shape[:1] + y.shape[1:], bool)  # (z, y): on the straight middle of a climb
    for j in range(cell.weft_per_layer):
        before, here, after = (cell.binder_path[0][(j + d) % cell.weft_per_layer] for d in (-1, 0, 1))
        if here == 1:  # gaps 0, 1, 2, 1: climbing (or falling) through column j
            centre = (j + 0.5) * cell.weft_spacing
            line = cell.gap_z(1) + (y - centre) * (after - before) / 2 * math.tan(math.radians(slope)) * (
                cell.gap_z(2) - cell.gap_z(0)) / abs(cell.gap_z(2) - cell.gap_z(0))
            near |= (np.abs(y - centre) < 0.1 * cell.weft_spacing) & (np.abs(z - line) < 0.25 * cell.warp_height)
    binder = (result.labels.data == WARP) & near[:, :, None]
    d = result.directions.astype(np.float64)[:, binder]
    angles = np.degrees(np.arctan2(np.abs(d[2]), np.abs(d[1])))
    assert binder.sum() > 50
    assert np.all(np.abs(angles - slope) < 1.0), (slope, angles.min(), angles.max())


def test_centre_lines_are_written_where_the_yarns_run(tmp_path):
    """``"centrelines"`` through the command line: centrelines.json holds every yarn's centre line
    inside the sample, in the scanner frame (the box centred on the axis): each weft a straight line
    along x at its column's y and its layer's z, from one face of the box to the other; a binder
    passes over and under the wefts, between the box's top and bottom."""
    path = tmp_path / "lines.toml"
    path.write_text(thick_text().replace("[scan]", "[scan]\nlabels = [\"classes\", \"centrelines\"]", 1))
    out = tmp_path / "out"
    assert cli.main(["scan", str(path), "-o", str(out), "--quiet"]) == 0
    lines = json.loads((out / "centrelines.json").read_text())
    loaded = load_scan_file(path)
    sample, cell = loaded.weave.sample, loaded.weave.sample.cell
    lo, hi = sample.yarn_box
    centre = (sample.box[0] + sample.box[1]) / 2
    assert lines["units"] == "mm" and {y["name"] for y in lines["yarns"]} == {y.name for y in sample.yarns()}
    expected = {(round(wy - centre[1], 6), round(wz - centre[2], 6)) for wy in cell.weft_y for wz in cell.weft_layer_z}
    for yarn in lines["yarns"]:
        points = np.array(yarn["points"])
        assert np.all(points >= lo - centre - 1e-9) and np.all(points <= hi - centre + 1e-9)
        if yarn["kind"] == "weft":
            assert np.ptp(points[:, 1]) < 1e-9 and np.ptp(points[:, 2]) < 1e-9
            assert (round(points[0, 1], 6), round(points[0, 2], 6)) in expected
            assert points[0, 0] < lo[0] - centre[0] + 0.2 and points[-1, 0] > hi[0] - centre[0] - 0.2
        else:
            z = points[:, 2] + centre[2]
            assert z.min() == pytest.approx(cell.gap_z(0), abs=0.01) and z.max() == pytest.approx(
                cell.gap_z(cell.weft_layers), abs=0.01)


def test_every_extra_label_has_its_file():
    from xrayraster.core.choices import LABEL_EXTRAS
    from xrayraster.pipeline.scan import EXTRA_LABEL_NAMES

    assert tuple(EXTRA_LABEL_NAMES) == LABEL_EXTRAS
