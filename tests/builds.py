"""Dataset builds written without rendering, as `xrayraster build` leaves them, for the tests of
their readers (xr.ml) and of hostile builds: volumes whose voxels encode their own index, so a
crop is checked exactly, and labels mostly background with a few percent of 1, 2 and 3; with
``extra_labels``, also instance ids that encode their voxel too (above 255, so uint16 shows) and
unit directions that change from voxel to voxel on the yarns (labels 2 and 3), 0 elsewhere. Also a
stand-in for xr.scan with the same arrays (:func:`fake_scan`), and what tests of the files read."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

import xrayraster as xr
from xrayraster.dataset.layouts import LAYOUTS
from xrayraster.pipeline.scan import ScanResult

NAME = "Twin"
LABELS = {1: "matrix", 2: "weft", 3: "warp"}
SHAPES = [(30, 34, 38), (36, 30, 32), (32, 40, 30), (28, 36, 34), (34, 34, 34)]
SPLITS = ["train", "train", "val", "train", "test"]


def coded(shape, index: int) -> np.ndarray:
    """Each voxel's value says where it is: z·4096 + y·64 + x + 300000·sample (exact in float32)."""
    z, y, x = np.indices(shape)
    return (z * 4096 + y * 64 + x + 300_000 * index).astype(np.float32)


def layered(shape) -> np.ndarray:
    """Mostly background (0) with a few percent of 1, 2 and 3: the skew class balancing is for."""
    z, y, x = np.indices(shape)
    labels = np.zeros(shape, np.uint8)
    labels[(z % 6 == 0) & (y > 4)] = 1
    labels[(x % 9 == 2) & (z % 6 == 3)] = 2
    labels[(y % 11 == 5) & (x % 5 == 1) & (z > 3)] = 3
    return labels


def instance_ids(shape) -> np.ndarray:
    """uint16 ids on the yarn voxels (labels 2 and 3) that say where they are, up to 1000; 0 elsewhere."""
    z, y, x = np.indices(shape)
    return np.where(layered(shape) >= 2, 1 + (z * 97 + y * 31 + x) % 1000, 0).astype(np.uint16)


def unit_directions(shape) -> np.ndarray:
    """(3, z, y, x) float16 unit vectors (x, y, z components) that turn from voxel to voxel on the
    yarns (labels 2 and 3), 0 elsewhere."""
    z, y, x = np.indices(shape)
    vectors = np.stack([np.cos(0.3 * x), np.sin(0.3 * x) * np.cos(0.2 * y), np.sin(0.3 * x) * np.sin(0.2 * y)])
    return np.where(layered(shape) >= 2, vectors, 0.0).astype(np.float16)


CENTRELINES = {"units": "mm", "frame": "scanner", "step_mm": 0.05, "yarns": [
    {"name": "yarn_1", "family": "weft", "kind": "weft", "points": [[0.1, 0.2, 0.3], [0.2, 0.2, 0.3]]},
    {"name": "yarn_2", "family": "warp", "kind": "binder", "points": [[0.0, 0.5, 0.3], [0.0, 0.6, 0.5]]}]}


def scan_result(grid, index: int = 0, extra_labels=()) -> ScanResult:
    """What xr.scan returns, on ``grid`` (a VolumeGeometry): the :func:`coded` volume of sample
    ``index``, :func:`layered` labels, and the ``extra_labels`` named (of "instances",
    "directions", "centrelines": :func:`instance_ids` with their id → yarn table in the metadata,
    :func:`unit_directions`, :data:`CENTRELINES`)."""
    shape, metadata = grid.shape, {"generator": "xrayraster scan"}
    extras = {"instances": xr.LabelVolume(instance_ids(shape), grid), "directions": unit_directions(shape),
              "centrelines": CENTRELINES}
    if "instances" in extra_labels:
        ids = np.unique(instance_ids(shape)).tolist()[1:]  # 0 aside
        metadata["instances"] = {str(i): {"name": f"yarn_{i}", "family": "weft", "kind": "weft", "index": i - 1,
                                          "material": "weft_carbon"} for i in ids}
    return ScanResult(xr.Volume(coded(shape, index), grid), xr.LabelVolume(layered(shape), grid), metadata,
                      **{label: extras[label] for label in extra_labels})


def fake_scan(loaded, **_):
    """A quick stand-in for xr.scan of a drawn scan file: :func:`scan_result` on its grid, the
    sample told apart by its seed, with the extra labels it asks for, and the metadata a build
    reads (the scan file named as xr.scan names it, the label names)."""
    result = scan_result(loaded.volume, loaded.options.seed % 1000, loaded.options.labels[1:])
    labels = {"0": "background", **{str(k): v for k, v in LABELS.items()}}
    return dataclasses.replace(result, metadata={**result.metadata, "scan_file": str(loaded.path), "labels": labels,
                                                 "seed": loaded.options.seed})


def write_build(root: Path, layout: str, shapes=SHAPES, splits=SPLITS, extra_labels=()) -> Path:
    """A build directory as `xrayraster build` leaves it: build.json, then the samples, each with
    the ``extra_labels`` named (:func:`scan_result`)."""
    root.mkdir(parents=True)
    (root / "build.json").write_text(json.dumps({"generator": "xrayraster build", "identity": {"layout": layout,
                                                                                                 "name": NAME}}))
    for index, (shape, split) in enumerate(zip(shapes, splits)):
        result = scan_result(xr.VolumeGeometry(shape, 0.1), index, extra_labels)
        record = {"split": split, "seed": index, "values": {}, "labels": {str(k): v for k, v in LABELS.items()}}
        LAYOUTS[layout].write_sample(root, index, result, record, name=NAME)
    return root


def visible_files(root: Path) -> list[str]:
    """Every file under ``root`` whose path has no hidden part, relative and sorted."""
    found = []
    for directory, dirs, names in os.walk(root):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        found += [str((Path(directory) / n).relative_to(root)) for n in names if not n.startswith(".")]
    return sorted(found)


def all_entries(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))
