"""``xrayraster reconstruct PROJECTIONS.tif --geometry SCAN.json -o VOLUME.tif``: FDK or FBP of a projection stack."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..core.choices import FILTERS, RECONSTRUCTION_INPUTS, SCAN_KINDS
from ..core.errors import ConfigError
from ..core.geometry import geometry_from_dict
from ..io.scan_file import read_scan_file
from ..io.tiff import read_tiff, write_quicklook, write_volume
from ..recon.fdk import fdk


def add_parser(subparsers) -> None:
    rec = subparsers.add_parser("reconstruct", help="FDK (cone beam) or FBP (parallel beam) reconstruction of a projection stack")
    rec.add_argument("projections", type=Path, help="TIFF stack (views, rows, cols), e.g. from 'xrayraster render --views all'")
    rec.add_argument("--geometry", metavar="SCAN.json", type=Path, required=True,
                     help="scan file: the volume grid, and the scan geometry unless the TIFF carries it (docs/reconstruction.md)")
    rec.add_argument("-o", "--out", dest="out", metavar="VOLUME.tif", type=Path, required=True,
                     help="float32 TIFF volume (z, y, x) in 1/cm (a PNG of the central slice goes beside it)")
    rec.add_argument("--filter", choices=FILTERS, default="ram-lak", help="ramp filter window (default ram-lak)")
    rec.add_argument("--cutoff", type=float, default=1.0, help="filter cut-off, fraction of Nyquist (default 1)")
    rec.add_argument("--scan", choices=SCAN_KINDS, default="auto",
                     help="full circle (redundancy ½ or displaced-detector weights) or short scan (Parker); default auto")
    rec.add_argument("--input", choices=RECONSTRUCTION_INPUTS, default=None,
                     help="what the TIFF holds (default: its metadata, written by 'xrayraster render', else lineint)")
    rec.add_argument("--device", default=None, help="OpenCL device: 'P:D' or part of its name (default: the fastest)")
    rec.add_argument("-v", "--verbose", action="store_true")
    rec.set_defaults(run=run)


def run(args) -> int:
    geometry, volume = read_scan_file(args.geometry)
    try:
        stack, info = read_tiff(args.projections)  # info {}: from elsewhere, the scan file gives the geometry
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{args.projections}: cannot read a TIFF stack ({exc})") from None
    if info.get("quantity") == "path length":
        raise ConfigError(f"{args.projections} holds path lengths per material; reconstruct radiographs "
                          "(xrayraster render without --path-lengths)")
    if stack.ndim == 2:
        stack = stack[None]
    if geometry is None:
        if "geometry" not in info:
            raise ConfigError(f"{args.geometry} has no 'geometry' and {args.projections} carries none in its metadata; "
                              "add the scan geometry to the scan file (docs/reconstruction.md)")
        if not isinstance(info["geometry"], dict):
            raise ConfigError(f"{args.projections} carries its geometry in an older form (a Python repr); add the scan "
                              f"geometry to {args.geometry} (docs/reconstruction.md)")
        geometry = geometry_from_dict(info["geometry"], f"{args.projections} metadata geometry")
    kind = args.input or info.get("output", "lineint")
    if kind == "raw":
        raise ConfigError(f"{args.projections} holds the raw detector signal; render with --output lineint or "
                          "transmission (flat- and dark-corrected) to reconstruct")
    start = time.perf_counter()
    vol = fdk(stack, geometry, volume, filter=args.filter, cutoff=args.cutoff, scan=args.scan, input=kind,
              device=args.device)
    seconds = time.perf_counter() - start
    vz, vy, vx = volume.voxel_size
    out = write_volume(args.out, vol.data, volume, {
        "quantity": "linear attenuation coefficient (FDK)" if geometry.beam == "cone" else "linear attenuation coefficient (FBP)",
        "units": vol.unit,
        "geometry": geometry.to_dict(),
        "filter": args.filter,
        "cutoff": args.cutoff,
        "scan": args.scan,
        "input": kind,
        "projections_file": str(args.projections),
    })
    png = write_quicklook(args.out.with_suffix(".png"), np.clip(vol.data[vol.data.shape[0] // 2], 0, None))
    print(f"{out}: {'×'.join(map(str, vol.data.shape))} voxels (z, y, x) of {vz:g}×{vy:g}×{vx:g} mm, "
          f"{vol.unit}, range {vol.data.min():.4g} to {vol.data.max():.4g}, {stack.shape[0]} views, "
          f"{seconds:.2f} s; central slice {png}")
    return 0


