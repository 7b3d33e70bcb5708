"""Files: configuration files by kind, a loader module each (TOML scene, scan and weave files, JSON grid
files), TIFF stacks and their metadata, quick-look PNGs. Dataset files and the on-disk layouts of
dataset builds are the dataset layer's (``xrayraster.dataset``)."""

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
