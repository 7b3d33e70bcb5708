"""The plan of a dataset build (``xrayraster build --plan``): every sample's draw and its predicted
time and disk use, from the scan plan (:func:`~xrayraster.pipeline.plan.scan_estimate`), no scan run."""

from __future__ import annotations

import json

from .dataset_file import DatasetFile, draw
from .plan import scan_estimate
from .scan import BATCH_VIEWS

__all__ = ["format_plan", "plan_rows", "sample_bytes"]

#: Bytes a voxel of a sample takes on disk: the float32 volume and the uint8 labels (uncompressed;
#: the build adds the projections when it keeps them).
BYTES_PER_VOXEL = 4 + 1


def plan_rows(dataset: DatasetFile, indices=None) -> list[dict]:
    """One row per sample (of ``indices``, default all): ``index``, ``split``, ``seed``, ``values``
    (dotted key → drawn value), ``attempts``, ``seconds`` (the scan's predicted time, s) and
    ``bytes`` (:func:`sample_bytes`)."""
    rows = []
    for index in range(dataset.count) if indices is None else indices:
        d = draw(dataset, index)
        rows.append({"index": index, "split": d.split, "seed": d.seed, "values": d.values, "attempts": d.attempts,
                     "seconds": scan_estimate(d.scan, BATCH_VIEWS).seconds, "bytes": sample_bytes(d.scan, dataset.keep)})
    return rows


def sample_bytes(scan_file, keep=()) -> int:
    """A sample's bytes on disk, uncompressed: its volume and labels, and its projections (float32)
    when ``keep`` holds ``"projections"`` (meshes, when kept, are not counted: a few MB)."""
    nz, ny, nx = scan_file.volume.shape
    rows, cols = scan_file.geometry.detector_shape
    kept = 4 * scan_file.geometry.num_views * rows * cols if "projections" in keep else 0
    return nz * ny * nx * BYTES_PER_VOXEL + kept


def format_plan(rows: list[dict]) -> str:
    """The rows as a text table, one line a sample and a total line (samples per split, time, disk)."""
    keys = list(dict.fromkeys(k for row in rows for k in row["values"]))
    header = ["index", "split", "seed", "attempts", *keys, "time (s)", "disk (MiB)"]
    table = [header] + [[str(r["index"]), r["split"], str(r["seed"]), str(r["attempts"]),
                         *(_value(r["values"].get(k)) for k in keys), f"{r['seconds']:.3g}",
                         f"{r['bytes'] / 2 ** 20:.3g}"] for r in rows]
    widths = [max(len(line[i]) for line in table) for i in range(len(header))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(line, widths)).rstrip() for line in table]
    splits = {}
    for r in rows:
        splits[r["split"]] = splits.get(r["split"], 0) + 1
    seconds, size = sum(r["seconds"] for r in rows), sum(r["bytes"] for r in rows)
    lines.append(f"{len(rows)} samples ({', '.join(f'{n} {s}' for s, n in splits.items())}): about "
                 f"{seconds / 60:.3g} min of scans and {size / 2 ** 30:.3g} GiB of volumes and labels")
    return "\n".join(lines)


def _value(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
