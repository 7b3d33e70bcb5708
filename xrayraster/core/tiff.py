"""TIFF stacks with JSON metadata (Fiji-readable), and quick-look PNGs with a scale bar; both
written atomically (:func:`~xrayraster.core.files.atomic_write`).

They live in ``core`` so that the data classes of every stage (``xr.Projections``,
``xr.Volume``, ``xr.LabelVolume``) can ``save`` themselves without importing ``io``;
:mod:`xrayraster.io.tiff` re-exports them for the command line and for readers.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .files import atomic_write
from .ownership import SOFTWARE, check_replaceable_files, resolved_output
from .volume import VolumeGeometry

#: Data above this many bytes cannot be a classic TIFF with an IFD a page (32-bit offsets): it is
#: written as ImageJ writes big stacks, one IFD and the pages after it, contiguous ("truncated", as
#: tifffile names it, which reads it whole like ImageJ). The margin is tifffile's own (its BigTIFF
#: threshold), left for the IFDs and the metadata; below it, the files are as they always were.
IMAGEJ_CONTIGUOUS_BYTES = 2**32 - 2**25
QUICKLOOK_MIN_PX = 512  # a quick-look's long side is upscaled (nearest neighbour, integer factor) to at least this
_BAR_STRIP_PX = 22  # height of the scale-bar strip below the picture


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
    # Said up front for big data: tifffile would do the same after warning "truncating ImageJ file".
    big = {"truncate": True} if data.nbytes > IMAGEJ_CONTIGUOUS_BYTES else {}
    # The Software tag marks the file as ours (core.ownership): a later write may replace it.
    return atomic_write(path, lambda tmp: tifffile.imwrite(tmp, data, imagej=True, metadata=metadata,
                                                           resolution=resolution, software=SOFTWARE, **big))


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


def write_projections(path, projections) -> Path:
    """A :class:`~xrayraster.core.projections.Projections` stack as a float32 ImageJ TIFF with its
    metadata (geometry, quantity, unit, provenance); ``Projections.load`` reads it back."""
    axes = "TCYX" if projections.quantity == "path_length" else "TYX"
    return write_tiff(path, projections.data, axes=axes, pixel_size_mm=pixel_size_mm(projections.geometry),
                      info=projections.metadata())


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


def quicklook_factor(shape) -> int:
    """The integer nearest-neighbour upscale that brings the long side to at least
    :data:`QUICKLOOK_MIN_PX` (1 for images already that large)."""
    return max(1, math.ceil(QUICKLOOK_MIN_PX / max(max(shape), 1)))


def quicklook_path(out) -> Path:
    """The quick-look PNG beside the TIFF ``out``."""
    return Path(out).with_suffix(".png")


def checked_outputs(path, *, quicklook: bool, beside=()) -> list[Path]:
    """``path`` (links resolved), then its quick-look PNG if ``quicklook``, then the files named
    ``beside`` it: checked together before any is written, so a ``save`` that would replace a file
    xrayraster did not write refuses before writing anything (:mod:`~xrayraster.core.ownership`)."""
    out = resolved_output(path)
    sides = ([quicklook_path(out)] if quicklook else []) + [out.with_name(name) for name in beside]
    return check_replaceable_files([out, *sides])


def png_text(**chunks):
    """PNG text chunks for PIL's ``save(pnginfo=...)``: ``Software`` (the mark
    :mod:`~xrayraster.core.ownership` reads) and ``chunks``."""
    from PIL import PngImagePlugin

    info = PngImagePlugin.PngInfo()
    for key, value in {"Software": SOFTWARE, **chunks}.items():
        info.add_text(key, value)
    return info


def write_quicklook(path, image: np.ndarray, pixel_size_mm: float | tuple[float, float] | None = None, *,
                    where: str = "") -> Path:
    """8-bit PNG scaled from 0 to the image maximum (a quick look, not data).

    Shown as a person expects: +z up. Array row 0 is the lowest detector row (docs/geometry.md),
    so the rows are flipped for the picture; the TIFF keeps the array order. Small images are
    enlarged by an integer nearest-neighbour factor (:func:`quicklook_factor`; every image pixel
    becomes a factor×factor block, so the picture's top-left block is image pixel (last row, 0)).

    With ``pixel_size_mm`` (the image pixel's (row, col) size, or one number), a strip below the
    picture holds a scale bar labelled in mm (``where``, e.g. ``"at the detector"``, is appended),
    and the PNG's text chunks ``mm_per_pixel`` (of the image, before enlarging), ``upscale`` and
    ``scale_bar`` say the same.
    """
    from PIL import Image, ImageDraw

    image = np.asarray(image, dtype=np.float64)
    peak = float(image.max()) if image.size else 0.0
    scaled = np.zeros(image.shape, np.uint8) if not peak > 0 else np.round(255 * np.clip(image / peak, 0, 1)).astype(np.uint8)
    factor = quicklook_factor(scaled.shape)
    picture = np.ascontiguousarray(np.repeat(np.repeat(scaled[::-1], factor, axis=0), factor, axis=1))
    info = png_text(upscale=str(factor))
    if pixel_size_mm is None:
        canvas = Image.fromarray(picture)
    else:
        pitch = float(np.atleast_1d(pixel_size_mm)[-1])  # the column pitch sets the horizontal bar
        length, bar_px = scale_bar_length(pitch / factor, picture.shape[1] / 4)
        label = f"{length:g} mm" + (f" {where}" if where else "")
        canvas = Image.new("L", (picture.shape[1], picture.shape[0] + _BAR_STRIP_PX), 0)
        canvas.paste(Image.fromarray(picture), (0, 0))
        draw = ImageDraw.Draw(canvas)
        top = picture.shape[0] + 6
        draw.rectangle([6, top, 6 + bar_px - 1, top + 3], fill=255)
        draw.text((12 + bar_px, picture.shape[0] + 4), label, fill=255)
        sizes = np.atleast_1d(pixel_size_mm).astype(float)
        info.add_text("mm_per_pixel", " x ".join(f"{s:g}" for s in sizes[::-1]) + " (x by y, image pixel)")
        info.add_text("scale_bar", label)
    return atomic_write(path, lambda tmp: canvas.save(tmp, format="PNG", pnginfo=info))


def scale_bar_length(mm_per_px: float, max_px: float) -> tuple[float, int]:
    """(mm, px): a round length (1, 2 or 5 × 10^k mm) whose bar spans at most ``max_px`` pixels
    (a quick-look's bar: a quarter of its width)."""
    target = max(max_px, 1) * mm_per_px
    power = 10.0 ** math.floor(math.log10(target))
    length = max((m * power for m in (1, 2, 5) if m * power <= target), default=power)
    return float(f"{length:.6g}"), max(1, round(length / mm_per_px))
