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
:func:`~xrayraster.dataset.layout_shared.stored_record` (``index``, the label ``fractions``, and the
``extra_labels`` the scan made); :meth:`~DatasetLayout.finished` gives it back for every complete
sample, so the runner can rebuild the manifest from the disk alone.

A scan's extra labels (``[scan] labels``: instances, directions, centre lines; docs/labels.md) are
stored beside its volume and classes, in every layout, by the same atomic writes: the instance ids
as uint16 in every sample, the directions as (3, z, y, x) float16 (float32 in NIfTI, which has no
float16), the centre lines as xr.scan's JSON, and the instances' id → yarn table as
``instances.json`` in the sample's folder (:meth:`~DatasetLayout.sample_folders`), which the
manifest's ``instance_table`` column names. A scan without them is stored as it always was, byte for byte.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable, Protocol

import numpy as np

from .hdf5_layout import HDF5_CHUNK, Hdf5Layout
from .layout_shared import NAME_RULE, ScanOutput, check_name
from .names import GENERATOR
from .nnunet_layout import NnunetLayout
from .tiff_layout import TiffLayout

if TYPE_CHECKING:
    from ..core.projections import Projections

# What readers of builds and the dataset file import from here (the rest of a layout is its module's).
__all__ = ["GENERATOR", "HDF5_CHUNK", "LAYOUTS", "NAME_RULE", "DatasetLayout", "ScanOutput", "check_name"]


class DatasetLayout(Protocol):
    """The on-disk layout of a dataset build (module docstring). ``name`` is the dataset's name,
    the prefix of nnU-Net's case names (:data:`NAME_RULE`)."""

    def write_sample(self, root: Path, index: int, result: ScanOutput, record: dict, *, name: str,
                     projections: Projections | None = None,
                     write_meshes: Callable[[Path], None] | None = None) -> dict:
        """Write sample ``index`` atomically: its volume, labels, extra labels (those ``result``
        holds) and :func:`~xrayraster.dataset.layout_shared.stored_record`, and, when given, its ``projections`` and the meshes
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


LAYOUTS: dict[str, DatasetLayout] = {"tiff": TiffLayout(), "nnunet": NnunetLayout(), "hdf5": Hdf5Layout()}
