"""Dataset builds (docs/dataset.md): every sample is the scan of its draw, a build resumes after
any kill with the same bytes as an uninterrupted one, with one worker or two, a changed dataset
file is refused, a failing sample is retried once and then recorded."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tifffile

import xrayraster as xr
from xrayraster import cli
from xrayraster.dataset import draw, load_dataset_file

from inputs import tiny

ROOT = Path(__file__).resolve().parents[2]

def hashes(root: Path) -> dict[str, str]:
    """sha256 of every file under ``root``, by relative path (hidden temporaries would show too)."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def child_env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


@pytest.fixture(scope="module")
def reference(gl, cl, tmp_path_factory):
    """An uninterrupted build of 4 tiny samples, one worker, in this process."""
    folder = tmp_path_factory.mktemp("reference")
    report = xr.build(tiny(folder), folder / "out")
    return folder / "out", report


def test_label_0_has_one_name_in_a_build_and_its_readers(reference):
    """nnU-Net v2 requires label 0 to be called "background" in dataset.json; the scan's record,
    the manifest's fraction column and xr.ml use the same name."""
    out, _ = reference
    sample = json.loads((out / "samples" / "00000" / "sample.json").read_text())
    assert sample["scan"]["labels"]["0"] == "background"
    assert "fraction.background" in next(csv.reader(open(out / "manifest.csv")))
    assert xr.ml.PatchDataset(out, (8, 8, 8), split=None).dataset.labels[0] == "background"

def test_every_sample_is_the_scan_of_its_draw(reference):
    out, report = reference
    assert report.built == (0, 1, 2, 3) and report.skipped == 0 and not report.failed
    dataset = load_dataset_file(out.parent / "tiny.toml")
    rows = list(csv.DictReader(open(out / "manifest.csv")))
    assert [int(r["index"]) for r in rows] == [0, 1, 2, 3]
    for index in range(4):
        drawn = draw(dataset, index)
        sample = json.loads((out / "samples" / f"{index:05d}" / "sample.json").read_text())
        assert sample["record"]["values"] == drawn.values and sample["record"]["split"] == drawn.split
        assert sample["scan"]["source"] == drawn.scan.spectrum.description  # the drawn kV was scanned
        assert not {"seconds", "peak_rss_mib", "devices"} & set(sample["scan"])
        volume = tifffile.imread(out / "samples" / f"{index:05d}" / "volume.tif")
        labels = tifffile.imread(out / "samples" / f"{index:05d}" / "labels.tif")
        assert volume.shape == labels.shape == (16, 32, 32) and volume.dtype == np.float32
        assert set(np.unique(labels)) == {0, 1, 2, 3}
        # The manifest's class fractions are the label volume's.
        for value, name in {0: "background", 1: "matrix", 2: "weft", 3: "warp"}.items():
            assert float(rows[index][f"fraction.{name}"]) == pytest.approx(np.mean(labels == value), abs=1e-12)
        assert float(rows[index]["source.kvp"]) == drawn.values["source.kvp"]
        # Sample by sample, the reconstruction is μ where the labels say matrix or yarn (cm⁻¹ of carbon
        # composites at 40 kV: between 0.2 and 1.5), air near 0.
        inside = volume[labels > 0].mean()
        assert 0.2 < inside < 1.5 and abs(np.median(volume[labels == 0])) < 0.1 * inside


def test_a_rerun_skips_finished_samples_and_count_may_grow(reference, tmp_path):
    out, _ = reference
    copy = tmp_path / "out"
    subprocess.run(["cp", "-a", str(out), str(copy)], check=True)
    before = hashes(copy)
    again = xr.build(tiny(out.parent), copy)
    assert again.built == () and again.skipped == 4 and hashes(copy) == before
    grown = xr.build(tiny(tmp_path, count=6), copy)
    assert grown.built == (4, 5) and grown.skipped == 4
    after = hashes(copy)
    assert all(after[name] == digest for name, digest in before.items()
               if name not in ("manifest.csv", "build.json", "gallery.png"))  # the first samples stay as they were
    assert len(list(csv.DictReader(open(copy / "manifest.csv")))) == 6


def test_a_changed_dataset_file_is_refused_naming_the_change(reference, tmp_path, capsys):
    out, _ = reference
    copy = tmp_path / "out"
    subprocess.run(["cp", "-a", str(out), str(copy)], check=True)
    changed = tiny(tmp_path)
    changed.write_text(changed.read_text().replace("seed = 7", "seed = 8"))
    before = hashes(copy)
    assert cli.main(["build", str(changed), "-o", str(copy), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "seed: 7 -> 8" in err and "--force" in err
    assert hashes(copy) == before
    fewer = tiny(tmp_path, count=2)
    assert cli.main(["build", str(fewer), "-o", str(copy), "--quiet"]) == 2
    assert "count: 4 -> 2" in capsys.readouterr().err


def test_force_rebuilds_a_changed_dataset_and_keeps_foreign_files(gl, cl, reference, tmp_path):
    out, _ = reference
    copy = tmp_path / "out"
    subprocess.run(["cp", "-a", str(out), str(copy)], check=True)
    (copy / "samples" / "notes.txt").write_text("mine")
    changed = tiny(tmp_path, count=2)
    changed.write_text(changed.read_text().replace("seed = 7", "seed = 8"))
    report = xr.build(changed, copy, force=True)
    assert report.built == (0, 1)
    assert sorted(p.name for p in (copy / "samples").iterdir()) == ["00000", "00001", "notes.txt"]
    assert json.loads((copy / "build.json").read_text())["identity"]["seed"] == 8


def test_a_foreign_directory_or_a_file_name_is_refused(tmp_path, capsys):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    assert cli.main(["build", str(tiny(tmp_path)), "-o", str(tmp_path / "mine"), "--quiet"]) == 2
    assert "did not write" in capsys.readouterr().err
    assert cli.main(["build", str(tiny(tmp_path)), "-o", str(tmp_path / "set.h5"), "--quiet"]) == 2
    assert "ends in .h5" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "tiny.toml"]
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "precious"


def test_a_sample_that_fails_twice_is_recorded_and_the_exit_status_says_so(gl, cl, tmp_path, monkeypatch, capsys):
    from xrayraster.dataset import build as dataset

    real = dataset.build_sample
    calls = []

    def flaky(data, root, index, threads=None, contexts=None):
        calls.append(index)
        if index == 1:
            raise RuntimeError("the GPU fell off the bus")
        return real(data, root, index, threads, contexts)

    monkeypatch.setattr(dataset, "build_sample", flaky)
    assert cli.main(["build", str(tiny(tmp_path, count=3)), "-o", str(tmp_path / "out"), "--quiet"]) == 1
    assert calls.count(1) == 2  # retried once
    assert "failed.csv" in capsys.readouterr().err
    failed = list(csv.DictReader(open(tmp_path / "out" / "failed.csv")))
    assert [row["index"] for row in failed] == ["1"] and "fell off the bus" in failed[0]["error"]
    assert json.loads(failed[0]["values"]) == draw(load_dataset_file(tmp_path / "tiny.toml"), 1).values
    assert sorted(p.name for p in (tmp_path / "out" / "samples").iterdir()) == ["00000", "00002"]
    monkeypatch.setattr(dataset, "build_sample", real)  # fixed: the rerun builds it and drops failed.csv
    assert cli.main(["build", str(tmp_path / "tiny.toml"), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    assert not (tmp_path / "out" / "failed.csv").exists()


def test_two_workers_give_the_same_bytes(reference, tmp_path):
    out, _ = reference
    run = subprocess.run([sys.executable, "-m", "xrayraster", "build", str(out.parent / "tiny.toml"), "-o",
                          str(tmp_path / "two"), "--workers", "2", "--quiet"], env=child_env(), capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert hashes(tmp_path / "two") == hashes(out)


def test_killed_at_random_moments_and_rerun_the_build_equals_an_uninterrupted_one(reference, tmp_path):
    """SIGKILL the build three times at random moments, then let it finish: no partial sample is
    ever visible, and the end result is the reference build, file for file, byte for byte."""
    out, _ = reference
    rng = np.random.default_rng(2026)
    command = [sys.executable, "-m", "xrayraster", "build", str(out.parent / "tiny.toml"), "-o",
               str(tmp_path / "out"), "--quiet"]
    finished_after_kills = []
    for delay in rng.uniform(1.0, 4.0, size=3):
        proc = subprocess.Popen(command, env=child_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        samples = tmp_path / "out" / "samples"
        visible = [s for s in samples.iterdir() if not s.name.startswith(".")] if samples.exists() else []
        assert all((sample / "sample.json").exists() for sample in visible), "a partial sample is visible"
        finished_after_kills.append(len(visible))
    assert min(finished_after_kills) < 4, "every kill came after the build had finished: it tested nothing"
    finish = subprocess.run(command, env=child_env(), capture_output=True, text=True, timeout=300)
    assert finish.returncode == 0, finish.stderr
    assert hashes(tmp_path / "out") == hashes(out)


def test_ctrl_c_stops_cleanly_and_the_rerun_completes(reference, tmp_path):
    out, _ = reference
    command = [sys.executable, "-m", "xrayraster", "build", str(out.parent / "tiny.toml"), "-o",
               str(tmp_path / "out"), "--quiet", "--workers", "2"]
    proc = subprocess.Popen(command, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # Mid-build: as soon as the first sample is in place (a fixed sleep let a fast machine finish first).
    samples, deadline = tmp_path / "out" / "samples", time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and not (
            samples.is_dir() and any(not s.name.startswith(".") for s in samples.iterdir())):
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.count("\n") == 1 and "Traceback" not in err, (proc.returncode, err)
    hidden = [p for p in (tmp_path / "out").rglob(".*")]
    assert hidden == [], f"temporaries left: {hidden}"
    assert subprocess.run(command, env=child_env(), capture_output=True, timeout=300).returncode == 0
    assert hashes(tmp_path / "out") == hashes(out)


def test_a_local_dask_cluster_gives_the_same_bytes(reference, tmp_path):
    pytest.importorskip("distributed", reason="the dask extra (pip install \"xrayraster[dask]\")")
    out, _ = reference
    run = subprocess.run([sys.executable, "-m", "xrayraster", "build", str(out.parent / "tiny.toml"), "-o",
                          str(tmp_path / "dask"), "--dask", "--workers", "2", "--quiet"], env=child_env(),
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert hashes(tmp_path / "dask") == hashes(out)


def test_a_scheduler_and_two_workers_started_apart_give_the_same_bytes(reference, tmp_path):
    """A cluster as a user starts one on several machines (docs/dataset.md), here on 127.0.0.1:
    a scheduler and two workers in their own processes, joined with --scheduler."""
    pytest.importorskip("distributed", reason="the dask extra (pip install \"xrayraster[dask]\")")
    out, _ = reference
    env, file = child_env(), tmp_path / "scheduler.json"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    started = [subprocess.Popen([*dask, "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                 "--scheduler-file", str(file)], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            started.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "1", "--nthreads", "1",
                 "--no-dashboard", "--host", "127.0.0.1"], env=env, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL))
        run = subprocess.run([sys.executable, "-m", "xrayraster", "build", str(out.parent / "tiny.toml"), "-o",
                              str(tmp_path / "cluster"), "--scheduler", address, "--quiet"], env=env,
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        assert hashes(tmp_path / "cluster") == hashes(out)
    finally:
        for proc in reversed(started):
            proc.terminate()
        for proc in started:
            proc.wait(timeout=30)


SOAK = """
import json, os, sys
from pathlib import Path
from xrayraster.dataset import load_dataset_file
from xrayraster.dataset.build import build_sample

dataset = load_dataset_file(sys.argv[1])
rss = []
for index in range(dataset.count):
    build_sample(dataset, sys.argv[2], index)
    with open("/proc/self/statm") as f:
        rss.append(int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE"))
print(json.dumps(rss))
"""


def test_a_hundred_samples_in_one_worker_keep_its_memory_steady(gl, cl, tmp_path):
    """Resident memory after the 10th of 100 samples is within 10 % of that after the 100th (the
    worker keeps its contexts, hands its heap's free memory back after each sample; nothing grows
    with the samples it made)."""
    path = tiny(tmp_path, count=100)
    path.write_text(path.read_text().replace('"geometry.num_views" = 20', '"geometry.num_views" = 8'))
    run = subprocess.run([sys.executable, "-c", SOAK, str(path), str(tmp_path / "out")], env=child_env(),
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    rss = json.loads(run.stdout.splitlines()[-1])
    print(f"resident memory after samples 10, 50, 100: {rss[9] / 2**20:.0f}, {rss[49] / 2**20:.0f}, "
          f"{rss[99] / 2**20:.0f} MiB")
    assert abs(rss[99] - rss[9]) <= 0.10 * rss[99]


def test_an_nnunet_build_loads_with_nibabel_at_its_voxel_size(gl, cl, tmp_path):
    nib = pytest.importorskip("nibabel", reason="the dataset extra (pip install \"xrayraster[dataset]\")")
    report = xr.build(tiny(tmp_path, count=3, layout="nnunet"), tmp_path / "out")
    assert report.built == (0, 1, 2)
    meta = json.loads((tmp_path / "out" / "dataset.json").read_text())
    assert meta["channel_names"] == {"0": "CT"} and meta["file_ending"] == ".nii.gz"
    assert meta["labels"] == {"background": 0, "matrix": 1, "weft": 2, "warp": 3}
    images = sorted((tmp_path / "out").glob("images*/*_0000.nii.gz"))
    assert len(images) == 3 and meta["numTraining"] == len(list((tmp_path / "out").glob("imagesTr/*.nii.gz")))
    for image in images:
        case = image.name.removesuffix("_0000.nii.gz")
        label = image.parent.parent / image.parent.name.replace("images", "labels") / f"{case}.nii.gz"
        img, lab = nib.load(image), nib.load(label)
        assert img.header.get_zooms() == pytest.approx((0.46, 0.46, 0.46)) == lab.header.get_zooms()
        assert img.shape == lab.shape == (32, 32, 16)  # x, y, z
        assert set(np.unique(np.asarray(lab.dataobj))) <= set(meta["labels"].values())


def test_kept_projections_and_meshes_go_with_their_sample(gl, cl, tmp_path):
    path = tiny(tmp_path, count=1, extra='keep = ["projections", "meshes"]')
    xr.build(path, tmp_path / "out")
    sample = tmp_path / "out" / "samples" / "00000"
    projections = xr.Projections.load(sample / "projections.tif")
    assert projections.data.shape == (20, 16, 32) and projections.quantity == "lineint"
    meshes = sorted(p.name for p in (sample / "meshes").iterdir())
    assert {"matrix.stl", "weft.stl", "warp.stl", "report.json"} <= set(meshes)


def test_the_plan_and_bad_files_do_no_work(tmp_path, capsys):
    assert cli.main(["build", str(tiny(tmp_path, count=3)), "--plan"]) == 0
    plan = capsys.readouterr().out
    rows = [line for line in plan.splitlines() if re.match(r"\d+\s+(train|val|test)\s", line)]
    assert "source.kvp" in plan and len(rows) == 3 and "3 samples" in plan
    bad = tiny(tmp_path)
    bad.write_text(bad.read_text().replace('"source.kvp"', '"source.kpv"'))
    assert cli.main(["build", str(bad), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "source.kpv" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.toml"]


def test_a_build_that_cannot_fit_on_the_disk_is_refused_before_the_first_sample(tmp_path, monkeypatch, capsys):
    import shutil as shutil_module

    real = shutil_module.disk_usage
    monkeypatch.setattr("xrayraster.dataset.build.shutil.disk_usage",
                        lambda path: real(path)._replace(free=100_000))
    assert cli.main(["build", str(tiny(tmp_path)), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "GiB free" in err and "4 samples" in err
    assert not (tmp_path / "out" / "samples").exists()


def test_the_readmes_dataset_command_runs_as_written(gl, cl, tmp_path):
    """README.md's dataset command, verbatim, from a folder whose examples/ is the repository's."""
    text = (ROOT / "README.md").read_text()
    command = text.split("## A dataset", 1)[1].split("```bash", 1)[1].split("```", 1)[0].split("#", 1)[0].strip()
    assert command.startswith("xrayraster build examples/dataset_small.toml -o ")
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    run = subprocess.run(command, shell=True, cwd=tmp_path, env=child_env(), capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    out = tmp_path / command.split(" -o ", 1)[1].split()[0]
    assert len(list(csv.DictReader(open(out / "manifest.csv")))) == 8 and (out / "gallery.png").is_file()


def test_a_build_drawing_the_weave_family_resumes_and_loads_in_nnunets_layout(gl, cl, tmp_path):
    """Four tiny samples that draw the family among all of them, in nnU-Net's layout: built two
    and then resumed to four, the same files as four built at once; every case loads with nibabel
    and its labels are dataset.json's."""
    nib = pytest.importorskip("nibabel", reason="the dataset extra (pip install \"xrayraster[dataset]\")")
    from xrayraster.weave.families import FAMILY_NAMES

    def dataset(folder: Path, count: int) -> Path:
        folder.mkdir(exist_ok=True)
        path = tiny(folder, count=count, layout="nnunet")
        choices = ", ".join(f'"{name}"' for name in FAMILY_NAMES)
        path.write_text(path.read_text() + f'"weave.family" = {{ choice = [{choices}] }}\n')
        return path

    resumed, whole = tmp_path / "resumed", tmp_path / "whole"
    assert xr.build(dataset(tmp_path / "a", 2), resumed).built == (0, 1)
    assert xr.build(dataset(tmp_path / "a", 4), resumed).built == (2, 3)
    assert xr.build(dataset(tmp_path / "b", 4), whole).built == (0, 1, 2, 3)
    cases = sorted(p.relative_to(whole) for p in [*whole.glob("images*/*.nii.gz"), *whole.glob("labels*/*.nii.gz")])
    assert len(cases) == 8  # four images and four labels
    assert all((resumed / c).read_bytes() == (whole / c).read_bytes() for c in cases)
    drawn = {row["weave.family"] for row in csv.DictReader(open(whole / "manifest.csv"))}
    assert len(drawn) >= 2, drawn  # the draw reaches more than one family
    meta = json.loads((whole / "dataset.json").read_text())
    assert meta["labels"] == {"background": 0, "matrix": 1, "weft": 2, "warp": 3}
    for case in cases:
        if case.parts[0].startswith("labels"):
            assert set(np.unique(np.asarray(nib.load(whole / case).dataobj))) <= set(meta["labels"].values())
