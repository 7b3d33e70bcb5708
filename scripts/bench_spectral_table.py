"""The spectral table against the exact sum over energy bins, on the twin's own views.

    python -m scripts.bench_spectral_table            # 4 views of examples/twin.toml at 512²

Renders the path lengths of a few views of the reference twin (its sample meshed coarsely: the
physics does not depend on the mesh), then makes each view's noisy radiograph twice from the same
seed: with the exact per-pixel sum over the spectrum's bins and with the spectral table
(xrayraster/physics/spectral_table.py). Both draw the same normal deviates where a pixel expects
over 1000 photons, so their line integrals differ by the table's interpolation error alone.
Prints the time per view of each (the table's one-off build apart) and the largest difference.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from xrayraster.core.transform import Transform
from xrayraster.physics.beer_lambert import pixel_photon_factor
from xrayraster.physics.detector import Detector
from xrayraster.physics.radiograph import radiograph, spectral_model
from xrayraster.pipeline import load_scan_file
from xrayraster.simulate.renderer import Renderer

from .common import machine_info

TWIN = Path(__file__).resolve().parent.parent / "examples" / "twin.toml"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=4)
    args = parser.parse_args(argv)
    loaded = load_scan_file(TWIN)
    sample = dataclasses.replace(loaded.weave.sample, points_per_section=16, samples_per_mm=4.0)
    lo, hi = sample.box
    scene = sample.scene(loaded.weave.materials, transform=Transform.translation(-(lo + hi) / 2))
    detector = loaded.detector or Detector()
    print("machine:", machine_info())
    start = time.perf_counter()
    tabled = spectral_model(scene.materials, loaded.spectrum, detector,
                            longest_mm=float(np.linalg.norm(np.ptp(scene.bounds, axis=0))))
    build = time.perf_counter() - start
    exact = spectral_model(scene.materials, loaded.spectrum, detector)
    seconds = {"exact": 0.0, "table": 0.0}
    worst = 0.0
    views = np.linspace(0, loaded.geometry.num_views, args.views, endpoint=False).astype(int)
    with Renderer(loaded.geometry, overlap="resolve") as renderer:
        for view in views:
            lengths = renderer.path_lengths(scene, int(view))
            factor = pixel_photon_factor(renderer.vector_geometry, int(view))
            images = {}
            for name, model in (("exact", exact), ("table", tabled)):
                rng = np.random.default_rng([0, int(view)])
                start = time.perf_counter()
                images[name] = radiograph(lengths, scene.materials, loaded.spectrum, detector, factor, noise=True,
                                          rng=rng, model=model).image
                seconds[name] += time.perf_counter() - start
            worst = max(worst, float(np.abs(images["table"] - images["exact"]).max()))
    rows, cols = loaded.geometry.detector_shape
    per_view = {name: s / len(views) for name, s in seconds.items()}
    print(f"{len(views)} views of {rows}×{cols}, {len(exact.energies)} bins, {len(scene.materials)} materials; "
          f"table {tabled.table.shape} built in {build:.2f} s, measured error {tabled.table.error:.1e}")
    print(f"noisy radiograph per view: exact {per_view['exact'] * 1e3:.0f} ms, table {per_view['table'] * 1e3:.0f} ms "
          f"({per_view['exact'] / per_view['table']:.1f}×); largest line-integral difference {worst:.1e}")


if __name__ == "__main__":
    main()
