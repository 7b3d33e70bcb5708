"""Each weave family seen from its side and through a scan, for docs/weave.md ("Families").

For every family, ``examples/twin_small.toml`` with ``[weave] family`` set (and ``cells``, and the
satin's spacings, so the sample stays about 20 mm across), one row of ``docs/images/weave_families.png``:

* the path length through its warp yarns in a parallel beam along the weft (x): the binders'
  paths through the thickness, the stuffers end on, a 2D weave's warps undulating in each ply;
* the scan's reconstruction (``xr.scan``: 120 noisy views of 128 columns, 0.23 mm voxels) and its
  labels on the y–z plane through the voxel column that holds the most warp.

Usage::

    python -m scripts.weave_families [--out-dir docs/images]     # ~2 min on 2 cores
"""

from __future__ import annotations

import argparse
import math
import time
import tomllib
from pathlib import Path

import numpy as np

import xrayraster as xr
from xrayraster.core.transform import Transform
from xrayraster.pipeline import load_scan_file

from .common import DOCS, ROOT, say

CELLS = {"layer_to_layer": [2, 2], "orthogonal": [1, 2], "through_thickness_angle_interlock": [2, 1],
         "offset_angle_interlock": [2, 1], "plain": [4, 4], "twill": [2, 2], "satin": [2, 2]}
FIELDS = {"satin": {"warp_spacing": 2.0, "weft_spacing": 2.0}}  # a 10 mm cell, as the twill's
LABEL_COLOURS = np.array([[0, 0, 0], [90, 90, 90], [230, 160, 40], [60, 140, 230]], np.uint8)  # air, matrix, weft, warp


def scan_table(family: str) -> dict:
    table = tomllib.loads((ROOT / "examples" / "twin_small.toml").read_text())
    table["weave"]["family"] = family
    table["weave"].update(FIELDS.get(family, {}))
    table["weave"]["sample"]["cells"] = CELLS[family]
    return table


def side_view(loaded) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The warps' path length (mm) with the beam along the sample's x, and the picture's extent (mm)."""
    sample = loaded.weave.sample
    lo, hi = sample.box
    # the beam runs along the scanner's y at angle 0: the sample's x turned onto it, z stays the axis
    place = Transform.rotation((0.0, 0.0, 1.0), math.pi / 2) @ Transform.translation(-(lo + hi) / 2)
    scene = sample.scene(loaded.weave.materials, transform=place)
    size = hi - lo
    pixel = 0.04
    rows, cols = (int(math.ceil(size[i] * 1.04 / pixel)) for i in (2, 1))
    with xr.Renderer(xr.ParallelBeamGeometry((rows, cols), pixel, (0.0,))) as renderer:
        lengths = renderer.path_lengths(scene, 0)
    warp = [i for i, m in enumerate(scene.materials) if any(o.label == 3 and o.material == m for o in scene.objects)]
    return lengths[warp].sum(axis=0), (-cols * pixel / 2, cols * pixel / 2, -rows * pixel / 2, rows * pixel / 2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out-dir", type=Path, default=DOCS / "images")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    families = list(CELLS)
    fig, axes = plt.subplots(len(families), 3, figsize=(13.5, 1.55 * len(families)), constrained_layout=True)
    for row, family in zip(axes, families):
        loaded = load_scan_file(scan_table(family), base_dir=ROOT / "examples")
        start = time.perf_counter()
        side, extent = side_view(loaded)
        result = xr.scan(loaded)
        volume, labels = result.volume.data, result.labels.data
        column = int(np.argmax((labels == 3).sum(axis=(0, 1))))
        cell = loaded.weave.sample.cell
        row[0].imshow(side, origin="lower", cmap="magma", extent=extent, aspect="equal")
        row[0].set_title(f"{family}: warp path length (beam along x)", fontsize=9)
        row[0].set_xlabel("y (mm)")
        row[0].set_ylabel("z (mm)")
        row[1].imshow(volume[:, :, column], origin="lower", cmap="gray", aspect="equal")
        row[1].set_title(f"reconstruction, y–z plane at x voxel {column}", fontsize=9)
        row[2].imshow(LABEL_COLOURS[labels[:, :, column]], origin="lower", aspect="equal")
        row[2].set_title("labels: matrix grey, weft orange, warp blue", fontsize=9)
        for ax in row[1:]:
            ax.set_axis_off()
        say(f"{family}: cell {cell.size} mm, {loaded.weave.sample.cells} cells, "
            f"{result.metadata['triangles']} triangles, {time.perf_counter() - start:.1f} s")
    args.out_dir.mkdir(parents=True, exist_ok=True)
    out = args.out_dir / "weave_families.png"
    fig.savefig(out, dpi=80)
    plt.close(fig)
    say(f"{out}")


if __name__ == "__main__":
    main()
