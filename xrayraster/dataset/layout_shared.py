"""What every dataset layout shares (docs/dataset_layouts.md; the contract in
:mod:`~xrayraster.dataset.layouts`): the file names of a sample, the dataset name's rule, the
record a sample stores, and the atomic writes of its extras and of the manifest."""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Protocol

import numpy as np

from ..core.choices import DATASET_SPLITS, LABEL_EXTRAS
from ..core.errors import ConfigError
from ..core.files import atomic_directory, atomic_write_text
from .manifest import json_ready, write_manifest
from .names import GENERATOR

if TYPE_CHECKING:
    from ..gl.voxelize import LabelVolume
    from ..recon.volume import Volume

MAX_LABEL = 255  # labels are stored as uint8
SAMPLE_JSON, EXTRAS_JSON, MANIFEST_CSV = "sample.json", "extras.json", "manifest.csv"
VOLUME_TIF, LABELS_TIF, PROJECTIONS_TIF, MESHES = "volume.tif", "labels.tif", "projections.tif", "meshes"
#: The instances' id → yarn table, in a sample's folder, and its key among a sample's extra files.
INSTANCES_JSON, INSTANCE_TABLE = "instances.json", "instance_table"
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


def checked_names(records: dict[int, dict], labels: dict[int, str]) -> dict[int, str]:
    """:func:`label_names` of ``labels``; refuses records holding a label that they do not name (a
    manifest column and nnU-Net's labels must cover every value in the files)."""
    names = label_names(labels)
    for index in sorted(records):
        for label in records[index].get("fractions", {}):
            if int(label) not in names:
                raise ConfigError(f"sample {index} has label {label}, which the build's labels do not name")
    return names


def uint8_labels(result: ScanOutput) -> np.ndarray:
    data = np.asarray(result.labels.data)
    if data.size and int(data.max()) > MAX_LABEL:
        raise ConfigError(f"labels above {MAX_LABEL} do not fit the dataset layouts' uint8 label files")
    return data.astype(np.uint8, copy=False)


def instance_ids(result: ScanOutput) -> np.ndarray:
    """The instance volume as the layouts store it: uint16 in every sample (xr.scan's is uint8 below
    256 yarns), so one build's samples share a type."""
    return np.asarray(result.instances.data).astype(np.uint16, copy=False)


def extra_paths(extra_labels, path_of: Callable[[str], str], folder: str) -> dict[str, str]:
    """A layout's :meth:`~xrayraster.dataset.layouts.DatasetLayout.extra_label_paths`: each of
    ``extra_labels`` → ``path_of(label)``, and with the instances their table,
    ``folder/instances.json`` (``folder``: the sample's own folder)."""
    paths = {label: path_of(label) for label in LABEL_EXTRAS if label in extra_labels}
    if "instances" in paths:
        paths[INSTANCE_TABLE] = f"{folder}/{INSTANCES_JSON}"
    return paths


def with_extra_files(paths: list[str], extra: dict[str, str]) -> list[str]:
    """``paths`` and then the ``extra`` files not among them (hdf5 keeps several in one file)."""
    return list(dict.fromkeys([*paths, *extra.values()]))


def write_layout_manifest(layout, root: Path, records: dict[int, dict], name: str, names: dict[int, str]) -> None:
    """Write ``manifest.csv`` of ``records`` for ``layout`` (``names``: :func:`checked_names`), its
    ``instance_table`` column naming each sample's table of instances."""
    tables = {index: layout.extra_label_paths(index, r["split"], name, ("instances",))[INSTANCE_TABLE]
              for index, r in records.items() if "instances" in r.get("extra_labels", ())}
    write_manifest(Path(root) / MANIFEST_CSV, records, names, tables)


def sample_document(layout: str, stored: dict, result: ScanOutput) -> dict:
    """The JSON a layout keeps per sample: the generator (the mark of docs/outputs.md), the voxel
    grid (mm), the record and the scan's metadata."""
    return {"generator": GENERATOR, "layout": layout, "volume_geometry": result.volume.geometry.to_dict(),
            "record": stored, "scan": result.metadata}


def to_json(document) -> str:
    return json.dumps(document, indent=2, default=json_ready) + "\n"


def read_json(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def remove_stray_extras(root: Path, pattern: str, done: dict) -> list[Path]:
    """Remove ``root/extras`` folders (named by ``pattern``, group 1 the index) of unfinished samples."""
    stray = [path for index, path in visible(root / "extras", pattern) if index not in done]
    for path in stray:
        shutil.rmtree(path)
    return stray


def visible(directory: Path, pattern: str) -> list[tuple[int, Path]]:
    """(index, path) of the entries of ``directory`` whose whole name matches ``pattern`` (its
    group 1 the index); hidden temporaries never match, as they start with a dot."""
    try:
        names = os.listdir(directory)
    except FileNotFoundError:
        return []
    compiled = re.compile(pattern)
    return sorted((int(m.group(1)), directory / n) for n in names if (m := compiled.fullmatch(n)))


def make_parent(directory: Path) -> None:
    """Create the parent of a sample's directory first: atomic_directory's write probe removes a
    parent it had to create, which would pull it from under another worker starting at once."""
    directory.parent.mkdir(parents=True, exist_ok=True)


def write_extras(directory: Path, result: ScanOutput, projections, write_meshes) -> None:
    """Into the sample's folder: the kept projections and meshes, and the instances' id → yarn table."""
    if projections is not None:
        projections.save(directory / PROJECTIONS_TIF, quicklook=False)
    if write_meshes is not None:
        (directory / MESHES).mkdir()
        write_meshes(directory / MESHES)
    if result.instances is not None:
        atomic_write_text(directory / INSTANCES_JSON, to_json(result.metadata["instances"]))


def extras_directory(path: Path, stored: dict, result: ScanOutput, projections, write_meshes) -> None:
    """The extras of a layout whose sample is not a directory, in a directory of their own, written
    whole before the sample's own files (so a complete sample's extras are complete too)."""
    if projections is None and write_meshes is None and result.instances is None:
        return
    make_parent(path)
    with atomic_directory(path, marker=EXTRAS_JSON, generator=GENERATOR) as tmp:
        write_extras(tmp, result, projections, write_meshes)
        atomic_write_text(tmp / EXTRAS_JSON, to_json({"generator": GENERATOR, "index": stored["index"]}))
