"""Dataset builds written without rendering, as `xrayraster build` leaves them, for the tests of
their readers (xr.ml) and of hostile builds: volumes whose voxels encode their own index, so a
crop is checked exactly, and labels mostly background with a few percent of 1, 2 and 3."""

from __future__ import annotations

import json
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


def write_build(root: Path, layout: str, shapes=SHAPES, splits=SPLITS) -> Path:
    """A build directory as `xrayraster build` leaves it: build.json, then the samples."""
    root.mkdir(parents=True)
    (root / "build.json").write_text(json.dumps({"generator": "xrayraster build", "identity": {"layout": layout,
                                                                                                 "name": NAME}}))
    for index, (shape, split) in enumerate(zip(shapes, splits)):
        grid = xr.VolumeGeometry(shape, 0.1)
        result = ScanResult(xr.Volume(coded(shape, index), grid), xr.LabelVolume(layered(shape), grid),
                            {"generator": "xrayraster scan"})
        record = {"split": split, "seed": index, "values": {}, "labels": {str(k): v for k, v in LABELS.items()}}
        LAYOUTS[layout].write_sample(root, index, result, record, name=NAME)
    return root
