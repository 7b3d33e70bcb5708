"""A reconstructed volume: linear attenuation in cm⁻¹ on a voxel grid, and how it is saved."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.tiff import checked_outputs, write_quicklook, write_volume
from ..core.volume import VolumeGeometry

MM_TO_CM = 10.0  # μ in mm⁻¹ × 10 = cm⁻¹


@dataclass(frozen=True)
class Volume:
    """A reconstructed volume: ``data`` float32 (z, y, x) in ``unit`` on ``geometry``.

    ``unit`` is ``"1/cm"``: reconstructions are linear attenuation coefficients in cm⁻¹ (the
    path-length physics works in mm⁻¹; see :mod:`xrayraster`). ``provenance``: JSON-ready facts
    about how it was made (scan geometry, filter, ...), stored by :meth:`save`.
    """

    data: np.ndarray
    geometry: VolumeGeometry
    unit: str = "1/cm"
    provenance: dict = field(default_factory=dict, compare=False)

    def save(self, path, *, quicklook: bool = True):
        """Write the volume as ``xrayraster reconstruct`` does: a float32 ImageJ TIFF (z, y, x) at
        ``path`` whose voxel size Fiji reads in mm, with the unit, the grid's dict form
        (``volume_geometry``) and :attr:`provenance` as JSON metadata, and, with ``quicklook``, a
        PNG of the central slice (negative values shown as 0, with a scale bar) beside it.
        Returns ``path``."""
        info = {"quantity": "linear attenuation coefficient", "units": self.unit, **self.provenance}
        out, *png = checked_outputs(path, quicklook=quicklook)
        write_volume(out, self.data, self.geometry, info)
        if png:
            middle = np.clip(self.data[self.data.shape[0] // 2], 0, None)
            write_quicklook(png[0], middle, self.geometry.voxel_size[1:])
        return out
