"""``xr.build``: a dataset of randomised, labelled tomograms from a dataset file (docs/dataset.md).

Each sample is ``xr.scan`` of one drawn scan table (:func:`~.dataset_file.draw`: the master seed
and the sample's index decide it, nothing else), written in the dataset's layout
(:mod:`.dataset_layout`) under a temporary name and moved into place when complete. So a build can
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
straight into ``directory`` on a shared file system). A sample that fails is retried once, then
written to ``failed.csv`` with its drawn values and the error.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import json
import logging
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..core.errors import ConfigError, XrayrasterError
from ..core.files import atomic_write_text, directory_target, remove_stale_temporaries_in
from ..core.ownership import read_record
from ..core.pictures import write_gallery
from ..core.provenance import package_version
from ..io.dataset_layout import LAYOUTS
from .dataset_file import DatasetFile, differences, draw, fingerprint, identity, load_dataset_file
from .dataset_plan import sample_bytes
from .distributions import Fixed
from .scan import scan
from .woven import weave

__all__ = ["BuildReport", "build", "build_sample"]

log = logging.getLogger(__name__)

GENERATOR = "xrayraster build"
RECORD_NAME, FAILED_NAME, GALLERY_NAME = "build.json", "failed.csv", "gallery.png"
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
    if workers < 1 or int(workers) != workers:
        raise ConfigError(f"workers must be a whole number >= 1, got {workers!r}")
    root = _prepare(dataset, directory, force)
    layout = LAYOUTS[dataset.layout]
    _sweep(root)  # what a killed build left: temporaries, and the files of samples it did not finish
    for path in layout.remove_unfinished(root, dataset.name):
        log.info("removed %s: its sample was not finished", path)
    finished = layout.finished(root, dataset.name)
    todo = [i for i in range(dataset.count) if i not in finished]
    _check_disk(dataset, root, todo)
    start = time.perf_counter()
    built, failed = [], {}
    try:
        for summary in _run(dataset, root, todo, workers=workers, dask=dask, scheduler=scheduler,
                            progress=progress):
            if "error" in summary:
                failed[summary["index"]] = summary["error"]
                log.warning("sample %05d failed twice: %s", summary["index"], summary["error"])
            else:
                built.append(summary["index"])
                log.info("sample %05d  seed %d  %.1f s  %s", summary["index"], summary["seed"], summary["seconds"],
                         "  ".join(f"{k} {v:.3f}" for k, v in summary["fractions"].items()))
    finally:
        _sweep(root)  # the pool's, when it was stopped
        records = layout.finished(root, dataset.name)
        layout.write_index(root, records, name=dataset.name, labels=_labels(records))
        _write_failed(root, dataset, failed)
        _write_gallery(root, dataset, records)
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
    fractions = {names.get(k, "air" if k == "0" else k): v for k, v in stored["fractions"].items()}
    return {"index": index, "seed": drawn.seed, "seconds": time.perf_counter() - start, "fractions": fractions}


def _steady(metadata: dict) -> dict:
    """A scan's metadata without what differs between two runs of it (:data:`VOLATILE`)."""
    return {k: v for k, v in metadata.items() if k not in VOLATILE}


# -- the directory -----------------------------------------------------------------------------


def _sweep(root: Path) -> None:
    """Remove the stale temporaries (their writers gone) in ``root`` and its visible folders: a
    layout writes its samples' temporaries there (``samples/.00007.…``, ``imagesTr/.…``), never
    deeper, as a sample's own folder appears whole."""
    for folder in [root, *(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))]:
        remove_stale_temporaries_in(folder)


def _prepare(dataset: DatasetFile, directory, force: bool) -> Path:
    """The dataset directory, checked and recorded before any work (module docstring)."""
    path = Path(directory)
    root = directory_target(path, GENERATOR)
    if root.is_dir() and any(root.iterdir()):
        earlier = read_record(root / RECORD_NAME, GENERATOR)
        if earlier is None:
            raise ConfigError(f"{path} holds files that {GENERATOR} did not write (no {RECORD_NAME}); they are never "
                              "removed: choose another directory")
        changed = differences(earlier["identity"], dataset) if earlier["fingerprint"] != fingerprint(dataset) else []
        if earlier["count"] > dataset.count:
            changed.append(f"count: {earlier['count']} -> {dataset.count} (a build only grows)")
        if changed and not force:
            raise ConfigError(f"{path} holds a build of another dataset file ({'; '.join(changed)}); rerun with the "
                              "same file (count may grow), choose another directory, or pass --force to remove this "
                              "build's samples and start again")
        if changed:
            _remove_samples(root, earlier["identity"])
    root.mkdir(parents=True, exist_ok=True)
    record = {"generator": GENERATOR, "version": package_version(), "fingerprint": fingerprint(dataset),
              "count": dataset.count, "identity": identity(dataset)}
    atomic_write_text(root / RECORD_NAME, json.dumps(record, indent=2, sort_keys=True) + "\n")
    return root


def _remove_samples(root: Path, earlier: dict) -> None:
    """Remove the samples of an earlier build (``earlier``: its identity): the files its layout
    names and the folders they leave empty, nothing else."""
    layout = LAYOUTS[earlier["layout"]]
    for index, record in layout.finished(root, earlier["name"]).items():
        paths = [root / relative for relative in layout.sample_paths(index, record["split"], earlier["name"])]
        for path in paths:
            path.unlink(missing_ok=True)
        for folder in {path.parent for path in paths} - {root}:
            if not any(folder.iterdir()):
                folder.rmdir()


def _check_disk(dataset: DatasetFile, root: Path, todo: list[int]) -> None:
    """Refuse, before the first sample, a build whose remaining samples cannot fit on the disk (the
    first one's size, :func:`~.dataset_plan.sample_bytes`, times their number)."""
    if not todo:
        return
    needed = sample_bytes(draw(dataset, todo[0]).scan, dataset.keep) * len(todo)
    free = shutil.disk_usage(root).free
    if needed > free:
        raise ConfigError(f"{root}: {len(todo)} samples need about {needed / 2**30:.1f} GiB and the disk has "
                          f"{free / 2**30:.1f} GiB free; free space, choose another disk, or lower [dataset] count")


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
    """Sample ``index``, retried once; an error after that is returned, not raised."""
    for attempt in range(RETRIES + 1):
        try:
            return build_sample(dataset, root, index, threads, contexts)
        except (XrayrasterError, OSError, RuntimeError, ValueError) as exc:
            error = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            log.info("sample %05d, attempt %d: %s", index, attempt + 1, error)
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


def _on_dask(dataset, root, todo, workers, scheduler):
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise ConfigError("building on Dask needs the dask extra: pip install \"xrayraster[dask]\"") from None
    # A LocalCluster's workers share this machine; a cluster's own workers know their machines, and
    # their threads are set where they are started (docs/dataset.md).
    threads = None if scheduler else max(1, (os.cpu_count() or 1) // workers)
    cluster = None if scheduler else LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)
    client = Client(scheduler or cluster)
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
    """A pool worker: Ctrl-C is the parent's to handle (it stops the pool)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _worker_contexts(threads: int | None):
    """This process's GL and OpenCL contexts, made on its first sample. A worker sharing the machine
    (``threads``: its share of the cores) first caps the CPU threads llvmpipe and PoCL start, which
    they read once, when the first context is made; a variable the user set is left as it is."""
    global _contexts
    if _contexts is None:
        from ..gl.context import GLContext
        from ..recon.opencl import CLContext

        if threads is not None:
            os.environ.setdefault("LP_NUM_THREADS", str(threads))  # llvmpipe's rasteriser threads
            os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", str(threads))  # PoCL's CPU device
        _contexts = (GLContext(), CLContext())
    return _contexts
