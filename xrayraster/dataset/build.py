"""``xr.build``: a dataset of randomised, labelled tomograms from a dataset file (docs/dataset.md).

Each sample is ``xr.scan`` of one drawn scan table (:func:`~.dataset_file.draw`: the master seed
and the sample's index decide it, nothing else), written in the dataset's layout
(:mod:`.layouts`) under a temporary name and moved into place when complete. So a build can
be killed at any moment and rerun: finished samples are skipped, partial ones (hidden
temporaries) removed and redone, and the files are the same bytes as an uninterrupted build's,
with one worker or many, on a process pool or on Dask.

The directory's record, ``build.json``, holds the dataset's fingerprint (everything that decides
the samples but their count): a rerun against a changed dataset file is refused, naming what
changed, unless ``force`` (which removes this build's samples first, never anything else); a
larger ``count`` only adds samples. Sample files hold nothing that varies between runs (no wall
times, no memory peaks): those go to the log, one line a sample.

Workers: ``workers`` processes of a local pool (spawned, each with its own GL and OpenCL contexts
kept across its samples, ``cores / workers`` threads each), or Dask distributed (``dask=True``: a
``LocalCluster`` of processes; ``scheduler``: an existing cluster's address, whose workers write
straight into ``directory`` on a shared file system). A sample that fails is retried once (not a
ConfigError: bad input fails alike every time), then written to ``failed.csv`` with its drawn values
and the error.

Nothing is written until every input has passed: the dataset file (its name too), the arguments,
the directory (an earlier build's record, the write permission), the first sample left against the
memory and the disk, and the scheduler's answer. A refused run leaves ``directory`` as it was.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import json
import logging
import numbers
import os
import shutil
import signal
import sys
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from ..core.errors import ConfigError, XrayrasterError, XrayrasterWarning
from ..core.files import atomic_write_text
from ..core.heap import hand_back_freed_memory
from ..core.pictures import write_gallery
from ..pipeline.scan import scan
from ..pipeline.woven import weave
from . import scheduler as scheduler_module  # its timeout read at each use: tests shorten it
from .dataset_file import DatasetFile, draw, load_dataset_file
from .directory import check_sample_folders, checked_directory, record_build, sweep
from .distributions import Fixed
from .layouts import LAYOUTS
from .names import FAILED_NAME, GALLERY_NAME
from .plan import check_sample, sample_bytes
from .scheduler import check_scheduler, require_distributed

__all__ = ["BuildReport", "build", "build_sample"]

log = logging.getLogger(__name__)

GALLERY_SAMPLES = 6  # the first finished samples the gallery shows
# Keys of a scan's metadata that differ between two runs of the same sample, kept out of its files:
# wall times, the memory peak, and the devices (an OpenCL CPU device's description counts the
# compute units a worker was given).
VOLATILE = ("seconds", "peak_rss_mib", "devices")
RETRIES = 1



@dataclass(frozen=True)
class BuildReport:
    """What a build did: ``built`` (indices made now), ``skipped`` (finished before), ``failed``
    (index → one-line error, after its retry), ``seconds`` (wall time) and ``directory``."""

    directory: Path
    built: tuple[int, ...]
    skipped: int
    failed: dict[int, str] = field(default_factory=dict)
    seconds: float = 0.0


def build(config, directory, *, workers: int = 1, dask: bool = False, scheduler: str | None = None,
          force: bool = False, progress: bool = False) -> BuildReport:
    """Build the dataset of ``config`` (a dataset file's path, its parsed table, or a
    :class:`~.dataset_file.DatasetFile`) into ``directory`` (module docstring). ``progress``: a
    bar with ETA and samples per hour on stderr. Returns a :class:`BuildReport`."""
    dataset = config if isinstance(config, DatasetFile) else load_dataset_file(config)
    workers = _checked_workers(workers)
    root, replaced = checked_directory(dataset, directory, force)
    layout = LAYOUTS[dataset.layout]
    finished = layout.finished(root, dataset.name) if root.is_dir() and replaced is None else {}
    todo = [i for i in range(dataset.count) if i not in finished]
    check_sample_folders(root, layout, todo, dataset.name)
    _check_first_sample(dataset, root, todo)
    if scheduler is not None:
        check_scheduler(scheduler, scheduler_module.SCHEDULER_TIMEOUT_S)
    else:
        workers = _useful_workers(workers, len(todo))
    # Everything has passed: from here on the build writes.
    record_build(root, dataset, replaced)
    dataset = _as_first_built(dataset, root, layout, finished)
    sweep(root)  # what a killed build left: temporaries, and the files of samples it did not finish
    for path in layout.remove_unfinished(root, dataset.name):
        log.info("removed %s: its sample was not finished", path)
    start = time.perf_counter()
    built, failed, interrupted = [], {}, None
    try:
        for summary in _run(dataset, root, todo, workers=workers, dask=dask, scheduler=scheduler,
                            progress=progress):
            if "error" in summary:
                failed[summary["index"]] = summary["error"]
                log.warning("sample %05d failed: %s", summary["index"], summary["error"])
            else:
                built.append(summary["index"])
                log.info("sample %05d  seed %d  %.1f s  %s", summary["index"], summary["seed"], summary["seconds"],
                         "  ".join(f"{k} {v:.3f}" for k, v in summary["fractions"].items()))
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM: the command line says what was kept
        interrupted = exc
        raise
    finally:
        sweep(root)  # the pool's, when it was stopped
        records = layout.finished(root, dataset.name)
        layout.write_index(root, records, name=dataset.name, labels=_labels(records))
        _write_failed(root, dataset, failed)
        _write_gallery(root, dataset, records)
        if interrupted is not None:
            interrupted.add_note(_kept(root, layout, len(records), dataset.count))
    return BuildReport(root, tuple(sorted(built)), dataset.count - len(todo), failed,
                       round(time.perf_counter() - start, 3))


def build_sample(dataset: DatasetFile, root, index: int, threads: int | None = None, contexts=None) -> dict:
    """Draw, scan and write sample ``index`` (one task, in whichever process runs it); returns a
    summary for the log: index, seed, wall seconds and the share of each label by name.
    ``contexts``: the (GLContext, CLContext) to scan on; by default a worker process's own, made on
    its first sample and kept (:func:`_worker_contexts`)."""
    start = time.perf_counter()
    drawn = draw(dataset, index)
    for reason in drawn.redraws:
        log.info("sample %05d redrawn: %s", index, reason)
    gl, cl = contexts or _worker_contexts(threads)
    keep_projections = "projections" in dataset.keep
    result = scan(drawn.scan, gl=gl, cl=cl, threads=threads, keep_projections=keep_projections)
    names = {k: v for k, v in result.metadata["labels"].items() if k != "0"}
    record = {"seed": drawn.seed, "split": drawn.split, "values": drawn.values, "attempts": drawn.attempts,
              "labels": names}
    woven = drawn.scan.weave
    meshes = (lambda directory: weave(woven).write(directory)) if "meshes" in dataset.keep and woven else None
    stored = LAYOUTS[dataset.layout].write_sample(
        Path(root), index, dataclasses.replace(result, metadata=_steady(result.metadata)), record,
        name=dataset.name, projections=result.projections, write_meshes=meshes)
    fractions = {names.get(k, "background" if k == "0" else k): v for k, v in stored["fractions"].items()}
    del result, stored
    hand_back_freed_memory()
    return {"index": index, "seed": drawn.seed, "seconds": time.perf_counter() - start, "fractions": fractions}


def _checked_workers(workers) -> int:
    """``workers`` as an int, or ConfigError naming it."""
    whole = isinstance(workers, numbers.Integral) or (isinstance(workers, float) and workers.is_integer())
    if isinstance(workers, bool) or not whole or workers < 1:
        raise ConfigError(f"workers (processes building samples at once) must be a whole number >= 1, "
                          f"got {workers!r}")
    return int(workers)


def _useful_workers(workers: int, samples: int) -> int:
    """``workers`` capped at the samples left and the cores this process may use, saying so: more
    processes would only start and wait, or share the cores."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    useful = max(1, min(samples, cores))
    if workers > useful and samples:
        warnings.warn(f"workers = {workers}: using {useful} ({samples} samples left, {cores} cores); more "
                      "processes would only wait or share the cores", XrayrasterWarning, stacklevel=3)
        return useful
    return workers


def _steady(metadata: dict) -> dict:
    """A scan's metadata without what differs between two runs of it (:data:`VOLATILE`)."""
    return {k: v for k, v in metadata.items() if k not in VOLATILE}


# -- the samples' checks and what a build leaves ------------------------------------------------


def _as_first_built(dataset: DatasetFile, root: Path, layout, finished: dict) -> DatasetFile:
    """``dataset`` naming the file the build's finished samples were drawn from, where it was: a
    sample's metadata names its dataset file (``scan_file``), so a build resumed from an identical
    copy elsewhere (the same fingerprint) still gives the bytes of an uninterrupted build."""
    if not finished:
        return dataset
    index = min(finished)
    try:
        recorded = layout.scan_metadata(root, index, finished[index]["split"], dataset.name)["scan_file"]
    except (OSError, KeyError, ValueError):  # a sample of an older build: keep this file's name
        return dataset
    where, _, number = str(recorded).rpartition(" sample ")
    if number != str(index) or where in ("", dataset.where):
        return dataset
    return dataclasses.replace(dataset, path=None if where == "dataset table" else Path(where))


def _check_first_sample(dataset: DatasetFile, root: Path, todo: list[int]) -> None:
    """Refuse, before any work, what the samples left would fail on, from the first one: a scan that
    cannot fit in memory (:func:`~.plan.check_sample`, as ``xr.scan`` would refuse it), and
    samples that cannot fit on the disk (its size, :func:`~.plan.sample_bytes`, times their
    number)."""
    if not todo:
        return
    first = draw(dataset, todo[0]).scan
    check_sample(first)
    needed = sample_bytes(first, dataset.keep) * len(todo)
    free = shutil.disk_usage(_existing(root)).free
    if needed > free:
        raise ConfigError(f"{root}: {len(todo)} samples need about {needed / 2**30:.1f} GiB and the disk has "
                          f"{free / 2**30:.1f} GiB free; free space, choose another disk, or lower [dataset] count")


def _existing(path: Path) -> Path:
    """``path`` or its nearest existing parent (a build's directory is made only once all has passed)."""
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _kept(root: Path, layout, finished: int, count: int) -> str:
    """What an interrupted build kept, for the command line's last line."""
    index = " and ".join(name for name in (*layout.index_names(), GALLERY_NAME) if (root / name).exists())
    return (f"{root} keeps the {finished} finished samples of {count}" + (f", listed in {index}" if index else "")
            + "; rerun the same command to build the rest (temporaries of unfinished samples removed)")


def _labels(records: dict[int, dict]) -> dict[int, str]:
    names: dict[int, str] = {}
    for record in records.values():
        for key, name in record.get("labels", {}).items():
            names.setdefault(int(key), name)
    return dict(sorted(names.items()))


def _write_failed(root: Path, dataset: DatasetFile, failed: dict[int, str]) -> None:
    path = root / FAILED_NAME
    if not failed:
        path.unlink(missing_ok=True)
        return
    text = io.StringIO()
    writer = csv.writer(text)
    writer.writerow(["index", "seed", "values", "error"])
    for index in sorted(failed):
        drawn = draw(dataset, index)
        writer.writerow([index, drawn.seed, json.dumps(drawn.values, sort_keys=True), failed[index]])
    atomic_write_text(path, text.getvalue())


def _write_gallery(root: Path, dataset: DatasetFile, records: dict[int, dict]) -> None:
    """``gallery.png``: the first finished samples' central slices, captioned with what was drawn
    for them (the varied keys, not those the dataset fixes)."""
    if not records:
        return
    varied = [key for key, d in dataset.vary.items() if not isinstance(d, Fixed)]
    layout, samples = LAYOUTS[dataset.layout], []
    for index in sorted(records)[:GALLERY_SAMPLES]:
        record = records[index]
        volume, labels = layout.read_sample(root, index, record["split"], dataset.name)
        drawn = ", ".join(f"{key} {_short(record['values'][key])}" for key in varied[:3] if key in record["values"])
        samples.append((volume, labels, record.get("labels", {}), f"sample {index:05d} ({record['split']}): {drawn}"))
    write_gallery(root / GALLERY_NAME, samples)


def _short(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)


# -- running the samples -----------------------------------------------------------------------


def _run(dataset, root, todo, *, workers, dask, scheduler, progress):
    """Summaries of the samples of ``todo`` as they finish (errors as ``{"index", "error"}``); with
    ``progress``, a bar with ETA and samples per hour, the log lines printed above it."""
    if not todo:
        return
    if dask or scheduler:
        runs = _on_dask(dataset, root, todo, workers, scheduler)
    elif workers > 1:
        runs = _on_pool(dataset, root, todo, workers)
    else:
        runs = _in_process(dataset, root, todo)
    if not progress:
        yield from runs
        return
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    with tqdm(total=len(todo), desc="samples", unit="sample", file=sys.stderr) as bar, logging_redirect_tqdm():
        for summary in runs:
            bar.update()
            hours = bar.format_dict["elapsed"] / 3600
            bar.set_postfix_str(f"{bar.n / hours:.0f} samples/h" if hours else "")
            yield summary


def _attempt(dataset, root, index, threads, contexts=None) -> dict:
    """Sample ``index``, retried once unless bad input (a ConfigError fails alike every time); an
    error after that is returned, not raised."""
    for attempt in range(RETRIES + 1):
        try:
            return build_sample(dataset, root, index, threads, contexts)
        except (XrayrasterError, OSError, RuntimeError, ValueError) as exc:
            error = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            log.info("sample %05d, attempt %d: %s", index, attempt + 1, error)
            if isinstance(exc, ConfigError):
                break
    return {"index": index, "error": error}


def _in_process(dataset, root, todo):
    """The samples one after another in this process, on contexts made for the build and released
    when it ends (a caller's process keeps no GL or OpenCL state of ours)."""
    from ..gl.context import GLContext
    from ..recon.opencl import CLContext

    with GLContext() as gl, CLContext() as cl:
        for index in todo:
            yield _attempt(dataset, root, index, None, (gl, cl))


def _on_pool(dataset, root, todo, workers):
    import multiprocessing

    threads = max(1, (os.cpu_count() or 1) // workers)
    context = multiprocessing.get_context("spawn")  # GL and OpenCL state does not survive a fork
    with _sigint_blocked():
        pool = context.Pool(workers, initializer=_init_worker)
    try:
        yield from pool.imap_unordered(functools.partial(_attempt, dataset, root, threads=threads), todo)
    except BaseException:  # Ctrl-C, an error, or the caller stopped: the workers stop now
        pool.terminate()  # (their temporaries are then stale, for the build's sweep)
        raise
    else:
        pool.close()
    finally:
        pool.join()


@contextmanager
def _sigint_blocked():
    """Block SIGINT in this thread while processes are started: they inherit the mask, so a Ctrl-C
    at the terminal (which signals every process of the group) never reaches a pool worker, even
    while it imports, before its initializer (the parent stops the pool: terminate); the parent's
    own, if one came meanwhile, arrives when the block ends."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    # Started first: starting it unblocks SIGINT in the caller (CPython's bpo-33613), and a pool
    # starts it with its first lock.
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _on_dask(dataset, root, todo, workers, scheduler):
    require_distributed()
    from distributed import Client, LocalCluster, as_completed
    # A LocalCluster's workers share this machine; a cluster's own workers know their machines, and
    # their threads are set where they are started (docs/dataset.md).
    threads = None if scheduler else max(1, (os.cpu_count() or 1) // workers)
    cluster = None if scheduler else LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)
    client = Client(scheduler or cluster, timeout=scheduler_module.SCHEDULER_TIMEOUT_S)
    try:
        futures = [client.submit(_attempt, dataset, str(root), index, threads, key=f"xrayraster-sample-{index}",
                                 pure=False) for index in todo]
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# A worker process's contexts, made on its first sample and kept for the rest (a worker of a pool
# or of Dask scans many samples; making them costs a second, compiling the kernels more). Only
# worker processes make them: a build in the caller's process owns its own (_in_process).
_contexts = None


def _init_worker() -> None:
    """A pool worker: Ctrl-C is the parent's to handle (it stops the pool). tqdm's bars (a woven
    sample's, even disabled) share a lock, by default a multiprocessing one: in a spawned process a
    named semaphore, which the pool's terminate (Ctrl-C) leaves behind, and the resource tracker then
    warns of "leaked semaphore objects". A worker's bars are its own: a thread lock does."""
    import threading

    from tqdm import tqdm

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    tqdm.set_lock(threading.RLock())


def _worker_contexts(threads: int | None):
    """This process's GL and OpenCL contexts, made on its first sample, its heap set to keep freed
    arrays (:func:`~xrayraster.core.heap.keep_freed_memory`). A worker sharing the machine
    (``threads``: its share of the cores) first caps the CPU threads llvmpipe and PoCL start, which
    they read once, when the first context is made; a variable the user set is left as it is."""
    global _contexts
    if _contexts is None:
        from ..core.heap import keep_freed_memory
        from ..gl.context import GLContext
        from ..recon.opencl import CLContext

        if threads is not None:
            os.environ.setdefault("LP_NUM_THREADS", str(threads))  # llvmpipe's rasteriser threads
            os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", str(threads))  # PoCL's CPU device
        keep_freed_memory()  # a worker's process is the build's (core/heap.py)
        _contexts = (GLContext(), CLContext())
    return _contexts
