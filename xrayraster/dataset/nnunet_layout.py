"""The ``nnunet`` dataset layout: nnU-Net v2's raw dataset of NIfTI files (docs/dataset_layouts.md)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..core.choices import DATASET_SPLITS, LABEL_EXTRAS
from ..core.errors import ConfigError
from ..core.extra_labels import centrelines_text
from ..core.files import atomic_write_text, atomic_writes
from ..core.ownership import read_record
from ..io.optional import optional_module
from .layout_shared import (EXTRAS_JSON, MANIFEST_CSV, check_name, checked_names, extra_paths, extras_directory,
                            instance_ids, read_json, remove_stray_extras, sample_document, sample_id, stored_record,
                            to_json, uint8_labels, visible, with_extra_files, write_layout_manifest)
from .names import GENERATOR
from .nifti import nifti_writer

if TYPE_CHECKING:
    from .layout_shared import ScanOutput

TRAINING_SPLITS = ("train", "val")  # nnU-Net trains (and cross-validates) on these; "test" is held out
DATASET_JSON, SPLITS_JSON = "dataset.json", "splits_final.json"
#: The nnunet layout's file ending of each extra label (its folder is the label's name and Tr or Ts).
NNUNET_ENDINGS = {"instances": ".nii.gz", "directions": ".nii.gz", "centrelines": ".json"}


def _part(split: str) -> str:
    """nnU-Net's folder suffix of a split: ``Tr`` for the samples it trains on, ``Ts`` for test."""
    return "Tr" if split in TRAINING_SPLITS else "Ts"


def _nifti_extra_writers(result: ScanOutput) -> dict[str, Callable[[str], None]]:
    """The nnunet layout's writer of each extra label ``result`` holds (the instances' table is in
    the sample's folder): NIfTI volumes on the labels' grid and affine, the centre lines' JSON."""
    grid, writers = result.volume.geometry, {}
    if result.instances is not None:
        writers["instances"] = nifti_writer(instance_ids(result), grid, description=GENERATOR)
    if result.directions is not None:  # (3, z, y, x) → NIfTI's x, y, z, component
        writers["directions"] = nifti_writer(np.asarray(result.directions, np.float32), grid, description=GENERATOR)
    if result.centrelines is not None:
        writers["centrelines"] = _text_writer(centrelines_text(result.centrelines))
    return writers


def _text_writer(text: str) -> Callable[[str], None]:
    """``write(path)`` of ``text`` (UTF-8), for :func:`~xrayraster.core.files.atomic_writes`."""
    return lambda tmp: Path(tmp).write_text(text, encoding="utf-8")


@dataclass(frozen=True)
class NnunetLayout:
    """nnU-Net v2's raw dataset: ``imagesTr/NAME_00000_0000.nii.gz`` and ``labelsTr/NAME_00000.nii.gz``
    for the train and val splits, ``imagesTs``/``labelsTs`` for test, ``records/NAME_00000.json``
    (record and scan metadata, written last: a sample is complete when it is there), and
    ``extras/NAME_00000/`` for projections, meshes and the instances' table. The extra labels go
    beside, in folders nnU-Net never reads, split as the images: ``instancesTr/NAME_00000.nii.gz``
    (uint16), ``directionsTr/NAME_00000.nii.gz`` (float32, x y z and the 3 components: NIfTI-1
    has no float16) and ``centrelinesTr/NAME_00000.json``. :meth:`write_index` writes
    ``dataset.json`` and ``splits_final.json`` (the build's train/val split as nnU-Net's one fold)."""

    def case(self, index: int, name: str) -> str:
        """nnU-Net's case identifier of sample ``index``."""
        return f"{name}_{sample_id(index)}"

    def sample_paths(self, index, split, name, extra_labels=()) -> list[str]:
        case, part = self.case(index, name), _part(split)
        paths = [f"images{part}/{case}_0000.nii.gz", f"labels{part}/{case}.nii.gz", f"records/{case}.json"]
        return with_extra_files(paths, self.extra_label_paths(index, split, name, extra_labels))

    def extra_label_paths(self, index, split, name, extra_labels) -> dict[str, str]:
        case, part = self.case(index, name), _part(split)
        return extra_paths(extra_labels, lambda label: f"{label}{part}/{case}{NNUNET_ENDINGS[label]}",
                            f"extras/{case}")

    def index_names(self) -> list[str]:
        return [MANIFEST_CSV, SPLITS_JSON, DATASET_JSON]

    def sample_folders(self, index, name) -> list[tuple[str, str]]:
        return [(f"extras/{self.case(index, name)}", EXTRAS_JSON)]

    def scan_metadata(self, root, index, split, name) -> dict:
        return read_json(Path(root) / self.sample_paths(index, split, name)[2])["scan"]

    def remove_unfinished(self, root, name) -> list[Path]:
        # A sample's image, labels and record are renamed into place one after another, the record
        # last: a kill between the renames leaves an image or labels whose case has no record.
        root, done = Path(root), self.finished(root, name)
        pattern = rf"{re.escape(name)}_(\d+)(?:_0000)?(?:\.nii\.gz|\.json)"
        stray = [path for kind in ("images", "labels", *LABEL_EXTRAS) for part in ("Tr", "Ts")
                 for index, path in visible(root / f"{kind}{part}", pattern) if index not in done]
        for path in stray:
            path.unlink()
        return stray + remove_stray_extras(root, rf"{re.escape(name)}_(\d+)", done)

    def read_sample(self, root, index, split, name) -> tuple[np.ndarray, np.ndarray]:
        nib = optional_module("nibabel", "dataset", "reading NIfTI files")
        image, label, _ = (Path(root) / path for path in self.sample_paths(index, split, name))
        return (np.asarray(nib.load(image).dataobj, np.float32).T, np.asarray(nib.load(label).dataobj, np.uint8).T)

    def write_sample(self, root, index, result, record, *, name, projections=None, write_meshes=None) -> dict:
        check_name(name, "dataset name")
        root = Path(root)
        stored = stored_record(index, result, record)
        grid, split, extra_labels = result.volume.geometry, stored["split"], result.extra_labels
        extras_directory(root / "extras" / self.case(index, name), stored, result, projections, write_meshes)
        image, label, record_path = (root / path for path in self.sample_paths(index, split, name))
        extra = self.extra_label_paths(index, split, name, extra_labels)
        document = to_json({**sample_document("nnunet", stored, result), "files": self.sample_paths(index, split, name,
                                                                                              extra_labels)})
        atomic_writes([
            (image, nifti_writer(np.asarray(result.volume.data, np.float32), grid, description=GENERATOR)),
            (label, nifti_writer(uint8_labels(result), grid, description=GENERATOR)),
            *((root / extra[label], write) for label, write in _nifti_extra_writers(result).items()),
            (record_path, _text_writer(document)),
        ])
        return stored

    def finished(self, root, name) -> dict[int, dict]:
        check_name(name, "dataset name")
        root = Path(root)
        done = {}
        for index, path in visible(root / "records", rf"{re.escape(name)}_(\d+)\.json"):
            document = read_record(path, GENERATOR)
            # The record is renamed into place last; the images are checked too, as a person may
            # have removed one since.
            if document is not None and all((root / p).is_file() for p in document.get("files", ())):
                done[index] = document["record"]
        return done

    def write_index(self, root, records, *, name, labels) -> None:
        check_name(name, "dataset name")
        root = Path(root)
        names = checked_names(records, labels)
        if sorted(names) != list(range(len(names))):
            raise ConfigError(f"nnU-Net needs consecutive labels 0, 1, 2, ...; the build's are {sorted(names)}")
        cases = {split: [self.case(i, name) for i in sorted(records) if records[i]["split"] == split]
                 for split in DATASET_SPLITS}
        dataset = {
            "name": name,
            "description": f"written by {GENERATOR}; one CT channel, linear attenuation in 1/cm",
            "generator": GENERATOR,
            "channel_names": {"0": "CT"},  # nnU-Net's CT normalisation: clip to foreground percentiles, z-score
            "labels": {("background" if label == 0 else names[label]): label for label in sorted(names)},
            "numTraining": len(cases["train"]) + len(cases["val"]),
            "file_ending": ".nii.gz",
        }
        write_layout_manifest(self, root, records, name, names)
        atomic_write_text(root / SPLITS_JSON, to_json([{"train": cases["train"], "val": cases["val"]}]))
        atomic_write_text(root / DATASET_JSON, to_json(dataset))
