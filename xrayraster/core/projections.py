"""A stack of projections with what it needs to be read correctly: its scan geometry, what the
numbers are and in which unit, and where they came from.

Every writer (TIFF today; HDF5, NIfTI and Zarr for the dataset stage) stores
:meth:`Projections.metadata` beside the data, and :meth:`Projections.from_metadata` reads it
back, so the schema is built here, once, not in each command. :func:`xrayraster.fdk` takes a
Projections directly (geometry and quantity then need no repeating).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError
from .geometry import geometry_from_dict
from .tiff import checked_outputs, pixel_size_mm, read_tiff, write_projections, write_quicklook

# quantity → (unit, axes, description). A line integral and a transmission are ratios ("1").
QUANTITIES = {
    "lineint": ("1", "view, row, col", "line integral -ln(transmission)"),
    "transmission": ("1", "view, row, col", "transmission (raw - dark) / (flat - dark)"),
    "raw": (None, "view, row, col", "raw detector signal (flat-field-free: open beam, dark offset and noise included)"),
    "path_length": ("mm", "view, material, row, col", "path length"),
}
RAW_UNITS = ("keV deposited", "counts")  # an integrating or a counting detector's raw signal


@dataclass(frozen=True)
class Projections:
    """``data`` float32 ``(views, rows, cols)`` (``(views, materials, rows, cols)`` for path lengths)
    taken with ``geometry`` (its views are the stack's, in order).

    * ``quantity``: ``"lineint"``, ``"transmission"``, ``"raw"`` or ``"path_length"``.
    * ``unit``: ``"1"`` (line integrals, transmissions), ``"mm"`` (path lengths), or for raw
      signals ``"keV deposited"`` (integrating detector) or ``"counts"`` (counting detector).
    * ``provenance``: JSON-ready facts about how the stack was made (scene file, spectrum,
      detector, materials, noise seed, view indices, renderer ...), stored with the data.
    """

    data: np.ndarray
    geometry: object
    quantity: str = "lineint"
    unit: str = "1"
    provenance: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.quantity not in QUANTITIES:
            raise ConfigError(f"quantity must be one of {', '.join(QUANTITIES)}, got {self.quantity!r}")
        expected = QUANTITIES[self.quantity][0]
        if self.unit != expected and not (self.quantity == "raw" and self.unit in RAW_UNITS):
            allowed = RAW_UNITS if self.quantity == "raw" else (expected,)
            raise ConfigError(f"a {self.quantity} stack has unit {' or '.join(map(repr, allowed))}, got {self.unit!r}")
        ndim = 4 if self.quantity == "path_length" else 3
        if np.ndim(self.data) != ndim:
            raise ConfigError(f"{self.quantity} projections must be a {ndim}-D stack ({QUANTITIES[self.quantity][1]}), "
                              f"got shape {np.shape(self.data)}")
        views, rows, cols = np.shape(self.data)[0], *np.shape(self.data)[-2:]
        if (views, rows, cols) != (self.geometry.num_views, *self.geometry.detector_shape):
            raise ConfigError(f"projections of shape {np.shape(self.data)} do not match the geometry's "
                              f"{self.geometry.num_views} views of {self.geometry.detector_shape} pixels")

    def metadata(self) -> dict:
        """The JSON metadata every writer stores with the data."""
        unit, axes, description = QUANTITIES[self.quantity]
        return {
            "quantity": description,
            "output": self.quantity,
            "units": self.unit,
            "axes": axes,
            "geometry": self.geometry.to_dict(),
            **self.provenance,
        }

    @classmethod
    def from_metadata(cls, data: np.ndarray, info: dict, where: str = "metadata") -> Projections:
        """The stack ``data`` with the metadata :meth:`metadata` wrote (``where`` names the file)."""
        if not isinstance(info.get("geometry"), dict):
            raise ConfigError(f"{where}: no scan geometry in the metadata (a 'geometry' object); give the geometry "
                              "separately (a grid file's 'geometry', docs/reconstruction.md)")
        quantity = info.get("output", "path_length" if info.get("quantity") == "path length" else None)
        if quantity not in QUANTITIES:
            raise ConfigError(f"{where}: the metadata's 'output' {quantity!r} is not one of {', '.join(QUANTITIES)}")
        known = {"quantity", "output", "units", "axes", "geometry"}
        provenance = {k: v for k, v in info.items() if k not in known}
        geometry = geometry_from_dict(info["geometry"], f"{where} geometry")
        return cls(data, geometry, quantity, info.get("units", QUANTITIES[quantity][0]), provenance)

    def save(self, path, *, quicklook: bool = True):
        """Write the stack as the command line does: a float32 ImageJ TIFF at ``path`` (Fiji
        reads the detector pixel size in mm) with :meth:`metadata` as JSON, and, with
        ``quicklook``, a PNG beside it (``path`` with suffix ``.png``: view 0, summed over
        materials for path lengths, +z up, with a scale bar at the detector). Returns ``path``;
        :meth:`load` reads it back."""
        out, *png = checked_outputs(path, quicklook=quicklook)
        write_projections(out, self)
        if png:
            first = self.data[0].sum(axis=0) if self.quantity == "path_length" else self.data[0]
            write_quicklook(png[0], first, pixel_size_mm(self.geometry), where="at the detector")
        return out

    @classmethod
    def load(cls, path) -> Projections:
        """The stack :meth:`save` (or ``xrayraster render``) wrote; its metadata must carry the geometry."""
        data, info = read_tiff(path)
        return cls.from_metadata(data, info, str(path))
