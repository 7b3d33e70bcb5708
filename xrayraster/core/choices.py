"""Every string option of the API and the command line, in one place.

argparse's ``choices``, the checks of every function that takes one of these, and the docs read
these tuples, so a new option is added once. :func:`check_choice` makes the error message.
"""

from __future__ import annotations

BEAMS = ("cone", "parallel")
OVERLAP_MODES = ("auto", "sum", "nested", "resolve")  # path lengths where objects overlap
RADIOGRAPH_OUTPUTS = ("raw", "transmission", "lineint")  # what a radiograph holds
DETECTOR_MODES = ("integrating", "counting")
SCATTER_MODELS = ("none", "kernel")  # [physics] scatter: physics/scatter.py
RECONSTRUCTION_INPUTS = ("lineint", "transmission")  # what a projection stack handed to FDK holds
FILTERS = ("ram-lak", "shepp-logan", "cosine", "hamming", "hann")  # ramp-filter windows
SCAN_KINDS = ("auto", "full", "short")  # FDK redundancy weighting
VOXELIZE_METHODS = ("exact", "stencil")
MESH_FORMATS = ("stl", "ply")  # mesh files a woven sample is exported as
WEAVE_RESOLVE = ("priority", "boolean")  # how overlapping yarns are settled
EXPORT_PER = ("family", "yarn")  # one mesh file per yarn family or per yarn
DATASET_LAYOUTS = ("tiff", "nnunet", "hdf5")  # how a dataset build lays out its samples
DATASET_SPLITS = ("train", "val", "test")  # the parts a dataset's samples are split into, in draw order
DATASET_KEEP = ("projections", "meshes")  # what a dataset build keeps beside each sample's volumes
LABEL_CLASSES = ("classes", "binder")  # a woven scan's class volume: binders in warp (3), or a class of their own (4)
LABEL_EXTRAS = ("instances", "directions", "centrelines")  # beside a woven scan's classes (docs/labels.md)
PATCH_TARGETS = ("classes", "instances", "directions")  # what xr.ml.PatchDataset crops beside the volume


def is_switch(value) -> bool:
    """An automatic-or-forced option (FDK's ``displaced``, ``truncation``): ``"auto"``, ``True`` or
    ``False``; not 1 or 0, which equal True and False."""
    return isinstance(value, bool) or (isinstance(value, str) and value == "auto")


def check_choice(value, choices: tuple[str, ...], field: str, error: type[Exception]) -> str:
    """``value`` if it is one of ``choices``, else ``error`` naming ``field`` and the choices."""
    if not isinstance(value, str) or value not in choices:
        listed = ", ".join(repr(c) for c in choices)
        raise error(f"{field} must be one of {listed}, got {value!r}")
    return value
