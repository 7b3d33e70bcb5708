"""``xrayraster voxelize SCENE.toml --grid GRID.json -o LABELS.tif``: label volumes on a grid file's voxel grid."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from ..core.tiff import quicklook_path
from ..gl.voxelize import fractions_path, voxelize
from ..io.grid_file import read_grid_file
from ..io.scene_file import load_scene_file
from .options import add_grid, positive_int
from .outputs import check_outputs


def add_parser(subparsers) -> None:
    vox = subparsers.add_parser("voxelize", help="label volume of a TOML scene on a voxel grid (the reconstruction's)")
    vox.add_argument("scene", type=Path, help="scene file (docs/scene-format.md): objects, labels, priorities")
    add_grid(vox, "grid file whose 'volume' gives the voxel grid (docs/reconstruction.md)", deprecated="--volume")
    vox.add_argument("-o", "--out", dest="out", metavar="LABELS.tif", type=Path, required=True,
                     help="uint8 (uint16 above 255 labels) TIFF (z, y, x); a PNG of the central slice goes beside it")
    vox.add_argument("--fractions", metavar="K", type=positive_int, default=None,
                     help="also write partial-volume shares per label from K×K×K sub-voxels (float32 (z, label, y, x), "
                          "OUT_fractions.tif)")
    vox.add_argument("-v", "--verbose", action="store_true")
    vox.set_defaults(run=run)


def run(args) -> int:
    side = [quicklook_path(args.out)] + ([fractions_path(args.out)] if args.fractions is not None else [])
    check_outputs([args.out, *side], [args.scene, args.grid])
    loaded = load_scene_file(args.scene)
    _, volume = read_grid_file(args.grid)
    start = time.perf_counter()
    labels = voxelize(loaded.scene, volume, fractions=args.fractions)
    seconds = time.perf_counter() - start
    names: dict[int, list[str]] = {}
    for o in loaded.scene.objects:
        names.setdefault(o.label, []).append(o.name)
    vz, vy, vx = volume.voxel_size
    labels = dataclasses.replace(labels, provenance={"labels": {str(k): v for k, v in sorted(names.items())},
                                                     "scene_file": str(args.scene)})
    out = labels.save(args.out)
    png = quicklook_path(out)
    counts = np.bincount(labels.data.ravel())
    present = ", ".join(f"{k}: {counts[k]}" for k in np.flatnonzero(counts) if k)
    print(f"{out}: {'×'.join(map(str, labels.data.shape))} {labels.data.dtype} labels (z, y, x) of {vz:g}×{vy:g}×{vx:g} mm, "
          f"voxels per label {{{present}}}, {seconds:.2f} s; central slice {png}")
    return 0


