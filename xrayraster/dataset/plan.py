"""The plan of a dataset build (``xrayraster build --plan``): every sample's draw and its predicted
time and disk use, from the scan plan (:class:`~xrayraster.pipeline.plan.ScanJob`), no scan run.

A draw costs about 0.4 s (most of it the tube spectrum), so a plan is streamed, a line a sample as
it is drawn (:func:`plan_lines`), and a plan of more than :data:`PLAN_DRAWS` samples draws only the
first ones and extrapolates its totals: 100,000 samples would take ten hours to draw. Each drawn
sample is refused as its scan would refuse it (:func:`check_sample`: more memory than the machine
has), so a plan passes only what a build can make.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

from ..core.errors import ConfigError
from ..core.estimate import plan
from ..pipeline.plan import ScanJob
from ..pipeline.scan import BATCH_VIEWS
from .dataset_file import DatasetFile, draw

__all__ = ["PLAN_DRAWS", "check_sample", "format_plan", "plan_lines", "plan_rows", "sample_bytes"]

#: Bytes a voxel of a sample takes on disk: the float32 volume and the uint8 labels (uncompressed;
#: the build adds the projections when it keeps them).
BYTES_PER_VOXEL = 4 + 1
#: And those of each extra label a scan file asks for (``[scan] labels``), as the tiff and hdf5
#: layouts store them uncompressed: uint16 instance ids, three float16 direction components (the
#: nnunet layout's float32 ones are gzipped, zero outside the yarns); centre lines take a few kB.
EXTRA_BYTES_PER_VOXEL = {"instances": 2, "directions": 3 * 2, "centrelines": 0}
#: The most samples ``--plan`` draws (about 20 s of draws); a larger count's totals are extrapolated
#: from these, the first samples, which a build makes first.
PLAN_DRAWS = 50


def check_sample(scan_file):
    """The scan plan (:class:`~xrayraster.core.estimate.Estimate`) of a drawn sample, refused as
    ``xr.scan`` would refuse it, before any work: ConfigError naming the key, when its scan cannot
    fit in the memory available."""
    return plan(ScanJob(scan_file, BATCH_VIEWS), ConfigError, f"{scan_file.path} ")


def plan_rows(dataset: DatasetFile, indices=None) -> list[dict]:
    """One row per sample (of ``indices``, default all): ``index``, ``split``, ``seed``, ``values``
    (dotted key → drawn value), ``attempts``, ``seconds`` (the scan's predicted time, s) and
    ``bytes`` (:func:`sample_bytes`). A sample whose scan cannot fit in memory is refused."""
    return [plan_row(dataset, index) for index in (range(dataset.count) if indices is None else indices)]


def plan_row(dataset: DatasetFile, index: int) -> dict:
    """Sample ``index``'s row of :func:`plan_rows`."""
    d = draw(dataset, index)
    return {"index": index, "split": d.split, "seed": d.seed, "values": d.values, "attempts": d.attempts,
            "seconds": check_sample(d.scan).seconds, "bytes": sample_bytes(d.scan, dataset.keep)}


def sample_bytes(scan_file, keep=()) -> int:
    """A sample's bytes on disk, uncompressed: its volume, labels and extra labels, and its
    projections (float32) when ``keep`` holds ``"projections"`` (meshes, when kept, are not
    counted: a few MB)."""
    nz, ny, nx = scan_file.volume.shape
    rows, cols = scan_file.geometry.detector_shape
    kept = 4 * scan_file.geometry.num_views * rows * cols if "projections" in keep else 0
    per_voxel = BYTES_PER_VOXEL + sum(EXTRA_BYTES_PER_VOXEL[label] for label in scan_file.options.labels[1:])
    return nz * ny * nx * per_voxel + kept


def format_plan(rows: list[dict]) -> str:
    """The rows as a text table, one line a sample and a total line (samples per split, time, disk)."""
    keys = list(dict.fromkeys(k for row in rows for k in row["values"]))
    table = [_header(keys)] + [_cells(r, keys) for r in rows]
    widths = [max(len(line[i]) for line in table) for i in range(len(table[0]))]
    return "\n".join([_line(line, widths) for line in table] + [_total(rows, len(rows))])


def plan_lines(dataset: DatasetFile) -> Iterator[str]:
    """The plan of :func:`format_plan`, a line at a time, each sample's as soon as it is drawn (the
    columns sized by the first sample): for a count above :data:`PLAN_DRAWS`, the first
    :data:`PLAN_DRAWS` samples, then the totals extrapolated to the count."""
    keys = list(dataset.vary)  # every draw's values are keyed by these
    widths = None
    rows = []
    for index in range(min(dataset.count, PLAN_DRAWS)):
        rows.append(plan_row(dataset, index))
        cells = _cells(rows[-1], keys)
        if widths is None:
            widths = [max(len(h), len(c)) for h, c in zip(_header(keys), cells)]
            yield _line(_header(keys), widths)
        yield _line(cells, widths)
    yield _total(rows, dataset.count)


def _header(keys) -> list[str]:
    return ["index", "split", "seed", "attempts", *keys, "time (s)", "disk (MiB)"]


def _cells(row: dict, keys) -> list[str]:
    return [str(row["index"]), row["split"], str(row["seed"]), str(row["attempts"]),
            *(_value(row["values"].get(k)) for k in keys), f"{row['seconds']:.3g}", f"{row['bytes'] / 2 ** 20:.3g}"]


def _line(cells, widths) -> str:
    return "  ".join(cell.ljust(w) for cell, w in zip(cells, widths)).rstrip()


def _total(rows: list[dict], count: int) -> str:
    """The total line of ``rows``; when they are the first of ``count`` samples, their mean times
    ``count``, saying so."""
    splits = {}
    for r in rows:
        splits[r["split"]] = splits.get(r["split"], 0) + 1
    scale = count / len(rows) if rows else 0.0
    seconds, size = scale * sum(r["seconds"] for r in rows), scale * sum(r["bytes"] for r in rows)
    drawn = f"{len(rows)} samples ({', '.join(f'{n} {s}' for s, n in splits.items())})"
    if count == len(rows):
        return f"{drawn}: about {seconds / 60:.3g} min of scans and {size / 2 ** 30:.3g} GiB of volumes and labels"
    return (f"{count} samples, estimated from the first {drawn}: about {seconds / 60:.3g} min of scans and "
            f"{size / 2 ** 30:.3g} GiB of volumes and labels; the other {count - len(rows)} are drawn and checked "
            "as the build reaches them")


def _value(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
