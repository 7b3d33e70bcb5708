"""Dataset builds: samples per hour at 128³ and 256³ with 1 and 2 workers and on Dask, and where a sample's time goes.

    python -m scripts.bench_dataset            # 128³: 8 samples a mode; 256³: 4 a mode (~8 min on 2 cores)
    python -m scripts.bench_dataset --quick    # 128³ only, 4 samples, one worker (~40 s)
    python -m scripts.bench_dataset --workers 1 8 --samples 32 16   # a bigger machine: pools of 1 and 8
    python -m scripts.bench_dataset --sizes 128 --samples 24 0      # 128³ only, 24 samples a mode

The samples are the reference twin's small version (``examples/twin_small.toml``: 2 × 2 woven
cells, 20 × 20 × 4 mm, 40 kV) with its kV, exposure and weave seed drawn per sample:

* **128³**: 180 views of 128² pixels (0.539 mm, 231 µm at the axis) onto 128³ voxels of 0.231 mm;
* **256³**: 360 views of 256² pixels (0.270 mm) onto 256³ voxels of 0.116 mm.

Each size is built from scratch as ``xrayraster build`` builds it (``xr.build``), in each mode:
one worker (this process), a pool of two workers (``workers=2``, one thread each), and a Dask
``LocalCluster`` of two worker processes (``dask=True``). ``--workers`` sets the pool sizes (the
Dask cluster takes the largest) and ``--samples`` the samples a mode builds at 128³ and 256³, for a
machine with more cores than this one's two. Samples per hour are the samples over the
build's wall time, start-up of the pool or cluster included; *steady* samples per hour leave
that start-up out, as a build of thousands of samples does: the samples finished after each
worker's first, over the time since the last of those first ones finished. The stages of a sample (sample
meshing, projections, FDK, labels: ``scan.json``'s ``seconds``) are those of ``xr.scan`` run on the
first draws in this process after one warm-up sample.

Error: a build's files must not depend on how it ran, so the figure beside each time is the
largest absolute difference (cm⁻¹) between its volumes and the one-worker build's, sample by
sample (0: the same bytes; every file is also hashed and compared).
"""

from __future__ import annotations

import hashlib
import logging
import shutil
import time
from pathlib import Path

import numpy as np
import tifffile

import xrayraster as xr
from xrayraster.dataset import draw, load_dataset_file

from .common import OUT, ROOT, announce, conclude, outputs, parser, pyplot, say

SIZES = {  # name: (views, detector pixels across, pixel size mm, voxels across, voxel size mm, samples)
    "128": (180, 128, 0.539467, 128, 0.2312, 8),
    "256": (360, 256, 0.2697335, 256, 0.1156, 4),
}


def modes(workers: list[int]) -> dict[str, dict]:
    """Build options by mode name: a pool of each size in ``workers`` (1: this process), then Dask with the largest."""
    out = {f"{n} worker{'s' * (n > 1)}": {"workers": n} for n in workers}
    return {**out, f"Dask, {max(workers)} workers": {"workers": max(workers), "dask": True}}


def dataset_table(size: str, count: int) -> dict:
    views, pixels, pitch, voxels, voxel, _ = SIZES[size]
    return {
        "base": str(ROOT / "examples" / "twin_small.toml"),
        "dataset": {"count": count, "seed": 2026, "name": f"bench{size}"},
        "vary": {
            "geometry.num_views": views, "geometry.detector_shape": [pixels, pixels], "geometry.pixel_size": pitch,
            "volume.shape": [voxels] * 3, "volume.voxel_size": voxel,
            "source.kvp": {"uniform": [38.0, 42.0]}, "source.mas": {"loguniform": [1.1, 1.4]},
        },
    }


class Finishes(logging.Handler):
    """When each sample of a build finished: the build's log line of a finished sample."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.times: list[float] = []

    def emit(self, record: logging.LogRecord) -> None:
        if str(record.msg).startswith("sample %05d  seed"):
            self.times.append(time.perf_counter())


def build_timed(dataset, out: Path, options: dict) -> tuple[float, float | None]:
    """Build; (wall s, steady samples per hour or None when no worker made a second sample)."""
    logger, finishes = logging.getLogger("xrayraster"), Finishes()
    level = logger.level
    logger.addHandler(finishes)
    logger.setLevel(logging.INFO)
    try:
        start = time.perf_counter()
        report = xr.build(dataset, out, **options)
        wall = time.perf_counter() - start
    finally:
        logger.removeHandler(finishes)
        logger.setLevel(level)
    assert not report.failed, report.failed
    first = options.get("workers", 1)  # each worker's first sample carries its start-up
    times = finishes.times
    steady = 3600 * (len(times) - first) / (times[-1] - times[first - 1]) if len(times) > first else None
    return wall, steady


def hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def volumes(root: Path, count: int) -> list[np.ndarray]:
    return [tifffile.imread(root / "samples" / f"{i:05d}" / "volume.tif") for i in range(count)]


def stages(dataset, count: int) -> dict:
    """Mean seconds a sample spends in each stage of ``xr.scan``, over ``count`` draws after a warm-up."""
    xr.scan(draw(dataset, 0).scan)
    totals = {}
    for index in range(count):
        for stage, seconds in xr.scan(draw(dataset, index).scan).metadata["seconds"].items():
            totals[stage] = totals.get(stage, 0.0) + seconds / count
    return totals


def main(argv=None) -> None:
    ap = parser(__doc__, "128³ only, 4 samples, one worker (~40 s)", plots=True)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2], metavar="N",
                    help="pool sizes to measure (default 1 2); Dask runs with the largest")
    ap.add_argument("--samples", type=int, nargs=2, metavar=("N128", "N256"),
                    help=f"samples a mode builds at 128³ and 256³ (default {SIZES['128'][-1]} {SIZES['256'][-1]})")
    ap.add_argument("--sizes", nargs="+", choices=list(SIZES), default=list(SIZES), help="sizes to build (default both)")
    args = outputs(ap.parse_args(argv), "bench_dataset")
    t_start = time.perf_counter()
    command, machine = announce()
    sizes = ["128"] if args.quick else args.sizes
    runs = {"1 worker": {"workers": 1}} if args.quick else modes(args.workers)
    rows, split = [], {}
    say(f"{'size':>5} {'mode':>16} {'samples':>8} {'wall s':>8} {'samples/h':>10} {'steady /h':>10} "
        f"{'max |dmu| 1/cm':>16} {'same bytes':>11}")
    for size in sizes:
        count = 4 if args.quick else args.samples[list(SIZES).index(size)] if args.samples else SIZES[size][-1]
        dataset = load_dataset_file(dataset_table(size, count), base_dir=ROOT)
        reference = None
        for mode, options in runs.items():
            out = OUT / "bench_dataset" / f"{size}_{mode.replace(' ', '_').replace(',', '')}"
            shutil.rmtree(out, ignore_errors=True)
            wall, steady = build_timed(dataset, out, options)
            made = volumes(out, count)
            reference = reference or (out, made)
            diff = max(float(np.abs(a - b).max()) for a, b in zip(made, reference[1]))
            same = {k: v for k, v in hashes(out).items() if k != "build.json"} == \
                {k: v for k, v in hashes(reference[0]).items() if k != "build.json"}
            rows.append({"size": size, "mode": mode, "samples": count, "wall_s": wall,
                         "samples_per_hour": 3600 * count / wall, "steady_samples_per_hour": steady,
                         "max_abs_diff_per_cm": diff, "same_bytes": same})
            say(f"{size:>5} {mode:>16} {count:>8} {wall:>8.1f} {3600 * count / wall:>10.0f} "
                f"{'-' if steady is None else f'{steady:.0f}':>10} {diff:>16.3g} {str(same):>11}")
        split[size] = stages(dataset, min(count, 3))
        say(f"{size:>5} a sample's stages (s): " + ", ".join(f"{k} {v:.2f}" for k, v in split[size].items()))
    plot(rows, args.plots_dir)
    conclude(args.json, {"command": command, "machine": machine, "rows": rows, "stages_s": split}, machine, t_start)


def plot(rows: list[dict], folder: Path) -> None:
    plt = pyplot()
    if plt is None:
        return
    sizes = list(dict.fromkeys(r["size"] for r in rows))
    fig, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 3.6), squeeze=False)
    for ax, size in zip(axes[0], sizes):
        mine = [r for r in rows if r["size"] == size]
        ax.bar([r["mode"] for r in mine], [r["samples_per_hour"] for r in mine], color="C0")
        for i, r in enumerate(mine):
            steady = "" if r["steady_samples_per_hour"] is None else f"\nsteady {r['steady_samples_per_hour']:.0f}/h"
            ax.text(i, r["samples_per_hour"], f"{r['samples_per_hour']:.0f}/h{steady}\n|Δμ| {r['max_abs_diff_per_cm']:.0g}",
                    ha="center", va="bottom", fontsize=8)
        ax.set_title(f"{size}³ voxels", fontsize=10)
        ax.set_ylabel("samples per hour")
        ax.margins(y=0.25)
    fig.suptitle("xrayraster build on this machine (|Δμ|: largest difference from the 1-worker build, cm⁻¹)",
                 fontsize=9)
    fig.tight_layout()
    folder.mkdir(parents=True, exist_ok=True)
    fig.savefig(folder / "bench_dataset.png", dpi=100)
    say(f"plot: {folder / 'bench_dataset.png'}")


if __name__ == "__main__":
    main()
