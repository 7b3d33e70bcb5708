"""`xrayraster build` and xr.ml against hostile and careless input (issue 38): a scheduler address
that is no Dask scheduler, a huge count, names, sizes and arguments that a build cannot use. Each
is refused at once, exit status 2 and one line naming the input and the fix, with nothing written;
the directory of a refused run is left as it was; an interrupted or forced build never leaves an
index that lists samples that are gone.

Most builds here scan with a quick stand-in for ``xr.scan`` (:func:`fake_scan`: a volume and labels
from the drawn scan file, metadata as a scan's): what is tested is the build around the scans."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster import cli
from xrayraster.core.errors import ConfigError
from xrayraster.dataset import build as dataset_module
from xrayraster.dataset import scheduler as scheduler_module
from xrayraster.dataset import load_dataset_file
from xrayraster.pipeline.scan import ScanResult

ROOT = Path(__file__).resolve().parents[2]

# A quick dataset (a monochromatic source: no tube spectrum to model, a draw takes a millisecond):
# its base scan inline, so an identical copy of the file elsewhere is the same dataset.
DATASET = """
[dataset]
count = {count}
seed = {seed}
{settings}

[weave.sample]
cells = [1, 1]
points_per_section = 12
samples_per_mm = 2.0

[source]
monochromatic_kev = 40.0
photons_per_mm2_at_1m = 1e7

[geometry]
source_to_origin = 35.0
source_to_detector = 70.0
detector_shape = [16, 32]
pixel_size = 0.9
num_views = 12

[volume]
shape = [8, 16, 16]
voxel_size = 0.8

[vary]
"weave.weft_width_fraction" = {{ uniform = [0.85, 0.99] }}
{vary}
"""


def dataset_file(folder: Path, name: str = "ds.toml", count: int = 3, seed: int = 3, settings: str = "",
                 vary: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(DATASET.format(count=count, seed=seed, settings=settings, vary=vary))
    return path


def fake_scan(loaded, **_):
    """A stand-in for xr.scan: a volume and labels on the drawn grid that depend on the draw (its
    seed), and the metadata keys a build reads, ``scan_file`` named as a scan names it."""
    rng = np.random.default_rng(loaded.options.seed)
    grid = loaded.volume
    volume = xr.Volume(rng.random(grid.shape, dtype=np.float32), grid)
    labels = xr.LabelVolume(rng.integers(0, 4, grid.shape, dtype=np.uint8), grid)
    metadata = {"generator": "xrayraster scan", "scan_file": str(loaded.path), "seed": loaded.options.seed,
                "labels": {"0": "background", "1": "matrix", "2": "weft", "3": "warp"}, "seconds": {"total": 0.1}}
    return ScanResult(volume, labels, metadata)


@pytest.fixture
def quick(monkeypatch, gl, cl):
    """Builds in this process scan with :func:`fake_scan` (on the build's own GL and CL contexts)."""
    monkeypatch.setattr(dataset_module, "scan", fake_scan)


def hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def manifest_indices(root: Path) -> list[int]:
    return [int(row["index"]) for row in csv.DictReader(open(root / "manifest.csv"))]


def refused(capsys, *argv) -> str:
    """Run the command line; it must refuse (exit 2) with one line. Returns that line."""
    assert cli.main(list(argv)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("xrayraster: error: "), err
    return err


def child_env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


# -- a scheduler that is not one ----------------------------------------------------------------


class Server:
    """A TCP server on 127.0.0.1 that accepts and then: says nothing ("silent"), sends an SSH
    banner ("ssh"), or answers as a web server ("http")."""

    def __init__(self, kind: str):
        self.kind, self.connections = kind, []
        self.socket = socket.create_server(("127.0.0.1", 0))
        self.port = self.socket.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                connection, _ = self.socket.accept()
            except OSError:
                return  # closed
            self.connections.append(connection)
            if self.kind == "ssh":
                connection.sendall(b"SSH-2.0-OpenSSH_9.6p1 Ubuntu-3ubuntu13\r\n")
            elif self.kind == "http":
                threading.Thread(target=self._http, args=(connection,), daemon=True).start()

    @staticmethod
    def _http(connection):
        try:
            connection.recv(65536)
            connection.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
            connection.close()
        except OSError:
            pass

    def close(self):
        self.socket.close()
        for connection in self.connections:
            connection.close()


@pytest.fixture
def server(request):
    s = Server(request.param)
    yield s
    s.close()


def closed_port() -> int:
    with socket.create_server(("127.0.0.1", 0)) as s:
        return s.getsockname()[1]  # nothing listens there once closed


@pytest.mark.parametrize("server", ["ssh", "http"], indirect=True)
def test_a_server_that_speaks_another_protocol_is_no_scheduler(server, tmp_path, capsys):
    pytest.importorskip("distributed")
    address = f"tcp://127.0.0.1:{server.port}"
    err = refused(capsys, "build", str(dataset_file(tmp_path)), "-o", str(tmp_path / "out"), "--scheduler", address,
                  "--quiet")
    assert address in err and "Dask" in err and "dask scheduler" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("address", ["not a url", "http://127.0.0.1:{port}", "127.0.0.1", "tcp://127.0.0.1:{port}"],
                         ids=["not a url", "http", "no port", "closed port"])
def test_an_address_where_no_scheduler_listens_is_refused(address, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(scheduler_module, "SCHEDULER_TIMEOUT_S", 1.0)  # a closed port: Dask retries
    address = address.format(port=closed_port())
    start = time.monotonic()
    err = refused(capsys, "build", str(dataset_file(tmp_path)), "-o", str(tmp_path / "out"), "--scheduler", address,
                  "--quiet")
    assert time.monotonic() - start < 10 and repr(address) in err and "dask scheduler" in err
    assert not (tmp_path / "out").exists()


TIMED = """
import sys
from xrayraster import cli
from xrayraster.dataset import scheduler
scheduler.SCHEDULER_TIMEOUT_S = 2.0
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("server", ["silent"], indirect=True)
def test_a_scheduler_that_never_answers_is_given_up_on_within_its_timeout(server, tmp_path):
    """A server that accepts and never says a word: Dask's own timeout covers connecting, not
    hearing back, and would wait for ever (339 s until Ctrl-C in the issue)."""
    pytest.importorskip("distributed")
    address = f"tcp://127.0.0.1:{server.port}"
    command = [sys.executable, "-c", TIMED, "build", str(dataset_file(tmp_path)), "-o", str(tmp_path / "out"),
               "--scheduler", address, "--quiet"]
    start = time.monotonic()
    try:
        run = subprocess.run(command, env=child_env(), capture_output=True, text=True, timeout=45)
    except subprocess.TimeoutExpired:
        pytest.fail("no answer from the scheduler, and the build waited for it 45 s")
    assert run.returncode == 2, run.stderr
    assert run.stderr.count("\n") == 1 and "no Dask scheduler answered within 2 s" in run.stderr
    assert time.monotonic() - start < 30 and not (tmp_path / "out").exists()


# -- a huge count, sizes the machine cannot hold ------------------------------------------------


@pytest.mark.slow
def test_the_plan_of_a_huge_count_prints_its_first_rows_at_once_and_estimates_the_rest(tmp_path):
    path = dataset_file(tmp_path, count=100_000)
    command = [sys.executable, "-m", "xrayraster", "build", str(path), "--plan"]
    proc = subprocess.Popen(command, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines, first_row_at = [], None
    start = time.monotonic()
    timer = threading.Timer(60, proc.kill)  # the plan printed nothing for 10 hours
    timer.start()
    try:
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if first_row_at is None and line.startswith("0 "):
                first_row_at = time.monotonic() - start
        proc.wait()
    finally:
        timer.cancel()
    assert proc.returncode == 0, proc.stderr.read()
    rows = [line for line in lines if re.match(r"\d+\s+(train|val|test)\s", line)]
    assert first_row_at is not None and first_row_at < 20
    assert len(rows) == 50 and rows[-1].startswith("49 ")
    assert lines[-1].startswith("100000 samples, estimated from the first 50 samples")


def test_a_sample_whose_scan_cannot_fit_in_memory_is_refused_by_plan_and_build(tmp_path, capsys, monkeypatch):
    """The scan's own memory check (xr.scan refuses it) is made in the plan and before the build,
    not found sample by sample (the issue's 2048³ grid passed --plan, then failed twice a sample)."""
    monkeypatch.setattr("xrayraster.core.memory.available_memory", lambda: 64 * 2**20)  # a 64 MiB machine
    path = dataset_file(tmp_path, vary='"volume.shape" = [256, 256, 256]')  # 80 MiB of volume and labels
    for argv in (["--plan"], ["-o", str(tmp_path / "out")]):
        err = refused(capsys, "build", str(path), *argv)
        assert "[volume] shape = [256, 256, 256]" in err and "available" in err
    assert not (tmp_path / "out").exists()


def test_a_run_refused_for_its_size_leaves_the_directory_as_it_was(quick, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    assert cli.main(["build", str(dataset_file(tmp_path, count=2)), "-o", str(out), "--quiet"]) == 0
    before = hashes(out)
    real = shutil.disk_usage
    with monkeypatch.context() as m:
        m.setattr("xrayraster.dataset.build.shutil.disk_usage", lambda p: real(p)._replace(free=10**6))
        err = refused(capsys, "build", str(dataset_file(tmp_path, count=100_000)), "-o", str(out), "--quiet")
    assert "99998 samples need about" in err
    assert hashes(out) == before
    # The count it had is still the build's: lowering it back is no change.
    assert cli.main(["build", str(dataset_file(tmp_path, count=2)), "-o", str(out), "--quiet"]) == 0
    assert hashes(out) == before


# -- names, forced rebuilds, what stays -----------------------------------------------------------


def test_one_name_rule_everywhere_and_a_refused_name_writes_nothing(quick, tmp_path, capsys):
    """A file named _x.toml names its dataset '_x', which no layout can use: refused by --plan and
    by the build before anything is written, so adding name = "x" then builds."""
    path = dataset_file(tmp_path, name="_x.toml", count=2, settings='layout = "nnunet"')
    out = tmp_path / "out"
    for argv in (["--plan"], ["-o", str(out)], ["-o", str(out), "--force"]):
        err = refused(capsys, "build", str(path), *argv)
        assert "'_x'" in err and 'name = "x"' in err
    assert not out.exists()
    path.write_text(path.read_text().replace('layout = "nnunet"', 'layout = "nnunet"\nname = "x"'))
    assert cli.main(["build", str(path), "-o", str(out), "--quiet"]) == 0
    assert manifest_indices(out) == [0, 1]
    with pytest.raises(ConfigError, match=r"name must be letters, digits and underscores, the first a letter"):
        load_dataset_file(dataset_file(tmp_path, settings='name = "-x"'))


def test_force_never_leaves_the_manifest_listing_samples_that_are_gone(quick, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["build", str(dataset_file(tmp_path, "x.toml", count=3)), "-o", str(out), "--quiet"]) == 0
    before = hashes(out)
    # A forced run that cannot build (a name no layout takes) is refused before it removes anything.
    bad = dataset_file(tmp_path, "_x.toml", count=3, settings='layout = "nnunet"')
    refused(capsys, "build", str(bad), "-o", str(out), "--force", "--quiet")
    assert hashes(out) == before
    # A forced run that builds: the earlier build's samples and index go, the new ones are listed.
    other = dataset_file(tmp_path, "y.toml", count=2, seed=4, settings='layout = "nnunet"')
    assert cli.main(["build", str(other), "-o", str(out), "--force", "--quiet"]) == 0
    assert not (out / "samples").exists() and manifest_indices(out) == [0, 1]
    assert len(list(out.glob("records/y_*.json"))) == 2


def test_a_persons_file_where_a_sample_goes_is_refused_first_without_advising_force(quick, tmp_path, capsys):
    """The issue: --force given, and each sample whose folder held a person's file failed twice,
    saying "or pass --force". Now refused before anything is written, naming the file to move."""
    out = tmp_path / "out"
    kept = "keep = [\"meshes\"]"  # a sample's recorded extras go with it when it is removed
    assert cli.main(["build", str(dataset_file(tmp_path, count=2, settings=kept)), "-o", str(out), "--quiet"]) == 0
    for sample in ("00001", "00002"):
        (out / "samples" / sample).mkdir(exist_ok=True)
        (out / "samples" / sample / "notes.txt").write_text("mine")
    before = hashes(out)
    # Resumed (sample 2 goes beside the notes), and forced (so does sample 1: its own files go).
    for seed, force, sample in ((3, [], "00002"), (4, ["--force"], "00001")):
        err = refused(capsys, "build", str(dataset_file(tmp_path, count=3, seed=seed, settings=kept)), "-o", str(out),
                      "--quiet", *force)
        assert f"samples/{sample} holds notes.txt" in err and "move them out" in err and "--force" not in err
        assert hashes(out) == before
    shutil.rmtree(out / "samples" / "00002")
    (out / "samples" / "00001" / "notes.txt").unlink()
    assert cli.main(["build", str(dataset_file(tmp_path, count=2, seed=4, settings=kept)), "-o", str(out),
                     "--force", "--quiet"]) == 0
    assert sorted(p.name for p in (out / "samples").iterdir()) == ["00000", "00001"]
    assert json.loads((out / "build.json").read_text())["identity"]["seed"] == 4


def test_bad_input_inside_a_sample_is_not_retried(quick, tmp_path, capsys, monkeypatch):
    calls = []

    def bad(data, root, index, *args):
        calls.append(index)
        raise ConfigError(f"sample {index}: a drawn value no scan takes")

    monkeypatch.setattr(dataset_module, "build_sample", bad)
    assert cli.main(["build", str(dataset_file(tmp_path, count=2)), "-o", str(tmp_path / "out"), "--quiet"]) == 1
    assert calls == [0, 1]  # once each: it fails alike every time
    assert "2 samples failed" in capsys.readouterr().err


def test_a_build_resumed_from_a_copy_of_its_file_elsewhere_gives_the_same_bytes(quick, tmp_path, monkeypatch):
    first = dataset_file(tmp_path / "here", count=3)
    reference = tmp_path / "reference"
    xr.build(first, reference)
    # Interrupted after its first sample, then resumed from an identical copy of the file elsewhere.
    real = dataset_module.build_sample

    def interrupted(data, root, index, *args):
        if index == 1:
            raise KeyboardInterrupt
        return real(data, root, index, *args)

    out = tmp_path / "out"
    monkeypatch.setattr(dataset_module, "build_sample", interrupted)
    with pytest.raises(KeyboardInterrupt):
        xr.build(first, out)
    monkeypatch.setattr(dataset_module, "build_sample", real)
    copy = tmp_path / "elsewhere" / "ds.toml"
    copy.parent.mkdir()
    shutil.copy(first, copy)
    assert xr.build(copy, out).built == (1, 2)
    assert hashes(out) == hashes(reference)


def test_ctrl_c_says_which_samples_were_kept(quick, tmp_path, capsys, monkeypatch):
    real = dataset_module.build_sample

    def interrupted(data, root, index, *args):
        if index == 2:
            raise KeyboardInterrupt
        return real(data, root, index, *args)

    monkeypatch.setattr(dataset_module, "build_sample", interrupted)
    out = tmp_path / "out"
    assert cli.main(["build", str(dataset_file(tmp_path, count=4)), "-o", str(out), "--quiet"]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no output written" not in err
    assert "keeps the 2 finished samples of 4, listed in manifest.csv and gallery.png" in err
    assert manifest_indices(out) == [0, 1] and (out / "gallery.png").is_file()


def test_an_output_directory_that_cannot_be_written_is_refused(quick, tmp_path, capsys):
    if os.geteuid() != 0 or shutil.which("chattr") is None:
        pytest.skip("needs root and chattr, to make a directory immutable")
    out = tmp_path / "out"
    assert cli.main(["build", str(dataset_file(tmp_path, count=1)), "-o", str(out), "--quiet"]) == 0
    empty = tmp_path / "empty"
    empty.mkdir()
    before = hashes(out)
    for folder in (out, empty, out / "samples"):
        if subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode:
            pytest.skip("this file system has no immutable flag")
        try:
            target = empty if folder == empty else out
            err = refused(capsys, "build", str(dataset_file(tmp_path, count=2)), "-o", str(target), "--quiet")
            assert f"cannot write {target}" in err and "Operation not permitted" in err
        finally:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
    assert hashes(out) == before and not any(empty.iterdir())


# -- workers ------------------------------------------------------------------------------------


def test_workers_beyond_the_samples_left_and_the_cores_are_capped_saying_so(tmp_path, capsys, monkeypatch):
    started = []
    monkeypatch.setattr(dataset_module, "_on_pool", lambda d, r, todo, workers: started.append(workers) or iter(()))
    monkeypatch.setattr(dataset_module, "_in_process", lambda d, r, todo: started.append(1) or iter(()))
    assert cli.main(["build", str(dataset_file(tmp_path, count=2)), "-o", str(tmp_path / "out"), "--workers",
                     "100", "--quiet"]) == 0
    useful = min(2, len(os.sched_getaffinity(0)))
    assert started == [useful]
    err = capsys.readouterr().err
    assert f"xrayraster: warning: workers = 100: using {useful} (2 samples left" in err


@pytest.mark.parametrize("workers", ["2", True])
def test_a_workers_argument_that_is_no_count_is_refused_naming_it(workers, tmp_path):
    with pytest.raises(ConfigError, match=r"^workers \(processes building samples at once\) must be a whole number"):
        xr.build(dataset_file(tmp_path), tmp_path / "out", workers=workers)
    assert not (tmp_path / "out").exists()


WORKER_MASK = """
import os, signal, sys
from pathlib import Path
# Imported again by every spawned pool worker (as __mp_main__), before its initializer runs:
# record whether Ctrl-C could reach it then.
if __name__ == "__mp_main__":
    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    Path(sys.argv[-1], f"{os.getpid()}.mask").write_text(str(blocked or ignored))
from xrayraster import cli
if __name__ == "__main__":
    sys.exit(cli.main(sys.argv[1:-1]))
"""


@pytest.mark.slow
def test_pool_workers_are_started_deaf_to_ctrl_c(tmp_path):
    """A Ctrl-C at the terminal signals every process of the group: a pool worker still importing
    (before its initializer ignores SIGINT) printed a traceback. Workers start with SIGINT blocked."""
    script, masks = tmp_path / "run.py", tmp_path / "masks"
    script.write_text(WORKER_MASK)
    masks.mkdir()
    path = dataset_file(tmp_path, count=2)
    run = subprocess.run([sys.executable, str(script), "build", str(path), "-o", str(tmp_path / "out"), "--workers",
                          "2", "--quiet", str(masks)], env=child_env(), capture_output=True, text=True, timeout=120)
    recorded = [p.read_text() for p in masks.iterdir()]
    assert len(recorded) == min(2, len(os.sched_getaffinity(0))), run.stderr
    assert set(recorded) == {"True"}


TERMINATED = """
import multiprocessing, sys, time
from xrayraster.dataset.build import _init_worker

def sample(_):
    from tqdm import tqdm
    list(tqdm(range(3), disable=True))  # as a woven sample's meshing does
    time.sleep(60)

if __name__ == "__main__":
    pool = multiprocessing.get_context("spawn").Pool(2, initializer=_init_worker)
    pool.map_async(sample, [0, 1])
    time.sleep(float(sys.argv[1]))
    pool.terminate()  # what Ctrl-C does to a build's pool
    pool.join()
"""


@pytest.mark.slow
def test_a_pool_stopped_mid_sample_leaves_no_semaphore_behind(tmp_path):
    """The issue's Ctrl-C with --workers 2: "resource_tracker: There appear to be 2 leaked semaphore
    objects" (tqdm's lock, made in each spawned worker, never released when the pool terminates)."""
    script = tmp_path / "pool.py"
    script.write_text(TERMINATED)
    run = subprocess.run([sys.executable, str(script), "5"], env=child_env(), capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and "leaked" not in run.stderr, run.stderr


# -- the dataset file ---------------------------------------------------------------------------


def test_a_table_where_a_value_goes_is_an_unknown_distribution(tmp_path):
    path = dataset_file(tmp_path, vary='"source.monochromatic_kev" = { gaussian = [40, 1] }')
    with pytest.raises(ConfigError, match=r"'source.monochromatic_kev' = .*: unknown distribution 'gaussian'; give "
                                          r"one of uniform, loguniform, normal, integer, choice"):
        load_dataset_file(path)


@pytest.mark.parametrize("base", ["ds.toml", "other.toml"], ids=["itself", "another dataset file"])
def test_a_base_that_is_a_dataset_file_says_so(base, tmp_path, capsys):
    dataset_file(tmp_path, "other.toml")
    path = tmp_path / "ds.toml"
    path.write_text(f'base = "{base}"\n[dataset]\ncount = 1\nseed = 0\n')
    err = refused(capsys, "build", str(path), "--plan")
    said = "names this dataset file itself" if base == "ds.toml" else "is a dataset file (it has [dataset]"
    assert f"base = '{base}' {said}" in err and "scan file" in err and "unknown key" not in err


# -- xr.ml --------------------------------------------------------------------------------------


@pytest.mark.parametrize("arguments, name", [({"patch_size": 16.5}, "patch_size"), ({"patch_size": "16"}, "patch_size"),
                                             ({"seed": -1}, "seed"), ({"seed": "1"}, "seed")],
                         ids=["patch 16.5", "patch '16'", "seed -1", "seed '1'"])
def test_patch_dataset_arguments_are_refused_naming_them(arguments, name, tmp_path):
    pytest.importorskip("h5py")
    pytest.importorskip("nibabel")
    from builds import write_build

    root = write_build(tmp_path / "build", "tiff")
    with pytest.raises(ConfigError, match=rf"^{name} must be"):
        xr.ml.PatchDataset(root, **{"patch_size": 8, **arguments})
    with pytest.raises(ConfigError, match=r"^epoch must be an integer >= 0"):
        xr.ml.PatchDataset(root, 8).set_epoch(-1)


# -- big volumes --------------------------------------------------------------------------------


def test_small_tiffs_are_written_as_before(tmp_path):
    """The ImageJ hyperstack, one IFD a page, byte for byte as tifffile writes it with these arguments."""
    import tifffile

    from xrayraster.core.ownership import SOFTWARE
    from xrayraster.core.tiff import write_tiff

    data = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    write_tiff(tmp_path / "ours.tif", data, axes="ZYX", pixel_size_mm=(0.5, 0.25), info={"a": 1}, spacing_mm=0.5)
    tifffile.imwrite(tmp_path / "plain.tif", data, imagej=True, resolution=(4.0, 2.0), software=SOFTWARE,
                     metadata={"axes": "ZYX", "unit": "mm", "Info": json.dumps({"a": 1}, indent=1), "spacing": 0.5})
    assert (tmp_path / "ours.tif").read_bytes() == (tmp_path / "plain.tif").read_bytes()


@pytest.mark.slow
def test_a_volume_over_4_gib_is_written_without_tifffiles_warning(tmp_path):
    """A 1024³ float32 volume (4 GiB) cannot have an IFD a page in a classic TIFF: it is written as
    ImageJ writes big stacks, without the "truncating ImageJ file" warning, and reads back whole."""
    import tifffile

    if shutil.disk_usage(tmp_path).free < 6 * 2**30:
        pytest.skip("needs 6 GiB of free disk")
    grid = xr.VolumeGeometry((1024, 1024, 1024), 0.01)
    data = np.zeros(grid.shape, np.float32)  # pages of zeros: no memory until written
    data[5, 6, 7], data[1000, 1001, 1002] = 3.0, 4.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        xr.Volume(data, grid).save(tmp_path / "big.tif", quicklook=False)
    read = tifffile.memmap(tmp_path / "big.tif", mode="r")
    assert read.shape == grid.shape and read[5, 6, 7] == 3.0 and read[1000, 1001, 1002] == 4.0
