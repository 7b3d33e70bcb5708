"""TIFF stacks with JSON metadata (Fiji-readable), and quick-look PNGs; both written atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.files import atomic_write
from ..core.projections import Projections
from ..core.volume import VolumeGeometry


def write_tiff(path, data: np.ndarray, *, axes: str, pixel_size_mm: tuple[float, float], info: dict,
               spacing_mm: float | None = None) -> Path:
    """ImageJ hyperstack (Fiji reads axes and mm scale: ``pixel_size_mm`` (y, x) and, for
    volumes, the slice ``spacing_mm``); ``info`` goes in as JSON. uint8 and uint16 (labels) are
    written as they are, anything else as float32."""
    import tifffile

    keep = data.dtype in (np.uint8, np.uint16)
    data = np.ascontiguousarray(data, dtype=data.dtype if keep else np.float32)
    metadata = {"axes": axes, "unit": "mm", "Info": json.dumps(info, indent=1)}
    if spacing_mm is not None:
        metadata["spacing"] = float(spacing_mm)
    resolution = (1.0 / pixel_size_mm[1], 1.0 / pixel_size_mm[0])
    return atomic_write(
        path, lambda tmp: tifffile.imwrite(tmp, data, imagej=True, metadata=metadata, resolution=resolution)
    )


def read_tiff(path) -> tuple[np.ndarray, dict]:
    """The array of a TIFF and the JSON ``info`` of :func:`write_tiff` ({} for a TIFF from elsewhere)."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        data = tif.asarray()
        text = (tif.imagej_metadata or {}).get("Info")
    try:
        return data, json.loads(text) if text else {}
    except json.JSONDecodeError:
        return data, {}


def read_tiff_info(path) -> dict:
    """The JSON ``info`` written by :func:`write_tiff`."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        return json.loads(tif.imagej_metadata["Info"])


def write_projections(path, projections: Projections) -> Path:
    """A :class:`~xrayraster.core.projections.Projections` stack as a float32 ImageJ TIFF with its
    metadata (geometry, quantity, unit, provenance); :func:`read_projections` reads it back."""
    axes = "TCYX" if projections.quantity == "path_length" else "TYX"
    return write_tiff(path, projections.data, axes=axes, pixel_size_mm=pixel_size_mm(projections.geometry),
                      info=projections.metadata())


def read_projections(path) -> Projections:
    """The stack :func:`write_projections` wrote (its metadata must carry the geometry)."""
    data, info = read_tiff(path)
    return Projections.from_metadata(data, info, str(path))


def write_volume(path, data: np.ndarray, grid: VolumeGeometry, info: dict, *, channels: str | None = None) -> Path:
    """A volume on ``grid`` (z, y, x; or z, ``channels``, y, x, e.g. one channel per label) as an
    ImageJ TIFF whose voxel size Fiji reads (mm), with ``info``, the axes and the grid's dict form
    as metadata."""
    vz, vy, vx = grid.voxel_size
    axes = {"axes": f"z, {channels}, y, x" if channels else "z, y, x", "volume_geometry": grid.to_dict()}
    return write_tiff(path, data, axes="ZCYX" if channels else "ZYX", pixel_size_mm=(vy, vx), spacing_mm=vz,
                      info={**info, **axes})


def pixel_size_mm(geometry) -> tuple[float, float]:
    """(row, col) pixel pitch in mm of a scan geometry's detector (its first view for a vector geometry)."""
    if hasattr(geometry, "pixel_size"):
        return geometry.pixel_size
    u, v = geometry.array[0, 6:9], geometry.array[0, 9:12]
    return float(np.linalg.norm(v)), float(np.linalg.norm(u))


def write_quicklook(path, image: np.ndarray) -> Path:
    """8-bit PNG scaled from 0 to the image maximum (a quick look, not data).

    Shown as a person expects: +z up. Array row 0 is the lowest detector row (docs/geometry.md),
    so the rows are flipped for the picture; the TIFF keeps the array order.
    """
    from PIL import Image

    peak = float(image.max())
    scaled = np.zeros(image.shape, np.uint8) if peak <= 0 else np.round(255 * np.clip(image / peak, 0, 1)).astype(np.uint8)
    scaled = np.ascontiguousarray(scaled[::-1])
    return atomic_write(path, lambda tmp: Image.fromarray(scaled).save(tmp, format="PNG"))
