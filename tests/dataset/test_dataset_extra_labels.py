"""The extra labels a dataset file's scans ask for (`[scan] labels`: instances, directions, centre
lines) in every dataset layout (docs/dataset_layouts.md): each file where the docs say, read back by
the format's own library (tifffile, nibabel, h5py) as what was written, and in a real build as what
`xr.scan` of the same drawn scan file returns; the instance table as the scan's metadata names it,
named by the manifest; a sample killed at any rename leaves no extra file visible once its layout
has swept, a killed build resumes to the bytes of an uninterrupted one, and so does a build of 2
and then 4 samples; the same input gives the same bytes."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core import files
from xrayraster.core.choices import LABEL_EXTRAS
from xrayraster.dataset import build as dataset_module
from xrayraster.dataset import draw, load_dataset_file
from xrayraster.dataset.layouts import HDF5_CHUNK, LAYOUTS
from xrayraster.dataset.plan import sample_bytes

from builds import NAME, all_entries, fake_scan, scan_result, visible_files
from inputs import tiny

h5py = pytest.importorskip("h5py")
nib = pytest.importorskip("nibabel")
tifffile = pytest.importorskip("tifffile")

ROOT = Path(__file__).resolve().parents[2]
EXTRAS = '"scan.labels" = ["classes", "instances", "directions", "centrelines"]\n'
SPLITS = ("train", "val", "test")
VOXEL = (0.02, 0.025, 0.03)  # mm, z y x: all different, so a swapped axis shows
GRID = xr.VolumeGeometry((20, 70, 24), VOXEL, offset=(0.1, -0.2, 0.3))  # 70 > one HDF5 chunk in y


def result(index: int = 0, extra_labels=LABEL_EXTRAS):
    return scan_result(GRID, index, extra_labels)


def record(index: int, split: str) -> dict:
    return {"split": split, "seed": 1000 + index, "values": {"weave.crimp": 0.1 * index}}


def write_three(layout: str, root: Path):
    """Samples 0, 1, 2 (train, val, test) with every extra label."""
    for index, split in enumerate(SPLITS):
        LAYOUTS[layout].write_sample(root, index, result(index), record(index, split), name=NAME)
    return result(2)


def hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def hidden(root: Path) -> list[str]:
    return [e for e in all_entries(root) if any(part.startswith(".") for part in Path(e).parts)]


# -- where the files go ----------------------------------------------------------------------------

def test_the_extra_files_are_where_the_docs_say():
    assert LAYOUTS["tiff"].sample_paths(7, "test", NAME, LABEL_EXTRAS) == [
        "samples/00007/volume.tif", "samples/00007/labels.tif", "samples/00007/sample.json",
        "samples/00007/instances.tif", "samples/00007/directions.tif", "samples/00007/centrelines.json",
        "samples/00007/instances.json"]
    assert LAYOUTS["nnunet"].sample_paths(7, "test", NAME, LABEL_EXTRAS) == [
        "imagesTs/Twin_00007_0000.nii.gz", "labelsTs/Twin_00007.nii.gz", "records/Twin_00007.json",
        "instancesTs/Twin_00007.nii.gz", "directionsTs/Twin_00007.nii.gz", "centrelinesTs/Twin_00007.json",
        "extras/Twin_00007/instances.json"]
    assert LAYOUTS["nnunet"].sample_paths(7, "val", NAME, ("directions",)) == [
        "imagesTr/Twin_00007_0000.nii.gz", "labelsTr/Twin_00007.nii.gz", "records/Twin_00007.json",
        "directionsTr/Twin_00007.nii.gz"]
    assert LAYOUTS["hdf5"].sample_paths(7, "train", NAME, LABEL_EXTRAS) == [
        "samples/00007.h5", "extras/00007/instances.json"]


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_every_file_belongs_to_a_sample_and_the_records_list_the_extra_labels(tmp_path, layout):
    write_three(layout, tmp_path)
    layouts = LAYOUTS[layout]
    owned = {p for index, split in enumerate(SPLITS) for p in layouts.sample_paths(index, split, NAME, LABEL_EXTRAS)}
    # and the marker of each sample's folder (extras.json where the sample itself is no folder)
    markers = {f"{folder}/{marker}" for index in range(3) for folder, marker in layouts.sample_folders(index, NAME)}
    assert visible_files(tmp_path) == sorted(owned | markers)
    done = LAYOUTS[layout].finished(tmp_path, NAME)
    assert sorted(done) == [0, 1, 2] and all(r["extra_labels"] == list(LABEL_EXTRAS) for r in done.values())


# -- read back by independent readers ---------------------------------------------------------------

def test_tiff_extras_read_back(tmp_path):
    scanned = write_three("tiff", tmp_path)
    folder = tmp_path / "samples" / "00002"
    with tifffile.TiffFile(folder / "instances.tif") as tif:
        ids, ij = tif.asarray(), tif.imagej_metadata
    assert ids.dtype == np.uint16 and np.array_equal(ids, scanned.instances.data)
    assert np.isclose(ij["spacing"], VOXEL[0]) and ij["unit"] == "mm"
    directions = tifffile.imread(folder / "directions.tif")
    assert directions.dtype == np.float16 and np.array_equal(directions, scanned.directions)
    assert json.loads((folder / "centrelines.json").read_text()) == scanned.centrelines
    assert json.loads((folder / "instances.json").read_text()) == scanned.metadata["instances"]


def test_nnunet_extras_read_back_beside_what_nnunet_reads(tmp_path):
    scanned = write_three("nnunet", tmp_path)
    labels = nib.load(tmp_path / "labelsTs" / "Twin_00002.nii.gz")
    ids = nib.load(tmp_path / "instancesTs" / "Twin_00002.nii.gz")
    directions = nib.load(tmp_path / "directionsTs" / "Twin_00002.nii.gz")
    assert ids.get_data_dtype() == np.uint16 and np.array_equal(np.asanyarray(ids.dataobj).T, scanned.instances.data)
    assert directions.get_data_dtype() == np.float32 and directions.shape == (*labels.shape, 3)  # x, y, z, component
    assert np.array_equal(directions.get_fdata().T, scanned.directions.astype(np.float32))
    for image in (ids, directions):
        assert np.array_equal(image.affine, labels.affine) and image.header.get_zooms()[:3] == labels.header.get_zooms()
    assert json.loads((tmp_path / "centrelinesTs" / "Twin_00002.json").read_text()) == scanned.centrelines
    table = json.loads((tmp_path / "extras" / "Twin_00002" / "instances.json").read_text())
    assert table == scanned.metadata["instances"]
    # What nnU-Net plans is as without the extra labels: the same images, labels, dataset.json and split.
    plain = tmp_path / "plain"
    for index, split in enumerate(SPLITS):
        LAYOUTS["nnunet"].write_sample(plain, index, result(index, ()), record(index, split), name=NAME)
    for root in (tmp_path, plain):
        LAYOUTS["nnunet"].write_index(root, LAYOUTS["nnunet"].finished(root, NAME), name=NAME,
                                      labels={1: "matrix", 2: "weft", 3: "warp"})
    for path in ("dataset.json", "splits_final.json", "imagesTr/Twin_00000_0000.nii.gz", "labelsTr/Twin_00001.nii.gz",
                 "imagesTs/Twin_00002_0000.nii.gz", "labelsTs/Twin_00002.nii.gz"):
        assert (tmp_path / path).read_bytes() == (plain / path).read_bytes(), path
    assert sorted(os.listdir(tmp_path / "imagesTr")) == ["Twin_00000_0000.nii.gz", "Twin_00001_0000.nii.gz"]


def test_hdf5_extras_read_back_chunked_as_the_volume(tmp_path):
    scanned = write_three("hdf5", tmp_path)
    with h5py.File(tmp_path / "samples" / "00002.h5", "r") as f:
        assert sorted(f) == ["centrelines", "directions", "instances", "label", "raw"]
        ids, directions = f["instances"], f["directions"]
        assert ids.dtype == np.uint16 and np.array_equal(ids[...], scanned.instances.data)
        assert directions.dtype == np.float16 and np.array_equal(directions[...], scanned.directions)
        assert ids.chunks == (20, HDF5_CHUNK, 24) and directions.chunks == (3, 20, HDF5_CHUNK, 24)
        for dataset in (ids, directions):
            assert (dataset.compression, dataset.compression_opts, dataset.shuffle) == ("gzip", 4, True)
            assert np.allclose(dataset.attrs["voxel_size_mm"], VOXEL)
        assert json.loads(f["centrelines"][()]) == scanned.centrelines
        assert json.loads(f.attrs["scan"])["instances"] == scanned.metadata["instances"]
    assert json.loads((tmp_path / "extras" / "00002" / "instances.json").read_text()) == scanned.metadata["instances"]


def test_the_disk_check_counts_the_extra_labels(tmp_path):
    """2 bytes a voxel for the uint16 ids and 6 for the float16 directions, on top of the volume's 4
    and the labels' 1 (centre lines: a few kB, not counted)."""
    plain = draw(load_dataset_file(tiny(tmp_path, count=1)), 0).scan
    path = tiny(tmp_path, count=1)
    path.write_text(path.read_text() + EXTRAS)
    extra = draw(load_dataset_file(path), 0).scan
    assert sample_bytes(plain) == 16 * 32 * 32 * 5 and sample_bytes(extra) == 16 * 32 * 32 * (5 + 2 + 6)


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_the_manifest_names_each_samples_instance_table(tmp_path, layout):
    scanned = write_three(layout, tmp_path)
    LAYOUTS[layout].write_sample(tmp_path, 3, result(3, ()), record(3, "train"), name=NAME)  # without extras
    LAYOUTS[layout].write_index(tmp_path, LAYOUTS[layout].finished(tmp_path, NAME), name=NAME,
                                labels={1: "matrix", 2: "weft", 3: "warp", 4: "tracer"})
    rows = list(csv.DictReader(open(tmp_path / "manifest.csv")))
    assert rows[3]["instance_table"] == ""
    for row in rows[:3]:
        assert json.loads((tmp_path / row["instance_table"]).read_text()) == scanned.metadata["instances"]


def test_the_same_input_gives_the_same_bytes(tmp_path):
    """Every layout with every extra, written twice over a second apart."""
    roots = [tmp_path / "a", tmp_path / "b"]
    for root in roots:
        if root == roots[1]:
            time.sleep(1.1)
        for layout in LAYOUTS:
            write_three(layout, root / layout)
    assert hashes(roots[0]) == hashes(roots[1]) and len(hashes(roots[0])) == 3 * (7 + 8 + 3)


# -- atomic samples ---------------------------------------------------------------------------------

def killed_at_rename(layout: str, root: Path, rename: int) -> bool:
    """Write sample 1 in a forked process that is SIGKILLed just before its ``rename``-th rename
    (counting from 1); False when the write made fewer renames and finished."""
    pid = os.fork()
    if pid == 0:  # the child: nothing of pytest's runs here, it ends by the kill or os._exit
        renames, replace = [0], os.replace

        def kill_at(src, dst):
            renames[0] += 1
            if renames[0] == rename:
                os.kill(os.getpid(), signal.SIGKILL)
            replace(src, dst)

        files.os.replace = kill_at
        try:
            LAYOUTS[layout].write_sample(root, 1, result(1), record(1, "test"), name=NAME)
        except BaseException:
            os._exit(1)
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) or os.WEXITSTATUS(status) == 0, "the write failed"
    return os.WIFSIGNALED(status)


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_a_sample_killed_at_any_rename_leaves_no_extra_file_once_swept(tmp_path, layout):
    """A kill before each of the sample's renames in turn (its files, its folders, its marker): the
    sample is never finished, remove_unfinished (what a resumed build runs) leaves nothing of it
    visible, and the rewrite completes it with no temporary left."""
    rename = 1
    while killed_at_rename(layout, tmp_path / str(rename), rename):
        root = tmp_path / str(rename)
        assert LAYOUTS[layout].finished(root, NAME) == {}, rename
        LAYOUTS[layout].remove_unfinished(root, NAME)
        assert visible_files(root) == [], (rename, visible_files(root))
        LAYOUTS[layout].write_sample(root, 1, result(1), record(1, "test"), name=NAME)
        assert sorted(LAYOUTS[layout].finished(root, NAME)) == [1] and not hidden(root)
        rename += 1
    assert rename > 4, "the write made too few renames for the kills to test anything"


# -- builds -----------------------------------------------------------------------------------------

KILLED_BUILD = """
import os, signal, sys
from pathlib import Path
sys.path.insert(0, {tests!r})
import xrayraster as xr
from xrayraster.core import files
from xrayraster.dataset import build
from builds import fake_scan
build.scan = fake_scan
replace = os.replace
def kill_at(src, dst):
    if Path(dst).parent.name == "records" and Path(dst).name == "Twin_00001.json":
        os.kill(os.getpid(), signal.SIGKILL)  # sample 1's images and extras are in place, its record is not
    replace(src, dst)
files.os.replace = kill_at
xr.build({path!r}, {out!r})
"""


def test_a_killed_build_resumes_to_the_bytes_of_an_uninterrupted_one(gl, cl, tmp_path, monkeypatch):
    """nnU-Net's layout, killed between sample 1's renames (its images and extra labels in place, its
    record not: the layout's known gap): nothing lists it, and the resumed build sweeps its files and
    gives the bytes of an uninterrupted build."""
    path = tiny(tmp_path, count=3, layout="nnunet", extra='name = "Twin"')
    path.write_text(path.read_text() + EXTRAS)
    code = KILLED_BUILD.format(tests=str(ROOT / "tests"), path=str(path), out=str(tmp_path / "out"))
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == -signal.SIGKILL, run.stderr
    out = tmp_path / "out"
    assert list(out.glob("instancesT?/Twin_00001.nii.gz"))  # the gap: visible, not finished
    assert sorted(LAYOUTS["nnunet"].finished(out, "Twin")) == [0]
    monkeypatch.setattr(dataset_module, "scan", fake_scan)
    assert xr.build(path, out).built == (1, 2)
    assert xr.build(path, tmp_path / "whole").built == (0, 1, 2)
    assert hashes(out) == hashes(tmp_path / "whole")
    # --force with a dataset file without extra labels removes the earlier build's, folders and all.
    (tmp_path / "plain").mkdir()
    plain = tiny(tmp_path / "plain", count=1, layout="nnunet", extra='name = "Twin"')
    assert xr.build(plain, out, force=True).built == (0,)
    assert not [p.name for p in out.iterdir() if p.name.startswith((*LABEL_EXTRAS, "extras"))]


@pytest.fixture(scope="module")
def real(gl, cl, tmp_path_factory):
    """Two tiny real samples with every extra label, built in each layout, and xr.scan of their draws."""
    folder = tmp_path_factory.mktemp("extras")
    builds = {}
    for layout in sorted(LAYOUTS):
        (folder / layout).mkdir()
        path = tiny(folder / layout, count=2, layout=layout, extra='name = "Twin"')
        path.write_text(path.read_text() + EXTRAS)
        xr.build(path, folder / layout / "out")
        builds[layout] = folder / layout / "out"
    dataset = load_dataset_file(path)
    scans = [xr.scan(draw(dataset, index).scan, gl=gl, cl=cl) for index in range(2)]
    return builds, scans, [draw(dataset, index).split for index in range(2)]


def stored_extras(root: Path, layout: str, index: int, split: str) -> tuple:
    """(instances, directions (3, z, y, x), centre lines, instance table) of a built sample, read
    from the documented files by their formats' own libraries."""
    case, part = f"Twin_{index:05d}", "Tr" if split != "test" else "Ts"
    if layout == "tiff":
        folder = root / "samples" / f"{index:05d}"
        return (tifffile.imread(folder / "instances.tif"), tifffile.imread(folder / "directions.tif"),
                json.loads((folder / "centrelines.json").read_text()),
                json.loads((folder / "instances.json").read_text()))
    if layout == "nnunet":
        return (np.asanyarray(nib.load(root / f"instances{part}" / f"{case}.nii.gz").dataobj).T,
                np.asanyarray(nib.load(root / f"directions{part}" / f"{case}.nii.gz").dataobj).T,
                json.loads((root / f"centrelines{part}" / f"{case}.json").read_text()),
                json.loads((root / "extras" / case / "instances.json").read_text()))
    with h5py.File(root / "samples" / f"{index:05d}.h5", "r") as f:
        return (f["instances"][()], f["directions"][()], json.loads(f["centrelines"][()]),
                json.loads((root / "extras" / f"{index:05d}" / "instances.json").read_text()))


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_a_builds_extra_labels_are_what_xr_scan_of_the_draw_returns(real, layout):
    builds, scans, splits = real
    for index, (scanned, split) in enumerate(zip(scans, splits)):
        ids, directions, lines, table = stored_extras(builds[layout], layout, index, split)
        assert ids.dtype == np.uint16 and np.array_equal(ids, scanned.instances.data)
        assert np.array_equal(directions, scanned.directions)  # float16, or float32 holding the same values
        assert lines == scanned.centrelines and table == scanned.metadata["instances"]
        assert set(np.unique(ids).tolist()) - {0} <= set(map(int, table)) and len(table) > 4
        stored_scan = LAYOUTS[layout].scan_metadata(builds[layout], index, split, "Twin")
        assert stored_scan["instances"] == table


def test_a_real_builds_direction_patches_are_unit_on_the_yarns(real):
    """xr.ml's direction patches of a real build, flipped at random: unit vectors on every voxel the
    classes call weft or warp, 0 on the matrix and the air."""
    builds, _, _ = real
    options = {"split": None, "patches_per_sample": 6, "flips": True, "seed": 4}
    directions = xr.ml.PatchDataset(builds["hdf5"], (8, 16, 16), target="directions", **options)
    classes = xr.ml.PatchDataset(builds["hdf5"], (8, 16, 16), **options)
    for item in range(len(directions)):
        vectors, labels = directions[item][1], classes[item][1]
        norm = np.linalg.norm(vectors, axis=0)
        assert vectors.dtype == np.float32 and vectors.shape == (3, 8, 16, 16)
        assert np.allclose(norm[labels >= 2], 1.0, atol=2e-3) and not vectors[:, labels < 2].any()


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_two_and_then_four_samples_are_the_bytes_of_four(gl, cl, tmp_path, layout):
    def dataset(count: int) -> Path:  # one file (a sample's metadata names it), its count grown
        path = tiny(tmp_path, count=count, layout=layout, extra='name = "Twin"')
        path.write_text(path.read_text() + EXTRAS)
        return path

    assert xr.build(dataset(2), tmp_path / "resumed").built == (0, 1)
    assert xr.build(dataset(4), tmp_path / "resumed").built == (2, 3)
    assert xr.build(dataset(4), tmp_path / "whole").built == (0, 1, 2, 3)
    assert hashes(tmp_path / "resumed") == hashes(tmp_path / "whole")
