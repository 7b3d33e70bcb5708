"""A quick look at what a scan file's scan will give, before it runs: the middle slice of its grid
reconstructed from a cut-down scan, with its labels.

The cut-down scan is the file's own (the page's edits, its angle as the first view, its noise) with
at most :data:`VIEWS` views over the same arc, the detector binned to at most :data:`PIXELS`
columns (the same area, the same distances), and one slice of the grid (the middle one along z,
at most :data:`PIXELS` voxels across, over the same field). ``xr.scan`` runs it whole (sample,
projections, FDK, labels), so the slice shows the file's materials, noise and reconstruction
filter, at a coarser sampling than the real scan's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import ConfigError
from ..io.scan_file import load_scan_file
from ..pipeline.scan import scan
from .document import Document, View

VIEWS = 90
PIXELS = 128


@dataclass(frozen=True)
class QuickSlice:
    """The slice (cm⁻¹, (y, x)), its labels (same shape) and their names by value, where it lies
    (``z_mm``), what it took (``views``, ``detector_shape``, ``voxel_mm`` across) and its seconds."""

    image: np.ndarray
    labels: np.ndarray
    names: dict
    z_mm: float
    views: int
    detector_shape: tuple
    voxel_mm: float
    seconds: float


def quick_table(document: Document, view: View, loaded) -> dict:
    """The scan table of the cut-down scan of ``document`` as ``view`` shows it (module docstring)."""
    if document.kind != "scan":
        raise ConfigError(f"{document.path}: a slice needs a scan file (a volume grid and a sample); this is a "
                          "scene file")
    table = document.saved(view)
    geometry, old = table["geometry"], loaded.geometry
    if "vectors" in geometry:
        raise ConfigError(f"{document.path}: a quick slice bins a circular scan's detector; this file gives "
                          "per-view vectors")
    rows, cols = old.detector_shape
    k = max(1, math.ceil(cols / PIXELS))
    pitch = old.pixel_size[0] * k
    grid = loaded.volume
    nz, ny, nx = grid.shape
    z = grid.offset[0] + (nz // 2 - (nz - 1) / 2) * grid.voxel_size[0]
    # Only the rows the slice's rays reach: its height seen at the largest magnification (the far
    # side of the field of view), about the detector's centre wherever its offset puts that.
    reach = (abs(z) + grid.voxel_size[0]) * _largest_magnification(old, grid) + abs(old.detector_offset[0])
    geometry["detector_shape"] = [min(max(1, rows // k), 2 * math.ceil(reach / pitch) + 4), max(1, cols // k)]
    geometry["pixel_size"] = [pitch, old.pixel_size[1] * k]
    if "angles_deg" in geometry:
        geometry["angles_deg"] = geometry["angles_deg"][::max(1, math.ceil(len(geometry["angles_deg"]) / VIEWS))]
    else:
        geometry["num_views"] = min(len(old.angles), VIEWS)
    across = min(nx, PIXELS)
    f = nx / across
    table["volume"] = {"shape": [1, max(1, round(ny / f)), across],
                       "voxel_size": [grid.voxel_size[0], grid.voxel_size[1] * f, grid.voxel_size[2] * f],
                       "offset": [z, grid.offset[1], grid.offset[2]]}
    return table


def quick_slice(document: Document, view: View, loaded, *, gl=None, cl=None, threads=None) -> QuickSlice:
    """Run the cut-down scan (on the given GL and OpenCL contexts) and return its slice."""
    table = quick_table(document, view, loaded)
    cut = load_scan_file(table, where=f"{document.path} (quick slice)", base_dir=document.path.resolve().parent)
    result = scan(cut, gl=gl, cl=cl, threads=threads)
    names = {int(k): v for k, v in result.metadata["labels"].items()}
    return QuickSlice(result.volume.data[0], result.labels.data[0], names, table["volume"]["offset"][0],
                      cut.geometry.num_views, cut.geometry.detector_shape, table["volume"]["voxel_size"][2],
                      float(result.metadata["seconds"]["total"]))


def _largest_magnification(geometry, grid) -> float:
    """Detector over object distance for the grid's point nearest the source (1: a parallel beam)."""
    if not hasattr(geometry, "source_to_origin"):
        return 1.0
    _, ny, nx = grid.shape
    radius = math.hypot(ny * grid.voxel_size[1] / 2 + abs(grid.offset[1]),
                        nx * grid.voxel_size[2] / 2 + abs(grid.offset[2]))
    return geometry.source_to_detector / max(geometry.source_to_origin - radius, 1e-3 * geometry.source_to_origin)
