"""The ``hdf5`` dataset layout: one HDF5 file a sample (docs/dataset_layouts.md)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.extra_labels import centrelines_text
from ..core.files import atomic_write
from ..io.optional import optional_module
from .layout_shared import (EXTRAS_JSON, MANIFEST_CSV, check_name, checked_names, extra_paths,
                            extras_directory, instance_ids, remove_stray_extras, sample_document, sample_id,
                            stored_record, uint8_labels, visible, with_extra_files, write_layout_manifest)
from .manifest import json_ready
from .names import GENERATOR

INSTANCE_UNIT = "instance id (0 matrix and background; the scan metadata's instances name each)"
DIRECTION_UNIT = "x, y, z components of the unit yarn direction (0 outside the yarns)"
# HDF5: chunks of 64³ voxels (1 MiB of float32) suit patch-wise training readers. gzip 4 after the
# byte shuffle, both filters every HDF5 build has (lzf is h5py's own; Fiji, MATLAB and h5ls lack
# it). Measured on 128³ noisy float32 + uint8 labels (docs/dataset_layouts.md): 62 % of the raw
# bytes in 0.27 s, against lzf 82 % in 0.09 s and gzip 4 unshuffled 72 % in 0.48 s.
HDF5_CHUNK = 64
HDF5_FILTERS = {"compression": "gzip", "compression_opts": 4, "shuffle": True}


@dataclass(frozen=True)
class Hdf5Layout:
    """``samples/00000.h5``: datasets ``raw`` (float32, cm⁻¹) and ``label`` (uint8), z y x, and the
    extra labels ``instances`` (uint16) and ``directions`` ((3, z, y, x) float16), chunked and
    compressed (:data:`HDF5_FILTERS`), each with ``element_size_um`` and ``voxel_size_mm``
    (z, y, x), and ``centrelines``, xr.scan's JSON as a string dataset (each extra label a dataset of
    its name); the file's attributes hold the record and the scan's metadata as JSON strings. Written
    under a hidden name and renamed. Extras, and the instances' table, go to ``extras/00000/``."""

    def sample_paths(self, index, split, name, extra_labels=()) -> list[str]:
        paths = [f"samples/{sample_id(index)}.h5"]
        return with_extra_files(paths, self.extra_label_paths(index, split, name, extra_labels))

    def extra_label_paths(self, index, split, name, extra_labels) -> dict[str, str]:
        return extra_paths(extra_labels, lambda label: self.sample_paths(index, split, name)[0],
                            f"extras/{sample_id(index)}")

    def index_names(self) -> list[str]:
        return [MANIFEST_CSV]

    def sample_folders(self, index, name) -> list[tuple[str, str]]:
        return [(f"extras/{sample_id(index)}", EXTRAS_JSON)]

    def scan_metadata(self, root, index, split, name) -> dict:
        h5py = optional_module("h5py", "dataset", "reading HDF5 files")
        with h5py.File(Path(root) / self.sample_paths(index, split, name)[0], "r") as f:
            return json.loads(f.attrs["scan"])

    def remove_unfinished(self, root, name) -> list[Path]:
        # The file appears by one rename, whole; its extras, written first, may be left without it.
        return remove_stray_extras(Path(root), r"(\d+)", self.finished(root, name))

    def read_sample(self, root, index, split, name) -> tuple[np.ndarray, np.ndarray]:
        h5py = optional_module("h5py", "dataset", "reading HDF5 files")
        with h5py.File(Path(root) / self.sample_paths(index, split, name)[0], "r") as f:
            return f["raw"][()], f["label"][()]

    def write_sample(self, root, index, result, record, *, name, projections=None, write_meshes=None) -> dict:
        check_name(name, "dataset name")
        root = Path(root)
        stored = stored_record(index, result, record)
        extras_directory(root / "extras" / sample_id(index), stored, result, projections, write_meshes)
        h5py = optional_module("h5py", "dataset", "the hdf5 dataset layout")
        grid = result.volume.geometry
        arrays = {"raw": np.asarray(result.volume.data, np.float32), "label": uint8_labels(result)}
        units = {"raw": result.volume.unit, "label": "label value (0 background)"}
        if result.instances is not None:
            arrays["instances"], units["instances"] = instance_ids(result), INSTANCE_UNIT
        if result.directions is not None:
            arrays["directions"], units["directions"] = np.asarray(result.directions, np.float16), DIRECTION_UNIT
        document = sample_document("hdf5", stored, result)

        def write(tmp):
            # The oldest file format stores no object times (measured: with HDF5 1.14, libver "v108" gives
            # the root group times whatever track_times says), and every HDF5 reads it.
            with h5py.File(tmp, "w", libver="earliest") as f:
                for key, data in arrays.items():
                    chunks = tuple(min(HDF5_CHUNK, n) for n in data.shape)
                    dataset = f.create_dataset(key, data=data, chunks=chunks, track_times=False, **HDF5_FILTERS)
                    dataset.attrs["element_size_um"] = [1000.0 * v for v in grid.voxel_size]
                    dataset.attrs["voxel_size_mm"] = list(grid.voxel_size)
                    dataset.attrs["unit"] = units[key]
                for key in ("generator", "layout"):
                    f.attrs[key] = document[key]
                f.attrs["voxel_size_mm"] = list(grid.voxel_size)
                for key in ("volume_geometry", "record", "scan"):
                    f.attrs[key] = json.dumps(document[key], default=json_ready)
                if result.centrelines is not None:
                    f.create_dataset("centrelines", data=centrelines_text(result.centrelines), track_times=False)

        atomic_write(root / self.sample_paths(index, stored["split"], name)[0], write)
        return stored

    def finished(self, root, name) -> dict[int, dict]:
        h5py = optional_module("h5py", "dataset", "the hdf5 dataset layout")
        done = {}
        for index, path in visible(Path(root) / "samples", r"(\d+)\.h5"):
            try:
                with h5py.File(path, "r") as f:
                    if f.attrs.get("generator") == GENERATOR:
                        done[index] = json.loads(f.attrs["record"])
            except (OSError, KeyError, ValueError):  # not an HDF5 file of ours: not a finished sample
                continue
        return done

    def write_index(self, root, records, *, name, labels) -> None:
        write_layout_manifest(self, root, records, name, checked_names(records, labels))
