"""Files: TOML scene files, JSON scan files, TIFF stacks and their metadata, quick-look PNGs. The
on-disk layouts of dataset builds are the dataset layer's (``xrayraster.dataset.layouts``)."""

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
