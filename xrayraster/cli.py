"""Command line: ``xrayraster render scene.toml -o out.tif`` (radiographs, or ``--path-lengths``),
``xrayraster reconstruct projections.tif --geometry scan.json -o volume.tif`` (FDK / FBP) and
``xrayraster voxelize scene.toml --volume scan.json -o labels.tif`` (label volumes)."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .config import ConfigError, load_scene_file
from .detector import Detector
from .geometry import GeometryError
from .geometry_io import geometry_from_repr, read_scan_file
from .glcontext import GLContextError
from .io import read_tiff, write_quicklook, write_tiff
from .label_volume import VoxelizeError, voxelize
from .materials import Material, MaterialError
from .mesh import MeshError
from .opencl import OpenCLError
from .physics import PhysicsError
from .radiograph import OUTPUTS
from .ramp_filter import FILTERS
from .reconstruction import INPUTS, ReconstructionError, fdk
from .render import Renderer, RenderError
from .scene import SceneError
from .spectrum import SpectrumError

USER_ERRORS = (
    ConfigError, GeometryError, GLContextError, MaterialError, MeshError, OpenCLError, PhysicsError, ReconstructionError,
    RenderError, SceneError, SpectrumError, VoxelizeError,
)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="xrayraster", description="X-ray CT simulation from triangle meshes.")
    parser.add_argument("--version", action="version", version=f"xrayraster {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render one or more views of a TOML scene")
    render.add_argument("scene", type=Path, help="scene file (docs/scene-format.md)")
    render.add_argument("-o", "--out", dest="out", metavar="OUT.tif", type=Path, required=True,
                        help="float32 TIFF to write (a PNG quick-look goes beside it)")
    render.add_argument("--output", choices=OUTPUTS, default=None,
                        help="radiograph quantity: raw detector signal, transmission, or lineint = -ln(transmission) (default lineint)")
    render.add_argument("--noise", action="store_true", help="add quantum (Poisson) and electronic noise")
    render.add_argument("--seed", type=int, default=None, help="noise seed (default 0; needs --noise)")
    render.add_argument("--path-lengths", action="store_true",
                        help="write per-material path lengths in mm instead of radiographs")
    render.add_argument("--views", default="0", help="comma-separated view indices, or 'all' (default: 0)")
    render.add_argument("--supersampling", type=int, default=1, help="k×k rays per pixel (default 1)")
    render.add_argument("--overlap", choices=("auto", "sum", "nested", "resolve"), default="auto", help="overlap handling (default auto)")
    render.add_argument("-v", "--verbose", action="store_true")
    rec = sub.add_parser("reconstruct", help="FDK (cone beam) or FBP (parallel beam) reconstruction of a projection stack")
    rec.add_argument("projections", type=Path, help="TIFF stack (views, rows, cols), e.g. from 'xrayraster render --views all'")
    rec.add_argument("--geometry", metavar="SCAN.json", type=Path, required=True,
                     help="scan file: the volume grid, and the scan geometry unless the TIFF carries it (docs/reconstruction.md)")
    rec.add_argument("-o", "--out", dest="out", metavar="VOLUME.tif", type=Path, required=True,
                     help="float32 TIFF volume (z, y, x) in 1/cm (a PNG of the central slice goes beside it)")
    rec.add_argument("--filter", choices=FILTERS, default="ram-lak", help="ramp filter window (default ram-lak)")
    rec.add_argument("--cutoff", type=float, default=1.0, help="filter cut-off, fraction of Nyquist (default 1)")
    rec.add_argument("--scan", choices=("auto", "full", "short"), default="auto",
                     help="full circle (redundancy ½ or displaced-detector weights) or short scan (Parker); default auto")
    rec.add_argument("--input", choices=INPUTS, default=None,
                     help="what the TIFF holds (default: its metadata, written by 'xrayraster render', else lineint)")
    rec.add_argument("--device", default=None, help="OpenCL device: 'P:D' or part of its name (default: the fastest)")
    rec.add_argument("-v", "--verbose", action="store_true")
    vox = sub.add_parser("voxelize", help="label volume of a TOML scene on a voxel grid (the reconstruction's)")
    vox.add_argument("scene", type=Path, help="scene file (docs/scene-format.md): objects, labels, priorities")
    vox.add_argument("--volume", metavar="SCAN.json", type=Path, required=True,
                     help="scan file whose 'volume' gives the voxel grid (docs/reconstruction.md)")
    vox.add_argument("-o", "--out", dest="out", metavar="LABELS.tif", type=Path, required=True,
                     help="uint8 (uint16 above 255 labels) TIFF (z, y, x); a PNG of the central slice goes beside it")
    vox.add_argument("--fractions", metavar="K", type=int, default=None,
                     help="also write partial-volume shares per label from K×K×K sub-voxels (float32 (z, label, y, x), "
                          "OUT_fractions.tif)")
    vox.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        return {"reconstruct": _reconstruct, "voxelize": _voxelize}.get(args.command, _render)(args)
    except USER_ERRORS as exc:
        print(f"xrayraster: error: {exc}", file=sys.stderr)
        return 2


def _render(args) -> int:
    if args.path_lengths:
        ignored = [flag for flag, given in (("--output", args.output is not None), ("--noise", args.noise),
                                             ("--seed", args.seed is not None)) if given]
        if ignored:
            raise ConfigError(f"{', '.join(ignored)} appl(y/ies) to radiographs, not to --path-lengths; drop one or the other")
        return _render_path_lengths(args)
    if args.seed is not None and not args.noise:
        raise ConfigError("--seed needs --noise (without noise the radiograph is the expected value)")
    return _render_radiographs(args)


def _material_name(material) -> str:
    return material.name if isinstance(material, Material) else str(material)


def _render_path_lengths(args) -> int:
    loaded = load_scene_file(args.scene)
    geometry, scene = loaded.geometry, loaded.scene
    views = _views(args.views, geometry.num_views)
    start = time.perf_counter()
    with Renderer(geometry, supersampling=args.supersampling, overlap=args.overlap) as renderer:
        stack = np.stack([renderer.path_lengths(scene, v) for v in views])
        method, driver = renderer.last_method, renderer.gl.renderer
    seconds = time.perf_counter() - start
    info = {
        "quantity": "path length",
        "units": "mm",
        "axes": "view, material, row, col",
        "materials": [_material_name(m) for m in scene.materials],
        "views": views,
        "geometry": repr(geometry[views]),
        "supersampling": args.supersampling,
        "method": method,
        "renderer": driver,
        "scene_file": str(args.scene),
    }
    out = write_tiff(args.out, stack, axes="TCYX", pixel_size_mm=geometry.pixel_size, info=info)
    png = write_quicklook(args.out.with_suffix(".png"), stack[0].sum(axis=0))
    print(
        f"{out}: {len(views)} view(s) × {len(scene.materials)} material(s) × {stack.shape[2]}×{stack.shape[3]} "
        f"px, max {stack.max():.4f} mm, {method} pass, {seconds:.2f} s on {driver}; quick-look {png}"
    )
    return 0


QUANTITIES = {
    "raw": "raw detector signal (flat-field-free: open beam, dark offset and noise included)",
    "transmission": "transmission (raw - dark) / (flat - dark)",
    "lineint": "line integral -ln(transmission)",
}


def radiograph_units(output: str, counting: bool) -> str:
    """Units of a radiograph TIFF: raw signal in keV deposited (integrating) or counts; normalised ones are ratios."""
    if output == "raw":
        return "counts" if counting else "keV deposited"
    return "1"  # transmission and its -ln are dimensionless


def _render_radiographs(args) -> int:
    loaded = load_scene_file(args.scene)
    missing = [what for what, absent in (
        ("a [source] table (the X-ray spectrum)", loaded.spectrum is None),
        ("a [materials] table (composition and density of every object's material)", loaded.materials is None),
    ) if absent]
    if missing:
        raise ConfigError(
            f"{args.scene}: radiographs need {' and '.join(missing)}; add {'them' if len(missing) > 1 else 'it'} "
            "(docs/scene-format.md), or pass --path-lengths to write path lengths only"
        )
    geometry, scene, spectrum = loaded.geometry, loaded.scene, loaded.spectrum
    detector = loaded.detector if loaded.detector is not None else Detector()
    output = args.output or "lineint"
    seed = (0 if args.seed is None else args.seed) if args.noise else None
    views = _views(args.views, geometry.num_views)
    start = time.perf_counter()
    with Renderer(geometry, supersampling=args.supersampling, overlap=args.overlap) as renderer:
        shots = [renderer.project(scene, spectrum, v, detector=detector, output=output, noise=args.noise, seed=seed)
                 for v in views]
        method, driver = renderer.last_method, renderer.gl.renderer
    seconds = time.perf_counter() - start
    stack = np.stack([shot.image for shot in shots])
    starved = [shot.starved for shot in shots]
    units = radiograph_units(output, detector.counting)
    info = {
        "quantity": QUANTITIES[output],
        "output": output,
        "units": units,
        "axes": "view, row, col",
        "materials": [_material_name(m) for m in scene.materials],
        "material_compositions": [repr(m) for m in scene.materials],
        "views": views,
        "geometry": repr(geometry[views]),
        "spectrum": spectrum.description,
        "spectrum_photons_per_mm2_at_1m": spectrum.total,
        "spectrum_bins": spectrum.n_bins,
        "detector": repr(detector),
        "bins_used": [shot.bins for shot in shots],
        "dropped_signal_share": [shot.dropped for shot in shots],
        "starved_pixels": starved,
        "noise": bool(args.noise),
        "seed": seed,
        "supersampling": args.supersampling,
        "method": method,
        "renderer": driver,
        "scene_file": str(args.scene),
    }
    out = write_tiff(args.out, stack, axes="TYX", pixel_size_mm=geometry.pixel_size, info=info)
    png = write_quicklook(args.out.with_suffix(".png"), stack[0])
    extras = []
    if args.noise:
        extras.append(f"noise seed {seed}")
    if any(starved):
        extras.append(f"{sum(starved)} starved pixel(s) clamped ({', '.join(map(str, starved))} per view)")
    print(
        f"{out}: {len(views)} view(s) × {stack.shape[1]}×{stack.shape[2]} px {output} radiograph"
        f" [{units}], range {stack.min():.4g} to {stack.max():.4g}, {shots[0].bins} energy bins"
        + "".join(f", {e}" for e in extras)
        + f", {method} pass, {seconds:.2f} s on {driver}; quick-look {png}"
    )
    return 0


def _reconstruct(args) -> int:
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
        geometry = geometry_from_repr(info["geometry"])
    kind = args.input or info.get("output", "lineint")
    if kind == "raw":
        raise ConfigError(f"{args.projections} holds the raw detector signal; render with --output lineint or "
                          "transmission (flat- and dark-corrected) to reconstruct")
    start = time.perf_counter()
    vol = fdk(stack, geometry, volume, filter=args.filter, cutoff=args.cutoff, scan=args.scan, input=kind,
              device=args.device)
    seconds = time.perf_counter() - start
    vz, vy, vx = volume.voxel_size
    out = write_tiff(args.out, vol.data, axes="ZYX", pixel_size_mm=(vy, vx), spacing_mm=vz, info={
        "quantity": "linear attenuation coefficient (FDK)" if geometry.beam == "cone" else "linear attenuation coefficient (FBP)",
        "units": vol.unit,
        "axes": "z, y, x",
        "volume_geometry": repr(volume),
        "geometry": repr(geometry),
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


def _voxelize(args) -> int:
    loaded = load_scene_file(args.scene)
    _, volume = read_scan_file(args.volume)
    start = time.perf_counter()
    labels = voxelize(loaded.scene, volume, fractions=args.fractions)
    seconds = time.perf_counter() - start
    names: dict[int, list[str]] = {}
    for o in loaded.scene.objects:
        names.setdefault(o.label, []).append(o.name)
    vz, vy, vx = volume.voxel_size
    out = write_tiff(args.out, labels.data, axes="ZYX", pixel_size_mm=(vy, vx), spacing_mm=vz, info={
        "quantity": "label (0: background; else the label of the highest-priority object at the voxel centre)",
        "axes": "z, y, x",
        "labels": {str(k): v for k, v in sorted(names.items())},
        "volume_geometry": repr(volume),
        "scene_file": str(args.scene),
    })
    if labels.fractions is not None:
        shares = args.out.with_name(f"{args.out.stem}_fractions.tif")
        # ImageJ hyperstacks are ordered T Z C Y X: one channel per label.
        write_tiff(shares, labels.fractions.transpose(1, 0, 2, 3), axes="ZCYX", pixel_size_mm=(vy, vx), spacing_mm=vz,
                   info={"quantity": f"share of each voxel owned by each label, from {args.fractions}³ sub-voxel centres",
                         "axes": "z, label, y, x", "channel_labels": list(labels.labels), "volume_geometry": repr(volume)})
    png = write_quicklook(args.out.with_suffix(".png"), labels.data[labels.data.shape[0] // 2].astype(np.float32))
    counts = np.bincount(labels.data.ravel())
    present = ", ".join(f"{k}: {counts[k]}" for k in np.flatnonzero(counts) if k)
    print(f"{out}: {'×'.join(map(str, labels.data.shape))} {labels.data.dtype} labels (z, y, x) of {vz:g}×{vy:g}×{vx:g} mm, "
          f"voxels per label {{{present}}}, {seconds:.2f} s; central slice {png}")
    return 0


def _views(text: str, num_views: int) -> list[int]:
    if text == "all":
        return list(range(num_views))
    try:
        views = [int(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(f"--views must be comma-separated integers or 'all', got {text!r}") from None
    bad = [v for v in views if not 0 <= v < num_views]
    if bad:
        raise ConfigError(f"--views {bad} out of range: the scene has {num_views} views (0..{num_views - 1})")
    return views


if __name__ == "__main__":
    sys.exit(main())
