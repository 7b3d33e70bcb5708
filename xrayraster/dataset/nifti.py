"""NIfTI-1 volumes (``.nii.gz``) for nnU-Net, MONAI, ITK and nibabel, the same bytes for the same input.

NIfTI orders axes x, y, z (the first index varies fastest on disk), ours are (z, y, x) C-ordered,
so the array is handed over transposed: the bytes on disk are our array's, unchanged. The voxel
size (mm) is the affine's diagonal and the header's zooms (``pixdim``), and the affine's
translation is voxel (0, 0, 0)'s centre, so world coordinates are the scanner frame in mm
(:mod:`~xrayraster.core.volume`). NIfTI's world is RAS+ for anatomy; a scan has no patient, so
the scanner's x, y, z are written as they are (qform and sform code 1, "scanner").

The gzip stream is made here, not by nibabel, so its header holds no file name (nibabel's would
name the temporary the file is written under) and a modification time of 0.
"""

from __future__ import annotations

import gzip
from collections.abc import Callable

import numpy as np

from ..core.volume import VolumeGeometry
from ..io.optional import optional_module

# zlib's default. Measured on 128³ noisy float32 + uint8 labels: levels 1 and 6 take the same time
# (≈0.37 s; a reconstruction's noisy mantissas hardly compress at any level) and 6 makes the labels
# 4× smaller than 1 (5.8 vs 25 kB).
GZIP_LEVEL = 6
DESCRIPTION_BYTES = 80  # the header's descrip field


def nifti_affine(grid: VolumeGeometry) -> np.ndarray:
    """The 4×4 voxel-to-world affine (mm, x y z) of ``grid``: voxel sizes on the diagonal, voxel
    (0, 0, 0)'s centre as the translation."""
    affine = np.diag([*grid.voxel_size[::-1], 1.0])
    affine[:3, 3] = [grid.axis_centres(axis)[0] for axis in (2, 1, 0)]
    return affine


def nifti_writer(data: np.ndarray, grid: VolumeGeometry, *, description: str) -> Callable[[str], None]:
    """``write(path)``, for :func:`~xrayraster.core.files.atomic_write`, writing ``data`` (z, y, x, on
    ``grid``) as a gzipped NIfTI-1 file in its own dtype (float32 images, uint8 labels), with
    ``description`` (at most 80 ASCII characters) in the header's ``descrip``.
    ``nibabel.load(path).get_fdata().T`` is ``data`` again and ``header.get_zooms()`` the voxel size
    (x, y, z) in mm, as float32 (the header's type)."""
    nib = optional_module("nibabel", "dataset", "writing NIfTI files")
    if len(description.encode("ascii")) > DESCRIPTION_BYTES:
        raise ValueError(f"a NIfTI description holds {DESCRIPTION_BYTES} bytes, got {description!r}")
    data = np.ascontiguousarray(data)
    affine = nifti_affine(grid)
    image = nib.Nifti1Image(data.T, affine)
    header = image.header
    header.set_data_dtype(data.dtype)
    header.set_xyzt_units("mm")
    header["descrip"] = description.encode("ascii")
    image.set_qform(affine, code=1)
    image.set_sform(affine, code=1)

    def write(path):
        with open(path, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, compresslevel=GZIP_LEVEL,
                                                    mtime=0) as stream:
            image.to_file_map({"image": nib.FileHolder(fileobj=stream)})

    return write
