"""TIFF stacks with JSON metadata (Fiji-readable), and quick-look PNGs; both written atomically.

The writers live in :mod:`xrayraster.core.tiff` (so that ``Projections``, ``Volume`` and
``LabelVolume`` can ``save`` themselves); this module keeps their public names here.
"""

from __future__ import annotations

from ..core.projections import Projections
from ..core.tiff import (
    QUICKLOOK_MIN_PX,
    pixel_size_mm,
    quicklook_factor,
    read_tiff,
    read_tiff_info,
    write_projections,
    write_quicklook,
    write_tiff,
    write_volume,
)


def read_projections(path) -> Projections:
    """The stack :func:`write_projections` wrote (its metadata must carry the geometry)."""
    return Projections.load(path)


__all__ = [
    "QUICKLOOK_MIN_PX", "pixel_size_mm", "quicklook_factor", "read_projections", "read_tiff", "read_tiff_info",
    "write_projections", "write_quicklook", "write_tiff", "write_volume",
]
