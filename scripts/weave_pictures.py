"""Pictures of a woven sample for docs/weave.md and the README, made with the project's own renderer.

The sample is ``examples/weave.toml`` (2 × 2 cells of the default cell, distorted from seed 1, one
glass tracer weft), turned so its thickness lies along the beam (a top view: the weave pattern):

* ``docs/images/weave_pathlengths.png``: the path length (mm) through the wefts, the warps and the
  tracer, one panel each, in a parallel beam (one pixel 0.04 mm);
* ``docs/images/weave_radiograph.png``: a cone-beam radiograph (−ln of the transmission, with
  photon noise, seed 1) of the same view at 40 kV (tungsten, 2 mm aluminium, 1.25 mAs). The wefts and warps are given pure carbon at 1.72 and 1.82 g/cm³ (so their path
  lengths come out on separate channels; the example's own fibre bundles are one material).

Usage::

    python -m scripts.weave_pictures [--out-dir docs/images]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import xrayraster as xr
from xrayraster.core.transform import Transform
from xrayraster.io.weave_file import load_weave_file
from xrayraster.weave import YarnMaterials

from .common import DOCS, ROOT, say


def top_view_scene(materials: YarnMaterials) -> tuple[xr.Scene, np.ndarray, dict]:
    """The example sample centred on the origin, its thickness (z) turned onto the beam axis (y);
    its size (mm, before turning) and a title per material."""
    loaded = load_weave_file(ROOT / "examples" / "weave.toml")
    sample = loaded.sample
    lo, hi = sample.box
    place = Transform.rotation((1.0, 0.0, 0.0), -math.pi / 2) @ Transform.translation(-(lo + hi) / 2)
    scene = sample.scene(materials, per="family", transform=place)
    titles = {o.material: o.name if o.name in ("matrix", "weft", "warp") else "glass tracer weft"
              for o in scene.objects}
    return scene, hi - lo, titles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out-dir", type=Path, default=DOCS / "images")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    example = load_weave_file(ROOT / "examples" / "weave.toml").materials
    materials = YarnMaterials(matrix=example.matrix, weft=xr.Material.element("C", 1.72, name="carbon 1.72"),
                              warp=xr.Material.element("C", 1.82, name="carbon 1.82"), tracers=example.tracers)
    scene, size, titles = top_view_scene(materials)
    pixel = 0.04
    cols, rows = (int(math.ceil(size[i] * 1.04 / pixel)) for i in (0, 1))
    parallel = xr.ParallelBeamGeometry((rows, cols), pixel, (0.0,))
    with xr.Renderer(parallel) as renderer:
        lengths = renderer.path_lengths(scene, 0)
    panels = [(i, titles[m]) for i, m in enumerate(scene.materials) if titles[m] != "matrix"]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.2), constrained_layout=True)
    extent = (-cols * pixel / 2, cols * pixel / 2, -rows * pixel / 2, rows * pixel / 2)
    for ax, (i, name) in zip(np.atleast_1d(axes), panels):
        im = ax.imshow(lengths[i], origin="lower", cmap="magma", extent=extent)
        ax.set_title(f"path length: {name}")
        ax.set_xlabel("x (mm)")
        fig.colorbar(im, ax=ax, shrink=0.8, label="mm")
    np.atleast_1d(axes)[0].set_ylabel("y (mm)")
    args.out_dir.mkdir(parents=True, exist_ok=True)
    out = args.out_dir / "weave_pathlengths.png"
    fig.savefig(out, dpi=90)
    plt.close(fig)
    say(f"{out}: {len(panels)} panels, {rows}×{cols} px of {pixel} mm, max {lengths[1:].max():.3f} mm")

    # turned, the sample spans size_x across the beam, its thickness along it, size_y up the axis
    cone = xr.ConeBeamGeometry.framing(float(np.hypot(size[0], size[2]) / 2), float(size[1] / 2), num_views=1,
                                       columns=512)
    spectrum = xr.Spectrum.from_tube(40.0, filters={"Al": 2.0}, mas=1.25)
    with xr.Renderer(cone) as renderer:
        shot = renderer.project(scene, spectrum, 0, noise=True, seed=1)
    fig, ax = plt.subplots(figsize=(5.6, 5.0), constrained_layout=True)
    im = ax.imshow(shot.image, origin="lower", cmap="gray_r")
    ax.set_title("radiograph with photon noise (40 kV, 2 mm Al)")
    ax.set_axis_off()
    fig.colorbar(im, ax=ax, shrink=0.8, label="−ln(I/I₀)")
    out = args.out_dir / "weave_radiograph.png"
    fig.savefig(out, dpi=90)
    plt.close(fig)
    say(f"{out}: {cone.detector_shape[0]}×{cone.detector_shape[1]} px cone beam")


if __name__ == "__main__":
    main()
