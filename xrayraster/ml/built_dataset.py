"""A finished ``xrayraster build`` directory read lazily: which samples it holds in which split, and
each sample's volume and labels as arrays that read only what is sliced (never a whole file).

* ``tiff``: ``numpy.memmap`` views of ``volume.tif`` and ``labels.tif`` (uncompressed, contiguous:
  tifffile maps them), so a slice reads its pages.
* ``hdf5``: the ``raw`` and ``label`` datasets of ``samples/00000.h5``: a slice reads the 64³
  chunks it touches.
* ``nnunet``: nibabel's array proxies of the ``.nii.gz`` files, sliced along NIfTI's slowest axis
  (our z), so a slice decompresses up to its last z plane and keeps only its planes.

The extra labels a build's scans made (``[scan] labels``) are read the same way, from their own
files (the ``directions`` (3, z, y, x), the components first; the ``nnunet`` layout's components are
NIfTI's slowest axis, so a slice there decompresses nearly the whole file).

Arrays are indexed (z, y, x) as everywhere in xrayraster; the volume is float32 cm⁻¹, the labels
uint8 (0 background, 1 matrix, 2 weft, 3 warp, 4 and up tracers: docs/dataset_layouts.md), the
instances uint16, the directions float16 (float32 in ``nnunet``). Open files are kept per process
(a PyTorch ``DataLoader`` worker opens its own), never pickled.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.choices import DATASET_SPLITS
from ..core.errors import ConfigError
from ..dataset.layouts import LAYOUTS
from ..dataset.names import RECORD_NAME
from ..io.optional import optional_module


@dataclass(frozen=True)
class BuiltDataset:
    """The complete samples of the build in ``root`` (a build still running, or killed, shows those it
    finished): ``layout`` and ``name`` from its ``build.json``; from the samples' records, ``splits``
    (sample index → ``train``, ``val`` or ``test``), ``labels`` (label value → name, 0 background)
    and ``extra_labels`` (sample index → the extra labels stored with it, such as ``("instances",)``)."""

    root: Path
    layout: str
    name: str
    splits: dict
    labels: dict
    extra_labels: dict = field(default_factory=dict)
    _open: dict = field(default_factory=dict, compare=False, repr=False)  # (pid, index) → arrays

    @classmethod
    def open(cls, root) -> "BuiltDataset":
        root = Path(root)
        record_path = root / RECORD_NAME  # written first by a build: its layout and the dataset's name
        if not record_path.is_file():
            raise ConfigError(f"{root}: not a dataset build (no {RECORD_NAME}); build one with "
                              "`xrayraster build DATASET.toml -o DIR`")
        identity = json.loads(record_path.read_text(encoding="utf-8"))["identity"]
        records = LAYOUTS[identity["layout"]].finished(root, identity["name"])  # complete samples only
        labels = {0: "background"}
        for record in records.values():
            labels.update((int(k), v) for k, v in record.get("labels", {}).items())
        return cls(root, identity["layout"], identity["name"], {i: r["split"] for i, r in records.items()},
                   dict(sorted(labels.items())), {i: tuple(r.get("extra_labels", ())) for i, r in records.items()})

    def indices(self, split: str | None) -> list[int]:
        """The samples of ``split`` (None: all), in order; ConfigError for an unknown or empty split."""
        if split is not None and split not in DATASET_SPLITS:
            raise ConfigError(f"split must be one of {', '.join(DATASET_SPLITS)} or None (all), got {split!r}")
        chosen = sorted(i for i, s in self.splits.items() if split is None or s == split)
        if not chosen:
            counts = {s: sum(v == s for v in self.splits.values()) for s in DATASET_SPLITS}
            raise ConfigError(f"{self.root}: no sample in split {split!r} (the build's splits: {counts})")
        return chosen

    def arrays(self, index: int):
        """(volume, labels) of sample ``index``: lazy arrays (module docstring) with ``shape`` and
        ``[z0:z1, y0:y1, x0:x1]`` slicing that returns NumPy arrays."""
        key = (os.getpid(), index)
        if key not in self._open:
            paths = [self.root / p for p in LAYOUTS[self.layout].sample_paths(index, self.splits[index], self.name)]
            self._open[key] = _OPENERS[self.layout](paths)
        return self._open[key]

    def extra_label(self, index: int, label: str):
        """The extra label ``label`` (``"instances"`` or ``"directions"``) of sample ``index``: a lazy
        array as :meth:`arrays` gives, (z, y, x) or, for the directions, (3, z, y, x)."""
        key = (os.getpid(), index, label)
        if key not in self._open:
            layout = LAYOUTS[self.layout]
            path = layout.extra_label_paths(index, self.splits[index], self.name, (label,))[label]
            self._open[key] = _EXTRA_OPENERS[self.layout](self.root / path, label)
        return self._open[key]

    def __getstate__(self):
        return {**self.__dict__, "_open": {}}  # open files stay with their process


class _Transposed:
    """A NIfTI array proxy (x, y, z[, component]) seen as ([component,] z, y, x), sliced by basic
    slices only."""

    def __init__(self, proxy, dtype):
        self.proxy, self.dtype = proxy, dtype
        self.shape = tuple(proxy.shape[::-1])

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        key += (slice(None),) * (len(self.shape) - len(key))
        return np.asarray(self.proxy[key[::-1]], dtype=self.dtype).T


def _tiff(paths):
    import tifffile

    return tuple(tifffile.memmap(p, mode="r") for p in paths[:2])


def _hdf5(paths):
    h5py = optional_module("h5py", "dataset", "reading HDF5 dataset builds")
    f = h5py.File(paths[0], "r")
    return f["raw"], f["label"]


def _nnunet(paths, dtypes=(np.float32, np.uint8)):
    nib = optional_module("nibabel", "dataset", "reading nnU-Net dataset builds")
    return tuple(_Transposed(nib.load(p, keep_file_open=True).dataobj, dtype) for p, dtype in zip(paths, dtypes))


_OPENERS = {"tiff": _tiff, "hdf5": _hdf5, "nnunet": _nnunet}


def _tiff_extra(path, label):
    return _tiff([path])[0]


def _hdf5_extra(path, label):
    h5py = optional_module("h5py", "dataset", "reading HDF5 dataset builds")
    return h5py.File(path, "r")[label]  # opened again: HDF5 shares the open file in a process


def _nnunet_extra(path, label):
    return _nnunet([path], (np.uint16 if label == "instances" else np.float32,))[0]


_EXTRA_OPENERS = {"tiff": _tiff_extra, "hdf5": _hdf5_extra, "nnunet": _nnunet_extra}
