"""The files of a woven scan's extra labels (docs/labels.md): the instance volume, the yarn
directions and the centre lines, as ``xr.scan`` writes them into its output directory and the
``tiff`` dataset layout into each sample's folder. One writer for both, here so the dataset layouts
use it without importing the pipeline (``xr.ml`` reads builds without the renderer); the other
layouts store the same arrays and the same centre-line JSON (:func:`centrelines_text`).
"""

from __future__ import annotations

import json
from pathlib import Path

from .files import atomic_write_text

#: The file of each extra label a scan file may ask for (:data:`~xrayraster.core.choices.LABEL_EXTRAS`).
EXTRA_LABEL_NAMES = {"instances": "instances.tif", "directions": "directions.tif", "centrelines": "centrelines.json"}
#: What the direction TIFF's channels are, in its metadata.
DIRECTION_CHANNELS = "x, y, z components of the yarn direction"


def centrelines_text(centrelines: dict) -> str:
    """The centre lines' JSON (:func:`~xrayraster.weave.centrelines.centreline_table`), as every
    output stores it."""
    return json.dumps(centrelines) + "\n"


def write_extra_labels(directory, *, instances=None, directions=None, centrelines=None) -> None:
    """Write, into ``directory``, the extra labels given: ``instances`` (a
    :class:`~xrayraster.LabelVolume`, its own ImageJ TIFF writer, no quick-look), ``directions``
    ((3, z, y, x) float16, a plain TIFF whose axes are ``CZYX``) and ``centrelines`` (a JSON-ready
    dict), each under its name in :data:`EXTRA_LABEL_NAMES`."""
    directory = Path(directory)
    if instances is not None:
        instances.save(directory / EXTRA_LABEL_NAMES["instances"], quicklook=False)
    if directions is not None:
        import tifffile

        tifffile.imwrite(directory / EXTRA_LABEL_NAMES["directions"], directions,
                         metadata={"axes": "CZYX", "channels": DIRECTION_CHANNELS})
    if centrelines is not None:
        atomic_write_text(directory / EXTRA_LABEL_NAMES["centrelines"], centrelines_text(centrelines))
