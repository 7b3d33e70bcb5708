"""The truncation correction on objects wider than the field of view: interior bias by extrapolation width.

    python -m scripts.truncation_table            # 8 objects × 5 settings (~6 s on 2 cores)
    python -m scripts.truncation_table --quick    # the 1.5× cylinder and the 3× slab only

The geometry of docs/reconstruction.md's table: cone beam, source 200 mm and detector 400 mm from
the axis, 16 × 96 pixels of 1 mm, 180 views over 360°, a 2-slice grid of 96² voxels across the
field of view (radius 23.8 mm). Objects, μ 0.02 mm⁻¹, infinitely tall: cylinders of 0.8-3× the
field of view's radius (projected exactly, references/phantoms.py) and slabs of half-width 3× and
6× and half-thickness 0.3× it (exact box chords, references/chords.py). Each is reconstructed with
``xr.fdk`` without the correction, with it at truncation widths 0.25, 0.5 (the default) and 1.0
and the object's reach unknown, and told its reach (``object_radius_mm``: the cylinder's radius,
the slab's corner). Error: the mean of μ̂/μ − 1 inside the object and 0.9 of the field of view's
radius (the interior bias; cupping and rims are in it), printed beside each reconstruction's time.
"""

from __future__ import annotations

import math
import time

import numpy as np

import xrayraster as xr
from references.chords import box_chord, cone_rays
from references.phantoms import Ellipsoid, project

from .common import announce, conclude, outputs, parser, say

SOURCE, DETECTOR, ROWS, COLS, VIEWS, VOXELS = 200.0, 400.0, 16, 96, 180, 96
MU = 0.02  # mm⁻¹
FOV = SOURCE * math.sin(math.atan(COLS / 2 / DETECTOR))  # mm: the radius every view sees
GEOMETRY = xr.ConeBeamGeometry(SOURCE, DETECTOR, (ROWS, COLS), 1.0, xr.full_circle(VIEWS))
VOLUME = xr.VolumeGeometry((2, VOXELS, VOXELS), 2 * FOV / VOXELS)
SETTINGS = {"off": {"truncation": False}, "width 0.25": {"truncation_width": 0.25},
            "width 0.5 (default)": {}, "width 1.0": {"truncation_width": 1.0}, "reach known": None}


def phantom(shape: str, scale: float) -> tuple[np.ndarray, float, np.ndarray]:
    """Line integrals (float32), the object's reach about the axis (mm) and the scored voxels (y, x)."""
    y, x = np.meshgrid(*(np.arange(VOXELS) - (VOXELS - 1) / 2,) * 2, indexing="ij")
    radius = np.hypot(x, y) / (VOXELS / 2)  # share of the FOV radius
    if shape == "cylinder":
        p = project([Ellipsoid((0.0, 0.0, 0.0), (scale * FOV, scale * FOV, 1e5), 0.0, MU)], GEOMETRY)
        return p.astype(np.float32), scale * FOV, (radius < 0.9) & (radius < 0.9 * scale)
    half = np.array([scale * FOV, 0.3 * FOV, 1e5])
    p = np.stack([box_chord(*cone_rays(SOURCE, DETECTOR, (ROWS, COLS), 1.0, theta), np.zeros(3), np.eye(3), half) * MU
                  for theta in GEOMETRY.angles])
    return p.astype(np.float32), float(np.hypot(half[0], half[1])), (radius < 0.9) & (np.abs(y) / (VOXELS / 2) < 0.27)


def main(argv=None) -> int:
    args = outputs(parser(__doc__, "the 1.5× cylinder and the 3× slab only").parse_args(argv), "truncation_table")
    t_start = time.perf_counter()
    cl = xr.CLContext()
    command, machine = announce(cl=cl)
    objects = [("slab", 3.0), ("cylinder", 1.5)] if args.quick else \
        [("cylinder", k) for k in (0.8, 1.05, 1.2, 1.5, 2.0, 3.0)] + [("slab", 3.0), ("slab", 6.0)]
    say(f"field of view radius {FOV:.2f} mm; interior bias (of μ) and seconds per reconstruction")
    say(f"{'object':14s}" + "".join(f"{name:>24s}" for name in SETTINGS))
    records = []
    for shape, scale in objects:
        p, reach, scored = phantom(shape, scale)
        record = {"object": shape, "scale": scale, "reach_mm": reach}
        for name, options in SETTINGS.items():
            t = time.perf_counter()
            options = {"object_radius_mm": reach} if options is None else options
            volume = xr.fdk(p, GEOMETRY, VOLUME, context=cl, **options)
            seconds = time.perf_counter() - t
            record[name] = {"bias": float((volume.data[:, scored] / 10 / MU - 1).mean()), "seconds": seconds,
                            "corrected_row_ends": volume.provenance["truncation_corrected_row_ends"]}
        records.append(record)
        say(f"{shape + ' ' + format(scale, 'g') + '×':14s}"
            + "".join(f"{record[n]['bias']:+15.4f} {record[n]['seconds']:6.2f} s" for n in SETTINGS))
    conclude(args.json, {"command": command, "machine": machine, "fov_radius_mm": FOV, "records": records}, machine,
             t_start)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
