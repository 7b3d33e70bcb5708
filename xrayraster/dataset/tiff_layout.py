"""The ``tiff`` dataset layout: a folder of TIFF stacks a sample (docs/dataset_layouts.md)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.extra_labels import EXTRA_LABEL_NAMES, write_extra_labels
from ..core.files import atomic_directory, atomic_write_text
from ..core.ownership import read_record
from .layout_shared import (LABELS_TIF, MANIFEST_CSV, SAMPLE_JSON, VOLUME_TIF, check_name, checked_names, extra_paths,
                            instance_ids, make_parent, read_json, sample_document, sample_id, stored_record, to_json,
                            visible, with_extra_files, write_extras, write_layout_manifest)
from .names import GENERATOR


@dataclass(frozen=True)
class TiffLayout:
    """``samples/00000/``: ``volume.tif`` and ``labels.tif`` (Fiji reads the voxel size in mm),
    ``sample.json`` (record and scan metadata), the extra labels as xr.scan writes them
    (``instances.tif``, uint16 here, with ``instances.json``; ``directions.tif``;
    ``centrelines.json``), and ``projections.tif`` and ``meshes/`` when kept. The directory is
    built under a hidden name and moved into place whole, ``sample.json`` its marker
    (:func:`~xrayraster.core.files.atomic_directory`)."""

    def write_sample(self, root, index, result, record, *, name, projections=None, write_meshes=None) -> dict:
        check_name(name, "dataset name")
        stored = stored_record(index, result, record)
        directory = Path(root) / "samples" / sample_id(index)
        make_parent(directory)
        with atomic_directory(directory, marker=SAMPLE_JSON, generator=GENERATOR) as tmp:
            result.volume.save(tmp / VOLUME_TIF, quicklook=False)
            result.labels.save(tmp / LABELS_TIF, quicklook=False)
            instances = None if result.instances is None else replace(result.instances, data=instance_ids(result))
            directions = None if result.directions is None else np.asarray(result.directions, np.float16)
            write_extra_labels(tmp, instances=instances, directions=directions, centrelines=result.centrelines)
            write_extras(tmp, result, projections, write_meshes)
            atomic_write_text(tmp / SAMPLE_JSON, to_json(sample_document("tiff", stored, result)))
        return stored

    def finished(self, root, name) -> dict[int, dict]:
        done = {}
        for index, directory in visible(Path(root) / "samples", r"(\d+)"):
            document = read_record(directory / SAMPLE_JSON, GENERATOR)
            if document is not None and "files" in document:  # atomic_directory adds "files" last
                done[index] = document["record"]
        return done

    def write_index(self, root, records, *, name, labels) -> None:
        write_layout_manifest(self, root, records, name, checked_names(records, labels))

    def sample_paths(self, index, split, name, extra_labels=()) -> list[str]:
        paths = [f"samples/{sample_id(index)}/{file}" for file in (VOLUME_TIF, LABELS_TIF, SAMPLE_JSON)]
        return with_extra_files(paths, self.extra_label_paths(index, split, name, extra_labels))

    def extra_label_paths(self, index, split, name, extra_labels) -> dict[str, str]:
        folder = f"samples/{sample_id(index)}"
        return extra_paths(extra_labels, lambda label: f"{folder}/{EXTRA_LABEL_NAMES[label]}", folder)  # as xr.scan's

    def index_names(self) -> list[str]:
        return [MANIFEST_CSV]

    def sample_folders(self, index, name) -> list[tuple[str, str]]:
        return [(f"samples/{sample_id(index)}", SAMPLE_JSON)]

    def scan_metadata(self, root, index, split, name) -> dict:
        return read_json(Path(root) / self.sample_paths(index, split, name)[2])["scan"]

    def remove_unfinished(self, root, name) -> list[Path]:
        return []  # the sample's folder, extras inside, appears by one rename, whole

    def read_sample(self, root, index, split, name) -> tuple[np.ndarray, np.ndarray]:
        import tifffile

        volume, labels, _ = (Path(root) / path for path in self.sample_paths(index, split, name))
        return tifffile.imread(volume), tifffile.imread(labels)
