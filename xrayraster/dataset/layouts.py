"""Where a dataset build puts its samples on disk: the ``tiff``, ``nnunet`` and ``hdf5`` layouts
(docs/dataset_layouts.md), one object each in :data:`LAYOUTS`, all with the same four methods
(:class:`DatasetLayout`).

The build's runner calls them from worker processes, one sample at a time, several at once,
possibly on other machines sharing the file system, and may be killed at any moment. So every
sample is written atomically: when :meth:`~DatasetLayout.write_sample` returns, the sample is
complete; before, nothing of it looks complete to :meth:`~DatasetLayout.finished`, and writing it
again replaces whatever a killed writer left. Workers never write the same file: each sample has
its own names, and the index files (``manifest.csv``, nnU-Net's ``dataset.json``) are written by
:meth:`~DatasetLayout.write_index`, once, by the runner. The same inputs give the same bytes (no
time stamps, no temporary names inside the files).

The build directory ``root`` is the runner's: it checks, before the build, that ``root`` is empty
or an earlier build's (docs/outputs.md); these writers then replace only their own names in it.

A sample's *record* is what the runner passes (``split``, ``seed``, the drawn ``values`` by dotted
key and anything else JSON-ready, nothing that varies between runs) completed by
:func:`stored_record` (``index``, the label ``fractions``, and the ``extra_labels`` the scan made);
:meth:`~DatasetLayout.finished` gives it back for every complete sample, so the runner can rebuild
the manifest from the disk alone.

A scan's extra labels (``[scan] labels``: instances, directions, centre lines; docs/labels.md) are
stored beside its volume and classes, in every layout, by the same atomic writes: the instance ids
as uint16 in every sample, the directions as (3, z, y, x) float16 (float32 in NIfTI, which has no
float16), the centre lines as xr.scan's JSON, and the instances' id → yarn table as
``instances.json`` in the sample's folder (:meth:`~DatasetLayout.sample_folders`), which the
manifest's ``instance_table`` column names. A scan without them is stored as it always was, byte for byte.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Protocol

import numpy as np

from ..core.choices import DATASET_SPLITS, LABEL_EXTRAS
from ..core.errors import ConfigError
from ..core.extra_labels import EXTRA_LABEL_NAMES, centrelines_text, write_extra_labels
from ..core.files import atomic_directory, atomic_write, atomic_write_text, atomic_writes
from ..core.ownership import read_record
from ..io.optional import optional_module
from .manifest import json_ready, write_manifest
from .names import GENERATOR
from .nifti import nifti_writer

if TYPE_CHECKING:
    from ..core.projections import Projections
    from ..gl.voxelize import LabelVolume
    from ..recon.volume import Volume

TRAINING_SPLITS = ("train", "val")  # nnU-Net trains (and cross-validates) on these; "test" is held out
MAX_LABEL = 255  # labels are stored as uint8
SAMPLE_JSON, EXTRAS_JSON, MANIFEST_CSV = "sample.json", "extras.json", "manifest.csv"
DATASET_JSON, SPLITS_JSON = "dataset.json", "splits_final.json"
VOLUME_TIF, LABELS_TIF, PROJECTIONS_TIF, MESHES = "volume.tif", "labels.tif", "projections.tif", "meshes"
#: The instances' id → yarn table, in a sample's folder, and its key among a sample's extra files.
INSTANCES_JSON, INSTANCE_TABLE = "instances.json", "instance_table"
#: The nnunet layout's file ending of each extra label (its folder is the label's name and Tr or Ts).
NNUNET_ENDINGS = {"instances": ".nii.gz", "directions": ".nii.gz", "centrelines": ".json"}
INSTANCE_UNIT = "instance id (0 matrix and background; the scan metadata's instances name each)"
DIRECTION_UNIT = "x, y, z components of the unit yarn direction (0 outside the yarns)"
# HDF5: chunks of 64³ voxels (1 MiB of float32) suit patch-wise training readers. gzip 4 after the
# byte shuffle, both filters every HDF5 build has (lzf is h5py's own; Fiji, MATLAB and h5ls lack
# it). Measured on 128³ noisy float32 + uint8 labels (docs/dataset_layouts.md): 62 % of the raw
# bytes in 0.27 s, against lzf 82 % in 0.09 s and gzip 4 unshuffled 72 % in 0.48 s.
HDF5_CHUNK = 64
HDF5_FILTERS = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
# A dataset's name starts the samples' file names (nnU-Net's NAME_00000_0000.nii.gz): letters, digits
# and underscores (as dataset files always required), the first not an underscore (a leading "_"
# reads as a hidden name to some tools). The one rule of the dataset file, --plan and every layout.
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_]*")
NAME_RULE = "letters, digits and underscores, the first a letter or digit (it starts the samples' file names)"


class ScanOutput(Protocol):
    """What a layout stores of a scan: an :class:`xrayraster.ScanResult` is one. Its extra labels
    (``instances``, ``directions``, ``centrelines``) are None where the scan made none;
    ``metadata["instances"]`` names each instance id's yarn."""

    volume: Volume
    labels: LabelVolume
    metadata: dict
    instances: LabelVolume | None
    directions: np.ndarray | None
    centrelines: dict | None

    @property
    def extra_labels(self) -> tuple[str, ...]:
        """The extra labels held (of :data:`~xrayraster.core.choices.LABEL_EXTRAS`)."""


class DatasetLayout(Protocol):
    """The on-disk layout of a dataset build (module docstring). ``name`` is the dataset's name,
    the prefix of nnU-Net's case names (:data:`NAME_RULE`)."""

    def write_sample(self, root: Path, index: int, result: ScanOutput, record: dict, *, name: str,
                     projections: Projections | None = None,
                     write_meshes: Callable[[Path], None] | None = None) -> dict:
        """Write sample ``index`` atomically: its volume, labels, extra labels (those ``result``
        holds) and :func:`stored_record`, and, when given, its ``projections`` and the meshes
        ``write_meshes(directory)`` writes. Returns the stored record."""

    def finished(self, root: Path, name: str) -> dict[int, dict]:
        """index → stored record of every complete sample under ``root`` (temporaries and the
        files of unfinished samples ignored)."""

    def write_index(self, root: Path, records: dict[int, dict], *, name: str, labels: dict[int, str]) -> None:
        """Write ``manifest.csv`` (and the layout's own index files) for ``records`` (as
        :meth:`finished` returns them), atomically; ``labels``: label value → name (0, the
        background, may be left out)."""

    def sample_paths(self, index: int, split: str, name: str, extra_labels=()) -> list[str]:
        """The files sample ``index`` always has, relative to the root, and those of its
        ``extra_labels`` (:meth:`extra_label_paths`); not the kept projections and meshes."""

    def extra_label_paths(self, index: int, split: str, name: str, extra_labels) -> dict[str, str]:
        """The file holding each of ``extra_labels`` (of :data:`~xrayraster.core.choices.LABEL_EXTRAS`)
        of sample ``index``, relative to the root, and with the instances, under
        :data:`INSTANCE_TABLE`, their id → yarn table (``instances.json``)."""

    def read_sample(self, root: Path, index: int, split: str, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(volume float32 cm⁻¹, labels uint8), both (z, y, x), of a complete sample, as written."""

    def remove_unfinished(self, root: Path, name: str) -> list[Path]:
        """Remove the visible files of samples a killed writer left unfinished (the runner calls it
        before a build resumes); returns them. Hidden temporaries are the runner's sweep's."""

    def index_names(self) -> list[str]:
        """The files :meth:`write_index` writes, relative to the root."""

    def sample_folders(self, index: int, name: str) -> list[tuple[str, str]]:
        """(folder relative to the root, its marker) of each folder that sample ``index`` writes whole
        (:func:`~xrayraster.core.files.atomic_directory`): its marker records the files in it."""

    def scan_metadata(self, root: Path, index: int, split: str, name: str) -> dict:
        """The scan metadata a complete sample stored (its ``scan`` document)."""


def sample_id(index: int) -> str:
    """The sample's number in file names: five digits, more when needed (``00042``, ``123456``)."""
    return f"{index:05d}"


def stored_record(index: int, result: ScanOutput, record: dict) -> dict:
    """The runner's ``record`` as stored: with ``index``, ``fractions`` (label value as a string →
    the share of the voxels with that label, labels present only) and, where the scan made any,
    ``extra_labels`` (their names, so a reader finds their files from the record alone). Refuses a
    record without a known ``split``."""
    if record.get("index", index) != index:
        raise ConfigError(f"sample {index}: its record says index {record['index']}")
    if record.get("split") not in DATASET_SPLITS:
        raise ConfigError(f"sample {index}: split must be one of {', '.join(DATASET_SPLITS)}, "
                          f"got {record.get('split')!r}")
    counts = np.bincount(np.asarray(result.labels.data).ravel())
    fractions = {str(label): count / counts.sum() for label, count in enumerate(counts.tolist()) if count}
    extra = {"extra_labels": list(result.extra_labels)} if result.extra_labels else {}  # none: as before
    return {**record, "index": index, "fractions": fractions, **extra}


def label_names(labels: dict[int, str]) -> dict[int, str]:
    """``labels`` with the background, 0, named ``background`` unless it is named there."""
    return {0: "background", **{int(label): str(name) for label, name in labels.items()}}


def check_name(name, where: str = "dataset") -> str:
    """``name`` if it is a dataset name (:data:`NAME_RULE`), else ConfigError naming ``where``."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ConfigError(f"{where}: name must be {NAME_RULE}, got {name!r}")
    return name


def _check_name(name: str) -> None:
    check_name(name, "dataset name")


def _checked_names(records: dict[int, dict], labels: dict[int, str]) -> dict[int, str]:
    """:func:`label_names` of ``labels``; refuses records holding a label that they do not name (a
    manifest column and nnU-Net's labels must cover every value in the files)."""
    names = label_names(labels)
    for index in sorted(records):
        for label in records[index].get("fractions", {}):
            if int(label) not in names:
                raise ConfigError(f"sample {index} has label {label}, which the build's labels do not name")
    return names


def _uint8_labels(result: ScanOutput) -> np.ndarray:
    data = np.asarray(result.labels.data)
    if data.size and int(data.max()) > MAX_LABEL:
        raise ConfigError(f"labels above {MAX_LABEL} do not fit the dataset layouts' uint8 label files")
    return data.astype(np.uint8, copy=False)


def _instance_ids(result: ScanOutput) -> np.ndarray:
    """The instance volume as the layouts store it: uint16 in every sample (xr.scan's is uint8 below
    256 yarns), so one build's samples share a type."""
    return np.asarray(result.instances.data).astype(np.uint16, copy=False)


def _extra_paths(extra_labels, path_of: Callable[[str], str], folder: str) -> dict[str, str]:
    """:meth:`~DatasetLayout.extra_label_paths`: each of ``extra_labels`` → ``path_of(label)``, and with
    the instances their table, ``folder/instances.json`` (``folder``: the sample's own folder)."""
    paths = {label: path_of(label) for label in LABEL_EXTRAS if label in extra_labels}
    if "instances" in paths:
        paths[INSTANCE_TABLE] = f"{folder}/{INSTANCES_JSON}"
    return paths


def _with_extra_files(paths: list[str], extra: dict[str, str]) -> list[str]:
    """``paths`` and then the ``extra`` files not among them (hdf5 keeps several in one file)."""
    return list(dict.fromkeys([*paths, *extra.values()]))


def _write_manifest(layout, root: Path, records: dict[int, dict], name: str, names: dict[int, str]) -> None:
    """Write ``manifest.csv`` of ``records`` for ``layout`` (``names``: :func:`_checked_names`), its
    ``instance_table`` column naming each sample's table of instances."""
    tables = {index: layout.extra_label_paths(index, r["split"], name, ("instances",))[INSTANCE_TABLE]
              for index, r in records.items() if "instances" in r.get("extra_labels", ())}
    write_manifest(Path(root) / MANIFEST_CSV, records, names, tables)


def _document(layout: str, stored: dict, result: ScanOutput) -> dict:
    """The JSON a layout keeps per sample: the generator (the mark of docs/outputs.md), the voxel
    grid (mm), the record and the scan's metadata."""
    return {"generator": GENERATOR, "layout": layout, "volume_geometry": result.volume.geometry.to_dict(),
            "record": stored, "scan": result.metadata}


def _json(document) -> str:
    return json.dumps(document, indent=2, default=json_ready) + "\n"


def _read_json(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def _remove_stray_extras(root: Path, pattern: str, done: dict) -> list[Path]:
    """Remove ``root/extras`` folders (named by ``pattern``, group 1 the index) of unfinished samples."""
    stray = [path for index, path in _visible(root / "extras", pattern) if index not in done]
    for path in stray:
        shutil.rmtree(path)
    return stray


def _visible(directory: Path, pattern: str) -> list[tuple[int, Path]]:
    """(index, path) of the entries of ``directory`` whose whole name matches ``pattern`` (its
    group 1 the index); hidden temporaries never match, as they start with a dot."""
    try:
        names = os.listdir(directory)
    except FileNotFoundError:
        return []
    compiled = re.compile(pattern)
    return sorted((int(m.group(1)), directory / n) for n in names if (m := compiled.fullmatch(n)))


def _make_parent(directory: Path) -> None:
    """Create the parent of a sample's directory first: atomic_directory's write probe removes a
    parent it had to create, which would pull it from under another worker starting at once."""
    directory.parent.mkdir(parents=True, exist_ok=True)


def _write_extras(directory: Path, result: ScanOutput, projections, write_meshes) -> None:
    """Into the sample's folder: the kept projections and meshes, and the instances' id → yarn table."""
    if projections is not None:
        projections.save(directory / PROJECTIONS_TIF, quicklook=False)
    if write_meshes is not None:
        (directory / MESHES).mkdir()
        write_meshes(directory / MESHES)
    if result.instances is not None:
        atomic_write_text(directory / INSTANCES_JSON, _json(result.metadata["instances"]))


def _extras_directory(path: Path, stored: dict, result: ScanOutput, projections, write_meshes) -> None:
    """The extras of a layout whose sample is not a directory, in a directory of their own, written
    whole before the sample's own files (so a complete sample's extras are complete too)."""
    if projections is None and write_meshes is None and result.instances is None:
        return
    _make_parent(path)
    with atomic_directory(path, marker=EXTRAS_JSON, generator=GENERATOR) as tmp:
        _write_extras(tmp, result, projections, write_meshes)
        atomic_write_text(tmp / EXTRAS_JSON, _json({"generator": GENERATOR, "index": stored["index"]}))


def _part(split: str) -> str:
    """nnU-Net's folder suffix of a split: ``Tr`` for the samples it trains on, ``Ts`` for test."""
    return "Tr" if split in TRAINING_SPLITS else "Ts"


def _nifti_extra_writers(result: ScanOutput) -> dict[str, Callable[[str], None]]:
    """The nnunet layout's writer of each extra label ``result`` holds (the instances' table is in
    the sample's folder): NIfTI volumes on the labels' grid and affine, the centre lines' JSON."""
    grid, writers = result.volume.geometry, {}
    if result.instances is not None:
        writers["instances"] = nifti_writer(_instance_ids(result), grid, description=GENERATOR)
    if result.directions is not None:  # (3, z, y, x) → NIfTI's x, y, z, component
        writers["directions"] = nifti_writer(np.asarray(result.directions, np.float32), grid, description=GENERATOR)
    if result.centrelines is not None:
        writers["centrelines"] = _text_writer(centrelines_text(result.centrelines))
    return writers


def _text_writer(text: str) -> Callable[[str], None]:
    """``write(path)`` of ``text`` (UTF-8), for :func:`~xrayraster.core.files.atomic_writes`."""
    return lambda tmp: Path(tmp).write_text(text, encoding="utf-8")


@dataclass(frozen=True)
class TiffLayout:
    """``samples/00000/``: ``volume.tif`` and ``labels.tif`` (Fiji reads the voxel size in mm),
    ``sample.json`` (record and scan metadata), the extra labels as xr.scan writes them
    (``instances.tif``, uint16 here, with ``instances.json``; ``directions.tif``;
    ``centrelines.json``), and ``projections.tif`` and ``meshes/`` when kept. The directory is
    built under a hidden name and moved into place whole, ``sample.json`` its marker
    (:func:`~xrayraster.core.files.atomic_directory`)."""

    def write_sample(self, root, index, result, record, *, name, projections=None, write_meshes=None) -> dict:
        _check_name(name)
        stored = stored_record(index, result, record)
        directory = Path(root) / "samples" / sample_id(index)
        _make_parent(directory)
        with atomic_directory(directory, marker=SAMPLE_JSON, generator=GENERATOR) as tmp:
            result.volume.save(tmp / VOLUME_TIF, quicklook=False)
            result.labels.save(tmp / LABELS_TIF, quicklook=False)
            instances = None if result.instances is None else replace(result.instances, data=_instance_ids(result))
            directions = None if result.directions is None else np.asarray(result.directions, np.float16)
            write_extra_labels(tmp, instances=instances, directions=directions, centrelines=result.centrelines)
            _write_extras(tmp, result, projections, write_meshes)
            atomic_write_text(tmp / SAMPLE_JSON, _json(_document("tiff", stored, result)))
        return stored

    def finished(self, root, name) -> dict[int, dict]:
        done = {}
        for index, directory in _visible(Path(root) / "samples", r"(\d+)"):
            document = read_record(directory / SAMPLE_JSON, GENERATOR)
            if document is not None and "files" in document:  # atomic_directory adds "files" last
                done[index] = document["record"]
        return done

    def write_index(self, root, records, *, name, labels) -> None:
        _write_manifest(self, root, records, name, _checked_names(records, labels))

    def sample_paths(self, index, split, name, extra_labels=()) -> list[str]:
        paths = [f"samples/{sample_id(index)}/{file}" for file in (VOLUME_TIF, LABELS_TIF, SAMPLE_JSON)]
        return _with_extra_files(paths, self.extra_label_paths(index, split, name, extra_labels))

    def extra_label_paths(self, index, split, name, extra_labels) -> dict[str, str]:
        folder = f"samples/{sample_id(index)}"
        return _extra_paths(extra_labels, lambda label: f"{folder}/{EXTRA_LABEL_NAMES[label]}", folder)  # as xr.scan's

    def index_names(self) -> list[str]:
        return [MANIFEST_CSV]

    def sample_folders(self, index, name) -> list[tuple[str, str]]:
        return [(f"samples/{sample_id(index)}", SAMPLE_JSON)]

    def scan_metadata(self, root, index, split, name) -> dict:
        return _read_json(Path(root) / self.sample_paths(index, split, name)[2])["scan"]

    def remove_unfinished(self, root, name) -> list[Path]:
        return []  # the sample's folder, extras inside, appears by one rename, whole

    def read_sample(self, root, index, split, name) -> tuple[np.ndarray, np.ndarray]:
        import tifffile

        volume, labels, _ = (Path(root) / path for path in self.sample_paths(index, split, name))
        return tifffile.imread(volume), tifffile.imread(labels)


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
        return _with_extra_files(paths, self.extra_label_paths(index, split, name, extra_labels))

    def extra_label_paths(self, index, split, name, extra_labels) -> dict[str, str]:
        case, part = self.case(index, name), _part(split)
        return _extra_paths(extra_labels, lambda label: f"{label}{part}/{case}{NNUNET_ENDINGS[label]}",
                            f"extras/{case}")

    def index_names(self) -> list[str]:
        return [MANIFEST_CSV, SPLITS_JSON, DATASET_JSON]

    def sample_folders(self, index, name) -> list[tuple[str, str]]:
        return [(f"extras/{self.case(index, name)}", EXTRAS_JSON)]

    def scan_metadata(self, root, index, split, name) -> dict:
        return _read_json(Path(root) / self.sample_paths(index, split, name)[2])["scan"]

    def remove_unfinished(self, root, name) -> list[Path]:
        # A sample's image, labels and record are renamed into place one after another, the record
        # last: a kill between the renames leaves an image or labels whose case has no record.
        root, done = Path(root), self.finished(root, name)
        pattern = rf"{re.escape(name)}_(\d+)(?:_0000)?(?:\.nii\.gz|\.json)"
        stray = [path for kind in ("images", "labels", *LABEL_EXTRAS) for part in ("Tr", "Ts")
                 for index, path in _visible(root / f"{kind}{part}", pattern) if index not in done]
        for path in stray:
            path.unlink()
        return stray + _remove_stray_extras(root, rf"{re.escape(name)}_(\d+)", done)

    def read_sample(self, root, index, split, name) -> tuple[np.ndarray, np.ndarray]:
        nib = optional_module("nibabel", "dataset", "reading NIfTI files")
        image, label, _ = (Path(root) / path for path in self.sample_paths(index, split, name))
        return (np.asarray(nib.load(image).dataobj, np.float32).T, np.asarray(nib.load(label).dataobj, np.uint8).T)

    def write_sample(self, root, index, result, record, *, name, projections=None, write_meshes=None) -> dict:
        _check_name(name)
        root = Path(root)
        stored = stored_record(index, result, record)
        grid, split, extra_labels = result.volume.geometry, stored["split"], result.extra_labels
        _extras_directory(root / "extras" / self.case(index, name), stored, result, projections, write_meshes)
        image, label, record_path = (root / path for path in self.sample_paths(index, split, name))
        extra = self.extra_label_paths(index, split, name, extra_labels)
        document = _json({**_document("nnunet", stored, result), "files": self.sample_paths(index, split, name,
                                                                                              extra_labels)})
        atomic_writes([
            (image, nifti_writer(np.asarray(result.volume.data, np.float32), grid, description=GENERATOR)),
            (label, nifti_writer(_uint8_labels(result), grid, description=GENERATOR)),
            *((root / extra[label], write) for label, write in _nifti_extra_writers(result).items()),
            (record_path, _text_writer(document)),
        ])
        return stored

    def finished(self, root, name) -> dict[int, dict]:
        _check_name(name)
        root = Path(root)
        done = {}
        for index, path in _visible(root / "records", rf"{re.escape(name)}_(\d+)\.json"):
            document = read_record(path, GENERATOR)
            # The record is renamed into place last; the images are checked too, as a person may
            # have removed one since.
            if document is not None and all((root / p).is_file() for p in document.get("files", ())):
                done[index] = document["record"]
        return done

    def write_index(self, root, records, *, name, labels) -> None:
        _check_name(name)
        root = Path(root)
        names = _checked_names(records, labels)
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
        _write_manifest(self, root, records, name, names)
        atomic_write_text(root / SPLITS_JSON, _json([{"train": cases["train"], "val": cases["val"]}]))
        atomic_write_text(root / DATASET_JSON, _json(dataset))


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
        return _with_extra_files(paths, self.extra_label_paths(index, split, name, extra_labels))

    def extra_label_paths(self, index, split, name, extra_labels) -> dict[str, str]:
        return _extra_paths(extra_labels, lambda label: self.sample_paths(index, split, name)[0],
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
        return _remove_stray_extras(Path(root), r"(\d+)", self.finished(root, name))

    def read_sample(self, root, index, split, name) -> tuple[np.ndarray, np.ndarray]:
        h5py = optional_module("h5py", "dataset", "reading HDF5 files")
        with h5py.File(Path(root) / self.sample_paths(index, split, name)[0], "r") as f:
            return f["raw"][()], f["label"][()]

    def write_sample(self, root, index, result, record, *, name, projections=None, write_meshes=None) -> dict:
        _check_name(name)
        root = Path(root)
        stored = stored_record(index, result, record)
        _extras_directory(root / "extras" / sample_id(index), stored, result, projections, write_meshes)
        h5py = optional_module("h5py", "dataset", "the hdf5 dataset layout")
        grid = result.volume.geometry
        arrays = {"raw": np.asarray(result.volume.data, np.float32), "label": _uint8_labels(result)}
        units = {"raw": result.volume.unit, "label": "label value (0 background)"}
        if result.instances is not None:
            arrays["instances"], units["instances"] = _instance_ids(result), INSTANCE_UNIT
        if result.directions is not None:
            arrays["directions"], units["directions"] = np.asarray(result.directions, np.float16), DIRECTION_UNIT
        document = _document("hdf5", stored, result)

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
        for index, path in _visible(Path(root) / "samples", r"(\d+)\.h5"):
            try:
                with h5py.File(path, "r") as f:
                    if f.attrs.get("generator") == GENERATOR:
                        done[index] = json.loads(f.attrs["record"])
            except (OSError, KeyError, ValueError):  # not an HDF5 file of ours: not a finished sample
                continue
        return done

    def write_index(self, root, records, *, name, labels) -> None:
        _write_manifest(self, root, records, name, _checked_names(records, labels))


LAYOUTS: dict[str, DatasetLayout] = {"tiff": TiffLayout(), "nnunet": NnunetLayout(), "hdf5": Hdf5Layout()}
