"""A scan file's [pose] (issue 22): the sample turned about its box centre, then moved; the labels
follow it, the reconstruction lines up with them, the default grid covers it, bad values are refused.

The scans are tiny (60 views of 64 × 64 pixels, 48³ voxels of 0.2 mm, monochromatic, noise-free).
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster import cli
from xrayraster.core.errors import ConfigError
from xrayraster.pipeline import load_scan_file
from xrayraster.io.pose import Pose


EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scan_small.toml"
VOXEL_MM = 0.2
BOX_SCAN = """
[[objects]]
name = "block"
mesh = {{ box = {box} }}
material = "aluminium"
translate = [0.5, -0.25, 0.0]

[geometry]
beam = "cone"
source_to_origin = 40.0
source_to_detector = 80.0
detector_shape = [64, 64]
pixel_size = 0.4              # 0.2 mm at the axis: a 12.8 mm field of view
num_views = 60

[source]
monochromatic_kev = 40.0
photons_per_mm2_at_1m = 1e7

[scan]
noise = false
"""
GRID = """
[volume]
shape = [48, 48, 48]
voxel_size = 0.2
"""


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def shift(v):
    m = np.eye(4)
    m[:3, 3] = v
    return m


def turn(r):
    m = np.eye(4)
    m[:3, :3] = r
    return m


@pytest.mark.parametrize("tilt", [(0, 0, 0), (30, 0, 0), (0, -45, 0), (0, 0, 90), (10, 20, 30), (-170, 95, 180)])
def test_the_pose_is_turns_about_x_then_y_then_z_about_the_pivot_then_the_offset(tilt):
    offset, pivot = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.0, -4.0])
    pose = Pose(tuple(offset), tuple(float(t) for t in tilt), tuple(pivot))
    a, b, c = np.radians(tilt)
    expected = shift(pivot + offset) @ turn(rz(c) @ ry(b) @ rx(a)) @ shift(-pivot)
    assert np.allclose(pose.transform.array, expected, atol=1e-12)
    assert np.allclose(pose.transform.apply([pivot]), [pivot + offset])  # the pivot only moves


def test_a_quarter_turn_about_z_takes_x_to_y():
    assert np.allclose(Pose(tilt_deg=(0.0, 0.0, 90.0)).transform.apply([[1.0, 0.0, 0.0]]), [[0.0, 1.0, 0.0]])
    assert Pose().is_identity and not Pose(offset_mm=(0.0, 0.0, 1e-9)).is_identity


# 2.1 mm tall, an odd number of half voxels: the offset's 2.5 voxels in z then move one face of the
# hard labels by 2 voxels and the other by 3, and their centroid by 2.5 (with a whole number of voxels
# both faces move by 2, or both by 3, half a voxel off). No face of the block, placed or moved, lies
# on a plane of voxel centres (there a centre's label is a tie).
BOX_MM = (3.0, 2.0, 2.1)


def write(tmp_path, name: str, box=BOX_MM, pose: str = "", grid: str = GRID):
    path = tmp_path / f"{name}.toml"
    path.write_text(BOX_SCAN.format(box=list(box)) + grid + pose)
    return path


def centroid_mm(mask: np.ndarray, grid: xr.VolumeGeometry) -> np.ndarray:
    """The mean (x, y, z) of the voxel centres in ``mask`` (z, y, x), mm."""
    idx = np.argwhere(mask).astype(np.float64)
    return np.array([grid.axis_centres(axis)[0] + idx[:, axis].mean() * grid.voxel_size[axis]
                     for axis in (2, 1, 0)])


@pytest.fixture(scope="module")
def box_scans(gl, cl, tmp_path_factory):
    """The block as placed, offset by (1, 0, 0.5) mm, and tilted and offset, on one fixed grid."""
    root = tmp_path_factory.mktemp("pose")
    poses = {"placed": "", "offset": "[pose]\noffset_mm = [1.0, 0.0, 0.5]\n",
             "tilted": "[pose]\noffset_mm = [1.0, 0.0, 0.5]\ntilt_deg = [20.0, -15.0, 30.0]\n"}
    return {name: xr.scan(write(root, name, pose=pose)) for name, pose in poses.items()}


def bright(result) -> np.ndarray:
    """The voxels above half the block's μ (cm⁻¹), monochromatic: no hardening."""
    return result.volume.data > 0.5 * 10 * xr.Material.named("aluminium").attenuation_per_mm(40.0)


def test_an_offset_moves_labels_and_reconstruction_alike(box_scans):
    placed, offset = box_scans["placed"], box_scans["offset"]
    grid = placed.labels.geometry
    assert offset.labels.geometry == grid  # a given [volume] is kept
    labels = centroid_mm(offset.labels.data == 1, grid) - centroid_mm(placed.labels.data == 1, grid)
    recon = centroid_mm(bright(offset), grid) - centroid_mm(bright(placed), grid)
    print(f"label centroid shift {labels}, reconstruction's {recon} (mm; offset [1, 0, 0.5])")
    assert np.all(np.abs(labels - [1.0, 0.0, 0.5]) <= VOXEL_MM / 2)
    assert np.all(np.abs(recon - [1.0, 0.0, 0.5]) <= VOXEL_MM / 2)
    assert offset.metadata["pose"] == {"offset_mm": [1.0, 0.0, 0.5], "tilt_deg": [0.0, 0.0, 0.0],
                                       "pivot_mm": [0.5, -0.25, 0.0]}


def dice(a: np.ndarray, b: np.ndarray) -> float:
    return 2 * np.sum(a & b) / (a.sum() + b.sum())


def test_a_posed_sample_lines_up_with_its_labels(box_scans):
    for name, result in box_scans.items():
        score = dice(bright(result), result.labels.data == 1)
        print(f"{name}: Dice of the thresholded reconstruction and the labels {score:.4f}")
        assert score > 0.9, name
    tilted = box_scans["tilted"]
    assert abs(dice(tilted.labels.data == 1, box_scans["offset"].labels.data == 1) - 1) > 0.1  # it did turn


def principal_angle_deg(mask: np.ndarray, grid: xr.VolumeGeometry) -> float:
    """The direction in (x, y) of the labelled voxels' longest axis, degrees in (−90, 90]."""
    idx = np.argwhere(mask)[:, ::-1] * np.array(grid.voxel_size[::-1])  # x, y, z in mm
    values, vectors = np.linalg.eigh(np.cov(idx.T))
    x, y, _ = vectors[:, np.argmax(values)]
    angle = math.degrees(math.atan2(y, x))
    return angle - 180 if angle > 90 else angle + 180 if angle <= -90 else angle


def test_a_tilt_about_z_turns_the_labels_principal_axis(gl, tmp_path):
    grid = xr.VolumeGeometry((16, 48, 48), VOXEL_MM)
    angles = {}
    for tilt in (0.0, 30.0):
        loaded = load_scan_file(write(tmp_path, f"long{tilt}", box=(7.0, 1.6, 2.0),
                                      pose=f"[pose]\ntilt_deg = [0, 0, {tilt}]\n"))
        labels = xr.voxelize(loaded.sample_scene(), grid, context=gl)
        angles[tilt] = principal_angle_deg(labels.data == 1, grid)
    print(f"principal axis: {angles} degrees")
    assert abs(angles[0.0]) < 0.5
    assert abs(angles[30.0] - angles[0.0] - 30.0) < 1.0


def test_the_default_grid_covers_a_posed_sample_and_follows_its_bounds(tmp_path):
    placed = load_scan_file(write(tmp_path, "placed", box=(3.0, 2.0, 2.0), grid=""))
    posed = load_scan_file(write(tmp_path, "posed", box=(3.0, 2.0, 2.0), grid="", pose="[pose]\ntilt_deg = [0, 0, 90]\n"
                                                                   "offset_mm = [0, 1, 0]\n"))
    assert np.allclose(placed.box_mm, [[-1.0, -1.25, -1.0], [2.0, 0.75, 1.0]])
    assert np.allclose(posed.box_mm, [[-0.5, -0.75, -1.0], [1.5, 2.25, 1.0]])  # 3 × 2 mm turned to 2 × 3, moved
    assert placed.volume.shape == (10, 10, 15) and posed.volume.shape == (10, 15, 10)
    assert np.allclose(posed.volume.offset, (0.0, 0.75, 0.5))


def test_the_default_grid_of_a_tilted_weave_holds_every_labelled_voxel(gl, tmp_path):
    """Tilted 10° about x, a weave's default grid (over its posed box) holds all of its labels: a
    grid on the same lattice with 3 more voxels on every side labels the same voxels and no more."""
    text = EXAMPLE.read_text().split("[volume]")[0] + "[scan]" + EXAMPLE.read_text().split("[scan]")[1]
    path = tmp_path / "tilted.toml"
    path.write_text(text + "\n[pose]\ntilt_deg = [10.0, 0.0, 0.0]\n")
    loaded = load_scan_file(path)
    grid = loaded.volume
    lo, hi = loaded.box_mm
    thick, wide = 4.0, 10.0
    rad = math.radians(10)
    assert np.allclose(hi - lo, [wide, wide * math.cos(rad) + thick * math.sin(rad),
                                 thick * math.cos(rad) + wide * math.sin(rad)])
    assert all(n * v >= e for n, v, e in zip(grid.shape, grid.voxel_size, (hi - lo)[::-1]))
    pad = 3
    padded = xr.VolumeGeometry(tuple(n + 2 * pad for n in grid.shape), grid.voxel_size, grid.offset)
    scene = loaded.sample_scene()
    labels, around = (xr.voxelize(scene, g, context=gl).data for g in (grid, padded))
    inner = (slice(pad, -pad),) * 3
    assert np.array_equal(around[inner], labels)
    outside = around.copy()
    outside[inner] = 0
    faces = sum(int(np.count_nonzero(np.take(labels, i, axis=a))) for a in range(3) for i in (0, -1))
    print(f"default grid {grid.shape}: {np.count_nonzero(labels)} labelled voxels, {faces} of them on its faces, "
          f"{np.count_nonzero(outside)} outside it")
    assert np.count_nonzero(outside) == 0 and np.count_nonzero(labels) > 0


@pytest.mark.parametrize("pose, message", [
    ("spin = 3", r"\[pose\]: unknown key\(s\) spin"),
    ("offset_mm = [1, 2]", r"\[pose\]: offset_mm must be \[x, y, z\] in mm"),
    ("offset_mm = [1, inf, 0]", r"\[pose\]: offset_mm\[1\] must be finite"),
    ("tilt_deg = [0, nan, 0]", r"\[pose\]: tilt_deg\[1\] must be finite"),
    ('tilt_deg = [0, 0, "90"]', r"\[pose\]: tilt_deg\[2\] must be a number"),
    ("tilt_deg = [190, 0, 0]", r"\[pose\]: tilt_deg\[0\] must be within \[-180, 180\].*-170"),
])
def test_bad_poses_are_refused_naming_the_key(tmp_path, capsys, pose, message):
    path = write(tmp_path, "bad", pose=f"[pose]\n{pose}\n")
    with pytest.raises(ConfigError, match=message):
        load_scan_file(path)
    assert cli.main(["scan", str(path), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_a_pose_table_must_be_a_table(tmp_path):
    path = write(tmp_path, "flat")
    path.write_text("pose = 3\n" + path.read_text())
    with pytest.raises(ConfigError, match="pose must be a table"):
        load_scan_file(path)


def test_the_mount_stays_put(tmp_path):
    mount = '[[mount]]\nmesh = { box = [8.0, 8.0, 1.0] }\nmaterial = "aluminium"\ntranslate = [0.0, 0.0, -2.0]\n'
    loaded = load_scan_file(write(tmp_path, "mounted", grid="", pose=mount + "[pose]\noffset_mm = [0, 0, 1]\n"))
    assert np.allclose(loaded.mount.bounds, [[-4.0, -4.0, -2.5], [4.0, 4.0, -1.5]])
    assert np.allclose(loaded.box_mm[:, 2], [0.0 - 0.05, 2.05])  # the block's 2.1 mm, raised 1 mm
    scanned = loaded.with_mount(loaded.sample_scene())
    assert np.allclose(scanned.bounds, [[-4.0, -4.0, -2.5], [4.0, 4.0, 2.05]])


def test_a_posed_weave_scans_and_records_its_pose(gl, cl):
    loaded = load_scan_file(EXAMPLE)
    posed = dataclasses.replace(loaded, pose=Pose(tilt_deg=(0.0, 0.0, 45.0)))
    result = xr.scan(posed)
    assert result.metadata["pose"] == {"offset_mm": [0.0, 0.0, 0.0], "tilt_deg": [0.0, 0.0, 45.0],
                                       "pivot_mm": [0.0, 0.0, 0.0]}
    labels = result.labels.data > 0
    corner, vertex = labels[12, 1, 1], labels[12, 32, 2]  # turned 45°: no corner, a vertex on -x
    assert not corner and vertex
