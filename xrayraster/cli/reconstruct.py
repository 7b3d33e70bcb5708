"""``xrayraster reconstruct PROJECTIONS.tif --grid GRID.json -o VOLUME.tif``: FDK or FBP of a projection stack."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

from ..core.choices import FILTERS, RECONSTRUCTION_INPUTS, SCAN_KINDS
from ..core.errors import ConfigError
from ..core.geometry import geometry_from_dict
from ..core.inputs import read_tiff_file
from ..core.tiff import quicklook_path
from ..io.grid_file import read_grid_file
from ..recon.fdk import fdk
from ..recon.truncation import DEFAULT_WIDTH
from .options import add_grid, note_deprecated
from .outputs import check_outputs

GEOMETRY_SOURCES = ("grid", "projections")
SWITCH = {"auto": "auto", "on": True, "off": False}  # --displaced, --truncation

# Angular sampling. The usual rule asks for about (π/2)·N views over the scan for a grid N voxels
# across (its larger transverse side): then the arc between neighbouring views at the grid's edge
# is about one voxel (Kak & Slaney, ch. 5). Fewer views give streaks, at first faint; below a
# quarter of the rule (neighbouring views four or more voxels apart at the edge) they cross the
# whole slice and are easily mistaken for structure, so the command warns (a sparse-view study
# may mean it: the warning does not stop it). The bundled example's 4 views warn on any grid more
# than 10 voxels across (4 < ¼·(π/2)·N for N ≥ 11).
UNDERSAMPLED_SHARE = 0.25


def _geometry_source(text: str) -> str:
    """``--geometry-from``'s value; ``scan-file``, the grid file's older name, still works and says so."""
    if text == "scan-file":
        note_deprecated("--geometry-from scan-file", "--geometry-from grid")
        return "grid"
    return text


def views_needed(volume) -> float:
    """(π/2)·N views for a grid N voxels across its larger transverse side (y, x)."""
    return math.pi / 2 * max(volume.shape[1], volume.shape[2])


def add_parser(subparsers) -> None:
    rec = subparsers.add_parser("reconstruct", help="FDK (cone beam) or FBP (parallel beam) reconstruction of a projection stack")
    rec.add_argument("projections", type=Path, help="TIFF stack (views, rows, cols), e.g. from 'xrayraster render --views all'")
    add_grid(rec, "grid file: the volume grid, and the scan geometry unless the TIFF carries it "
                       "(docs/reconstruction.md)", deprecated="--geometry")
    rec.add_argument("--geometry-from", choices=GEOMETRY_SOURCES, type=_geometry_source, default=None,
                     help="which scan geometry to use when the grid file and the TIFF's metadata both give one "
                          "(default: they must agree)")
    rec.add_argument("-o", "--out", dest="out", metavar="VOLUME.tif", type=Path, required=True,
                     help="float32 TIFF volume (z, y, x) in 1/cm (a PNG of the central slice goes beside it)")
    rec.add_argument("--filter", choices=FILTERS, default="ram-lak", help="ramp filter window (default ram-lak)")
    rec.add_argument("--cutoff", type=float, default=1.0, help="filter cut-off, fraction of Nyquist (default 1)")
    rec.add_argument("--scan", choices=SCAN_KINDS, default="auto",
                     help="full circle (redundancy ½ or displaced-detector weights) or short scan (Parker); default auto")
    rec.add_argument("--displaced", choices=tuple(SWITCH), default="auto",
                     help="full scans: Wang's displaced-detector weights on, off, or chosen from the detector's "
                          "coverage of the axis and the object's reach (default auto; the choice is logged with -v)")
    rec.add_argument("--object-radius", type=float, default=None, metavar="MM",
                     help="the radius about the rotation axis outside which nothing attenuates, which --displaced "
                          "auto weighs and the truncation correction extrapolates to (default: the grid's farthest "
                          "corner, and --truncation-width)")
    rec.add_argument("--truncation", choices=tuple(SWITCH), default="auto",
                     help="extrapolate rows cut off by the detector's edges (an object wider than the field of "
                          "view): the rows with signal at an edge (default auto), every row, or none")
    rec.add_argument("--truncation-width", type=float, default=DEFAULT_WIDTH, metavar="SHARE",
                     help=f"how far the rows are extrapolated on each side without --object-radius, a share of "
                          f"the detector width (default {DEFAULT_WIDTH})")
    rec.add_argument("--input", choices=RECONSTRUCTION_INPUTS, default=None,
                     help="what the TIFF holds (default: its metadata, written by 'xrayraster render', else lineint)")
    rec.add_argument("--device", default=None, help="OpenCL device: 'P:D' or part of its name (default: the fastest)")
    rec.add_argument("-v", "--verbose", action="store_true")
    rec.set_defaults(run=run)


def same_geometry(a, b) -> bool:
    """Whether two scan geometries describe the same scan (to rounding: 1e-9 relative)."""
    if a == b:
        return True
    if type(a) is not type(b) or a.beam != b.beam or a.detector_shape != b.detector_shape or a.num_views != b.num_views:
        return False
    va, vb = a.to_vec().array, b.to_vec().array
    return bool(np.allclose(va, vb, rtol=1e-9, atol=1e-9 * max(1.0, float(np.abs(va).max()))))


def _differences(a, b) -> str:
    da, db = a.to_dict(), b.to_dict()
    if a.num_views != b.num_views:
        da["num_views"], db["num_views"] = a.num_views, b.num_views
    keys = [k for k in dict.fromkeys([*da, *db]) if da.get(k) != db.get(k)]
    return ", ".join(f"{k} {da.get(k, '-')} vs {db.get(k, '-')}" for k in keys[:3]) or "values differ"


def choose_geometry(args, scan_geometry, info):
    """The scan geometry to use and where it came from (grid file, projections' metadata, or both)."""
    grid, proj = str(args.grid), f"{args.projections} metadata"

    def from_tiff():
        if "geometry" not in info:
            return None
        if not isinstance(info["geometry"], dict):
            if args.geometry_from == "projections" or scan_geometry is None:
                raise ConfigError(f"{args.projections} carries its geometry in an older form (a Python repr); add the "
                                  f"scan geometry to {args.grid} (docs/reconstruction.md)")
            return None
        return geometry_from_dict(info["geometry"], f"{proj} geometry")

    if args.geometry_from == "grid":
        if scan_geometry is None:
            raise ConfigError(f"--geometry-from grid: {args.grid} has no 'geometry'; add it or drop the flag")
        return scan_geometry, f"grid file {grid}"
    tiff_geometry = from_tiff()
    if args.geometry_from == "projections":
        if tiff_geometry is None:
            raise ConfigError(f"--geometry-from projections: {args.projections} carries no geometry in its metadata; "
                              "use the grid file's (drop the flag)")
        return tiff_geometry, f"projections {proj}"
    if scan_geometry is None and tiff_geometry is None:
        raise ConfigError(f"{args.grid} has no 'geometry' and {args.projections} carries none in its metadata; "
                          "add the scan geometry to the grid file (docs/reconstruction.md)")
    if tiff_geometry is None:
        return scan_geometry, f"grid file {grid}"
    if scan_geometry is None:
        return tiff_geometry, proj
    if not same_geometry(scan_geometry, tiff_geometry):
        raise ConfigError(f"the scan geometries of {grid} and {proj} differ ({_differences(scan_geometry, tiff_geometry)}); "
                          "choose one with --geometry-from grid or --geometry-from projections")
    return scan_geometry, f"grid file {grid} (equal to the projections')"


def run(args) -> int:
    check_outputs([args.out, quicklook_path(args.out)], [args.projections, args.grid])
    scan_geometry, volume = read_grid_file(args.grid)
    stack, info = read_tiff_file(args.projections, "projections")  # info {}: from elsewhere, the grid file gives the geometry
    if info.get("quantity") == "path length":
        raise ConfigError(f"{args.projections} holds path lengths per material; reconstruct radiographs "
                          "(xrayraster render without --path-lengths)")
    if stack.ndim == 2:
        stack = stack[None]
    geometry, source = choose_geometry(args, scan_geometry, info)
    kind = args.input or info.get("output", "lineint")
    if kind == "raw":
        raise ConfigError(f"{args.projections} holds the raw detector signal; render with --output lineint or "
                          "transmission (flat- and dark-corrected) to reconstruct")
    needed = views_needed(volume)
    if stack.shape[0] < UNDERSAMPLED_SHARE * needed:
        n = max(volume.shape[1], volume.shape[2])
        print(f"xrayraster: warning: {stack.shape[0]} views for a grid {n} voxels across is under-sampled: the "
              f"angular-sampling rule asks for about π/2·{n} ≈ {needed:.0f}; expect streaks", file=sys.stderr)
    start = time.perf_counter()
    vol = fdk(stack, geometry, volume, filter=args.filter, cutoff=args.cutoff, scan=args.scan, input=kind,
              displaced=SWITCH[args.displaced], object_radius_mm=args.object_radius, truncation=SWITCH[args.truncation],
              truncation_width=args.truncation_width, device=args.device)
    seconds = time.perf_counter() - start
    vz, vy, vx = volume.voxel_size
    vol = dataclasses.replace(vol, provenance={**vol.provenance, "geometry_source": source,
                                               "projections_file": str(args.projections)})
    out = vol.save(args.out)
    png = quicklook_path(out)
    print(f"{out}: {'×'.join(map(str, vol.data.shape))} voxels (z, y, x) of {vz:g}×{vy:g}×{vx:g} mm, "
          f"{vol.unit}, range {vol.data.min() + 0.0:.4g} to {vol.data.max() + 0.0:.4g}, {stack.shape[0]} views, "
          f"geometry from {source}, {seconds:.2f} s; central slice {png}")
    return 0
