"""The dataset layouts (xrayraster/dataset/layouts.py, docs/dataset_layouts.md): files where the
docs say, data and voxel size read back by independent readers (tifffile, nibabel, h5py), nnU-Net's
dataset.json fields, atomic samples (a sample whose writer fails or is killed is not finished and
leaves nothing visible; a rerun completes it), the same bytes for the same input, manifest.csv."""

from __future__ import annotations

import csv
import json
import math
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core import files
from xrayraster.dataset.layouts import GENERATOR, HDF5_CHUNK, LAYOUTS
from xrayraster.pipeline.scan import ScanResult

from builds import all_entries, visible_files

h5py = pytest.importorskip("h5py")
nib = pytest.importorskip("nibabel")
tifffile = pytest.importorskip("tifffile")

ROOT = Path(__file__).resolve().parents[2]
NAME = "Twin"
LABELS = {1: "matrix", 2: "weft", 3: "warp", 4: "tracer"}
VOXEL = (0.02, 0.025, 0.03)  # mm, z y x: all different, so a swapped axis shows
SPLITS = ("train", "val", "test")


def result(shape=(20, 70, 24), seed=0) -> ScanResult:
    """A scan-like result: layered labels 0-4 and a noisy volume following them (70 > one HDF5 chunk in y)."""
    rng = np.random.default_rng(seed)
    grid = xr.VolumeGeometry(shape, VOXEL, offset=(0.1, -0.2, 0.3))
    z, y, x = np.indices(shape)
    labels = np.where((z > 2) & (z < shape[0] - 3), 1 + (z // 3 + x // 5) % 3, 0).astype(np.uint8)
    labels[(z == shape[0] // 2) & (y < 3)] = 4
    mu = np.array([0.0, 0.35, 0.6, 0.62, 2.0], np.float32)[labels]
    volume = (mu + rng.normal(0.0, 0.05, shape)).astype(np.float32)
    metadata = {"generator": "xrayraster scan", "volume": grid.to_dict(), "seed": seed, "seconds": {"total": 2.5}}
    return ScanResult(xr.Volume(volume, grid), xr.LabelVolume(labels, grid), metadata)


def record(index: int, split: str = "train") -> dict:
    return {"split": split, "seed": 1000 + index, "values": {"weave": {"weft_per_layer": 3 + index, "crimp": 0.1 * index},
                                                              "volume.voxel_size": [0.02, 0.025, 0.03]}}


def write_three(layout: str, root: Path, **extras) -> ScanResult:
    """Samples 0, 1, 2 (train, val, test) of one result."""
    scanned = result()
    for index, split in enumerate(SPLITS):
        LAYOUTS[layout].write_sample(root, index, scanned, record(index, split), name=NAME, **extras)
    return scanned


# --- where the files go, and what finished() reads back -------------------------------------------

@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_files_where_documented_and_finished_reads_records(tmp_path, layout):
    write_three(layout, tmp_path)
    owned = sorted(p for index, split in enumerate(SPLITS) for p in LAYOUTS[layout].sample_paths(index, split, NAME))
    assert visible_files(tmp_path) == owned
    assert all_entries(tmp_path) == sorted({*owned, *(str(p) for f in owned for p in Path(f).parents if str(p) != ".")})
    done = LAYOUTS[layout].finished(tmp_path, NAME)
    assert sorted(done) == [0, 1, 2]
    assert done[1]["split"] == "val" and done[1]["seed"] == 1001 and done[1]["index"] == 1
    assert done[1]["values"] == record(1)["values"]
    assert "seconds" not in done[1]  # wall times vary between runs: never in a sample's files
    labels = result().labels.data
    assert done[1]["fractions"] == {str(k): float(np.mean(labels == k)) for k in range(5)}


def test_sample_paths():
    assert LAYOUTS["tiff"].sample_paths(7, "test", NAME) == [
        "samples/00007/volume.tif", "samples/00007/labels.tif", "samples/00007/sample.json"]
    assert LAYOUTS["nnunet"].sample_paths(7, "val", NAME) == [
        "imagesTr/Twin_00007_0000.nii.gz", "labelsTr/Twin_00007.nii.gz", "records/Twin_00007.json"]
    assert LAYOUTS["nnunet"].sample_paths(123456, "test", NAME) == [
        "imagesTs/Twin_123456_0000.nii.gz", "labelsTs/Twin_123456.nii.gz", "records/Twin_123456.json"]
    assert LAYOUTS["hdf5"].sample_paths(7, "train", NAME) == ["samples/00007.h5"]


# --- round trips by independent readers -----------------------------------------------------------

def test_tiff_round_trip(tmp_path):
    scanned = write_three("tiff", tmp_path)
    sample = tmp_path / "samples" / "00001"
    for file, expected in (("volume.tif", scanned.volume.data), ("labels.tif", scanned.labels.data)):
        with tifffile.TiffFile(sample / file) as tif:
            data = tif.asarray()
            page = tif.pages.first
            x_res = page.tags["XResolution"].value
            y_res = page.tags["YResolution"].value
            ij = tif.imagej_metadata
        assert data.dtype == expected.dtype and np.array_equal(data, expected)
        assert ij["unit"] == "mm" and math.isclose(ij["spacing"], VOXEL[0])
        assert math.isclose(x_res[1] / x_res[0], VOXEL[2], rel_tol=1e-6)
        assert math.isclose(y_res[1] / y_res[0], VOXEL[1], rel_tol=1e-6)
        assert json.loads(ij["Info"])["volume_geometry"] == scanned.volume.geometry.to_dict()
    document = json.loads((sample / "sample.json").read_text())
    assert document["generator"] == GENERATOR
    assert document["scan"] == scanned.metadata
    assert document["volume_geometry"]["voxel_size"] == list(VOXEL)
    assert document["record"]["split"] == "val"
    assert document["files"] == ["labels.tif", "sample.json", "volume.tif"]


def test_nnunet_round_trip_and_dataset_json(tmp_path):
    scanned = write_three("nnunet", tmp_path)
    for index in range(3):
        image_path, label_path, _ = (tmp_path / p for p in LAYOUTS["nnunet"].sample_paths(index, SPLITS[index], NAME))
        image, label = nib.load(image_path), nib.load(label_path)
        for img in (image, label):
            assert img.header.get_zooms() == tuple(np.float32(v) for v in VOXEL[::-1])  # x, y, z
            assert np.allclose(np.diag(img.affine)[:3], VOXEL[::-1])
            assert img.header.get_xyzt_units()[0] == "mm"
            # The affine takes voxel (0, 0, 0) to its centre in the scanner frame (x, y, z, mm).
            grid = scanned.volume.geometry
            assert np.allclose(img.affine[:3, 3], [grid.axis_centres(a)[0] for a in (2, 1, 0)], atol=1e-6)
        assert image.get_data_dtype() == np.float32 and label.get_data_dtype() == np.uint8
        assert np.array_equal(image.get_fdata().T, scanned.volume.data)
        assert np.array_equal(np.asanyarray(label.dataobj).T, scanned.labels.data)

    LAYOUTS["nnunet"].write_index(tmp_path, LAYOUTS["nnunet"].finished(tmp_path, NAME), name=NAME, labels=LABELS)
    dataset = json.loads((tmp_path / "dataset.json").read_text())
    assert dataset["channel_names"] == {"0": "CT"}
    assert dataset["labels"] == {"background": 0, "matrix": 1, "weft": 2, "warp": 3, "tracer": 4}
    assert dataset["file_ending"] == ".nii.gz"
    training = sorted(os.listdir(tmp_path / "imagesTr"))
    assert dataset["numTraining"] == len(training) == len(os.listdir(tmp_path / "labelsTr")) == 2
    assert training == ["Twin_00000_0000.nii.gz", "Twin_00001_0000.nii.gz"]
    assert os.listdir(tmp_path / "imagesTs") == ["Twin_00002_0000.nii.gz"]
    for label_file in (tmp_path / "labelsTr").iterdir():
        assert set(np.unique(np.asanyarray(nib.load(label_file).dataobj)).tolist()) <= set(dataset["labels"].values())
    assert json.loads((tmp_path / "splits_final.json").read_text()) == [{"train": ["Twin_00000"], "val": ["Twin_00001"]}]


def test_hdf5_round_trip(tmp_path):
    scanned = write_three("hdf5", tmp_path)
    with h5py.File(tmp_path / "samples" / "00001.h5", "r") as f:
        assert sorted(f) == ["label", "raw"]
        for key, expected in (("raw", scanned.volume.data), ("label", scanned.labels.data)):
            dataset = f[key]
            assert dataset.dtype == expected.dtype and np.array_equal(dataset[...], expected)
            assert dataset.chunks == (20, HDF5_CHUNK, 24)  # 64³ chunks, cut to the volume
            assert dataset.compression == "gzip" and dataset.compression_opts == 4 and dataset.shuffle
            assert np.allclose(dataset.attrs["element_size_um"], [1000 * v for v in VOXEL])
            assert np.allclose(dataset.attrs["voxel_size_mm"], VOXEL)
        assert f["raw"].attrs["unit"] == "1/cm"
        assert f.attrs["generator"] == GENERATOR
        assert json.loads(f.attrs["record"])["split"] == "val"
        assert json.loads(f.attrs["scan"]) == scanned.metadata
        assert json.loads(f.attrs["volume_geometry"]) == scanned.volume.geometry.to_dict()


# --- extras ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_projections_and_meshes_kept(tmp_path, layout):
    geometry = xr.ParallelBeamGeometry((4, 6), 0.1, xr.full_circle(3))
    projections = xr.Projections(np.ones((3, 4, 6), np.float32), geometry)

    def write_meshes(directory: Path):
        (directory / "matrix.stl").write_text("solid matrix\nendsolid matrix\n")

    write_three(layout, tmp_path, projections=projections, write_meshes=write_meshes)
    extras = {"tiff": "samples/00002", "nnunet": "extras/Twin_00002", "hdf5": "extras/00002"}[layout]
    assert np.array_equal(xr.Projections.load(tmp_path / extras / "projections.tif").data, projections.data)
    assert (tmp_path / extras / "meshes" / "matrix.stl").is_file()
    assert sorted(LAYOUTS[layout].finished(tmp_path, NAME)) == [0, 1, 2]


# --- atomic samples -------------------------------------------------------------------------------

LAST_WRITE = {"tiff": "sample.json", "nnunet": "Twin_00001.json", "hdf5": "00001.h5"}


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_failed_sample_not_finished_and_rerun_completes(tmp_path, layout, monkeypatch):
    write_three(layout, tmp_path)
    LAYOUTS[layout].write_index(tmp_path, LAYOUTS[layout].finished(tmp_path, NAME), name=NAME, labels=LABELS)
    before = visible_files(tmp_path)
    sample_files = set(LAYOUTS[layout].sample_paths(1, "val", NAME))
    for path in sample_files:
        (tmp_path / path).unlink()
    chmod = os.chmod

    def fail_last_write(path, mode):  # the sample's last file has been written, nothing renamed yet
        if Path(path).name.startswith(f".{LAST_WRITE[layout]}."):
            raise OSError(28, "No space left on device")
        chmod(path, mode)

    monkeypatch.setattr(files.os, "chmod", fail_last_write)
    with pytest.raises(OSError, match="No space"):
        LAYOUTS[layout].write_sample(tmp_path, 1, result(), record(1, "val"), name=NAME)
    monkeypatch.undo()
    assert sorted(LAYOUTS[layout].finished(tmp_path, NAME)) == [0, 2]
    assert visible_files(tmp_path) == sorted(set(before) - sample_files)
    assert not [e for e in all_entries(tmp_path) if any(part.startswith(".") for part in Path(e).parts)]

    LAYOUTS[layout].write_sample(tmp_path, 1, result(), record(1, "val"), name=NAME)
    assert sorted(LAYOUTS[layout].finished(tmp_path, NAME)) == [0, 1, 2]
    assert visible_files(tmp_path) == before


KILLED_WRITER = """
import os, signal, sys
from pathlib import Path
sys.path[:0] = [{tests!r}, os.path.dirname({tests!r})]  # this folder, and tests/ for its helpers
from test_dataset_layout import LAYOUTS, LAST_WRITE, NAME, record, result
from xrayraster.core import files
chmod = os.chmod
def kill_at_last_write(path, mode):
    if Path(path).name.startswith("." + LAST_WRITE[{layout!r}] + "."):
        os.kill(os.getpid(), signal.SIGKILL)
    chmod(path, mode)
files.os.chmod = kill_at_last_write
LAYOUTS[{layout!r}].write_sample(Path({root!r}), 1, result(), record(1, "val"), name=NAME)
"""


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_killed_writer_leaves_nothing_visible_and_rerun_cleans_up(tmp_path, layout):
    """SIGKILL with every file of the sample written, before the renames: only hidden temporaries
    remain, the sample is not finished, and the rerun removes the dead writer's temporaries."""
    code = KILLED_WRITER.format(tests=str(Path(__file__).resolve().parent), layout=layout, root=str(tmp_path))
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == -signal.SIGKILL
    assert LAYOUTS[layout].finished(tmp_path, NAME) == {}
    assert visible_files(tmp_path) == []
    assert any(part.startswith(".") for e in all_entries(tmp_path) for part in Path(e).parts)  # the temporaries

    LAYOUTS[layout].write_sample(tmp_path, 1, result(), record(1, "val"), name=NAME)
    assert sorted(LAYOUTS[layout].finished(tmp_path, NAME)) == [1]
    assert not [e for e in all_entries(tmp_path) if any(part.startswith(".") for part in Path(e).parts)]


def write_one(layout: str, root: str, index: int) -> None:
    LAYOUTS[layout].write_sample(Path(root), index, result(seed=index), record(index, SPLITS[index % 3]), name=NAME)


def test_workers_writing_at_once(tmp_path):
    """Two worker processes write the samples of every layout into one new root at the same time
    (the first two race to create the shared folders)."""
    jobs = [(layout, str(tmp_path / layout), index) for index in range(6) for layout in sorted(LAYOUTS)]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork")) as pool:
        list(pool.map(write_one, *zip(*jobs)))
    for layout in LAYOUTS:
        assert sorted(LAYOUTS[layout].finished(tmp_path / layout, NAME)) == list(range(6))
    assert not [e for e in all_entries(tmp_path) if any(part.startswith(".") for part in Path(e).parts)]


# --- the same bytes for the same input ------------------------------------------------------------

def test_identical_inputs_give_identical_bytes(tmp_path):
    """Every layout written twice, over a second apart (a time stamp in whole seconds would differ)."""
    roots = [tmp_path / "a", tmp_path / "b"]
    for root in roots:
        if root == roots[1]:
            time.sleep(1.1)
        for layout in LAYOUTS:
            write_three(layout, root / layout)
            LAYOUTS[layout].write_index(root / layout, LAYOUTS[layout].finished(root / layout, NAME), name=NAME,
                                        labels=LABELS)
    names = [visible_files(root) for root in roots]
    assert names[0] == names[1] and len(names[0]) == 9 + 9 + 3 + 3 + 2  # samples, 3 manifests, dataset.json, splits
    for name in names[0]:
        assert (roots[0] / name).read_bytes() == (roots[1] / name).read_bytes(), name


# --- manifest.csv ---------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_manifest_columns_and_rows(tmp_path, layout):
    scanned = result()
    for index in (2, 0, 1):  # written out of order: rows come sorted by index
        given = record(index, SPLITS[index])
        if index == 2:
            given["values"]["extra"] = "drawn only here"
        LAYOUTS[layout].write_sample(tmp_path, index, scanned, given, name=NAME)
    LAYOUTS[layout].write_index(tmp_path, LAYOUTS[layout].finished(tmp_path, NAME), name=NAME, labels=LABELS)
    with open(tmp_path / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
        header = next(csv.reader(open(tmp_path / "manifest.csv")))
    assert header == ["index", "split", "seed", "extra", "volume.voxel_size", "weave.crimp", "weave.weft_per_layer",
                      "fraction.background", "fraction.matrix", "fraction.weft", "fraction.warp", "fraction.tracer"]
    assert [r["index"] for r in rows] == ["0", "1", "2"]
    assert [r["split"] for r in rows] == list(SPLITS)
    assert rows[1]["seed"] == "1001" and rows[1]["weave.weft_per_layer"] == "4"
    assert float(rows[1]["weave.crimp"]) == 0.1
    assert json.loads(rows[1]["volume.voxel_size"]) == [0.02, 0.025, 0.03]
    assert rows[0]["extra"] == "" and rows[2]["extra"] == "drawn only here"
    assert float(rows[1]["fraction.tracer"]) == float(np.mean(scanned.labels.data == 4))
    assert math.isclose(sum(float(rows[1][f"fraction.{n}"]) for n in ("background", *LABELS.values())), 1.0)


# --- refusals -------------------------------------------------------------------------------------

def test_refusals(tmp_path, monkeypatch):
    scanned = result()
    with pytest.raises(xr.ConfigError, match="split must be one of train, val, test"):
        LAYOUTS["tiff"].write_sample(tmp_path, 0, scanned, {"split": "training", "seed": 1, "values": {}}, name=NAME)
    with pytest.raises(xr.ConfigError, match="dataset name"):
        LAYOUTS["nnunet"].write_sample(tmp_path, 0, scanned, record(0), name="my data.v1")
    wide = ScanResult(scanned.volume, xr.LabelVolume(scanned.labels.data.astype(np.uint16) * 100, scanned.volume.geometry),
                      scanned.metadata)
    for layout in ("nnunet", "hdf5"):
        with pytest.raises(xr.ConfigError, match="labels above 255"):
            LAYOUTS[layout].write_sample(tmp_path, 0, wide, record(0), name=NAME)
    LAYOUTS["nnunet"].write_sample(tmp_path, 0, scanned, record(0), name=NAME)
    done = LAYOUTS["nnunet"].finished(tmp_path, NAME)
    with pytest.raises(xr.ConfigError, match="sample 0 has label 4, which the build's labels do not name"):
        LAYOUTS["nnunet"].write_index(tmp_path, done, name=NAME, labels={1: "matrix", 2: "weft", 3: "warp"})
    with pytest.raises(xr.ConfigError, match="consecutive labels"):
        LAYOUTS["nnunet"].write_index(tmp_path, done, name=NAME, labels={**LABELS, 6: "tracer_b"})
    assert not (tmp_path / "dataset.json").exists() and not (tmp_path / "manifest.csv").exists()
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(xr.ConfigError, match=r'pip install "xrayraster\[dataset\]"'):
        LAYOUTS["hdf5"].write_sample(tmp_path, 0, scanned, record(0), name=NAME)


def test_foreign_entry_in_a_tiff_sample_is_kept(tmp_path):
    """A tiff sample directory holding a user's file is refused, never emptied (docs/outputs.md)."""
    write_three("tiff", tmp_path)
    note = tmp_path / "samples" / "00001" / "notes.txt"
    note.write_text("mine")
    with pytest.raises(xr.ConfigError, match="notes.txt"):
        LAYOUTS["tiff"].write_sample(tmp_path, 1, result(), record(1, "val"), name=NAME)
    assert note.read_text() == "mine"


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_read_sample_gives_back_what_was_written(tmp_path, layout):
    scanned = write_three(layout, tmp_path)
    for index, split in enumerate(SPLITS):
        volume, labels = LAYOUTS[layout].read_sample(tmp_path, index, split, NAME)
        assert volume.dtype == np.float32 and labels.dtype == np.uint8
        assert np.array_equal(volume, scanned.volume.data) and np.array_equal(labels, scanned.labels.data)


@pytest.mark.parametrize("layout", ["nnunet", "hdf5"])
def test_files_of_an_unfinished_sample_are_removed_and_nothing_else(tmp_path, layout):
    """A kill between an nnU-Net sample's renames leaves its image and labels without a record, and
    one after a sample's extras leaves them without the sample: remove_unfinished takes those away,
    and only those, so a stopped build shows no partial sample."""
    write_three(layout, tmp_path)
    (tmp_path / "notes.txt").write_text("not a sample's")
    before = visible_files(tmp_path)
    stray = LAYOUTS[layout].sample_paths(7, "train", NAME)[:-1]  # all but the last file renamed in
    stray.append(f"extras/{NAME}_00007/mesh.stl" if layout == "nnunet" else "extras/00007/mesh.stl")
    for path in stray:
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_bytes(b"written before the kill")
    assert len(LAYOUTS[layout].remove_unfinished(tmp_path, NAME)) == len(stray)
    assert visible_files(tmp_path) == before
