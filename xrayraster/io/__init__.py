"""Files: TOML scene files, JSON scan files, TIFF stacks and their metadata, quick-look PNGs, and the
on-disk layouts of dataset builds (``dataset_layout``: TIFF, nnU-Net NIfTI, HDF5)."""

from .tiff import (
    read_projections,
    read_tiff,
    read_tiff_info,
    write_projections,
    write_quicklook,
    write_tiff,
    write_volume,
)

__all__ = ["read_projections", "read_tiff", "read_tiff_info", "write_projections", "write_quicklook", "write_tiff",
           "write_volume"]
