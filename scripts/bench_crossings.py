"""A view's cost on a dataset sample's scene: the GL crossing passes and the CPU physics apart.

    python -m scripts.bench_crossings                        # 32², 128², 256² (~10 s on 2 cores)
    python -m scripts.bench_crossings --quick                # 32² and 128², fewer views
    python -m scripts.bench_crossings --save out/a.npz       # keep the path lengths ...
    python -m scripts.bench_crossings --against out/a.npz    # ... and compare another checkout's

The scene is the first sample of ``scripts/bench_dataset``'s 128³ dataset (the small reference
twin: 2 × 2 woven cells, 47,108 triangles, yarns overlapping, so resolved by priority as
``xr.scan`` renders them), on its cone-beam geometry with the detector resampled to n² pixels
over the same area. Per size:

* **path lengths**: ``PathLengthRenderer.path_lengths`` (``overlap="resolve"``), best of 3
  passes over 30 views spread over the circle, ms a view; with LP_NUM_THREADS unset llvmpipe uses
  every core, with ``LP_NUM_THREADS=1`` one (a pool worker's share);
* **physics**: ``radiograph`` of those views' lengths (spectral table, noise), one thread, best
  of 5 passes, ms a view.

Each as wall and as CPU time (the process's, every thread): on a VM shared with other jobs the
wall time of the same work moves by ±30 % between runs, its CPU time much less.

Error: with ``--against``, the largest difference (mm) of the path lengths from another run's,
e.g. of an earlier commit (copy this file into its checkout and run it there with ``--save``).
"""

from __future__ import annotations

import time

import numpy as np

import xrayraster as xr
from scripts.bench_dataset import dataset_table
from xrayraster.gl.pathlengths import PathLengthRenderer
from xrayraster.physics.beer_lambert import pixel_photon_factor
from xrayraster.physics.detector import Detector
from xrayraster.physics.radiograph import radiograph, spectral_model
from xrayraster.dataset import draw, load_dataset_file

from .common import announce, conclude, outputs, parser, say

SIZES = (32, 128, 256)


def resampled(geometry, pixels: int):
    """The scan's cone-beam geometry with ``pixels``² detector pixels over the same detector area."""
    pitch = geometry.pixel_size[1] * geometry.detector_shape[1] / pixels
    return xr.ConeBeamGeometry(geometry.source_to_origin, geometry.source_to_detector, (pixels, pixels), pitch,
                               geometry.angles)


def best_ms(work, passes: int, count: int) -> tuple[float, float]:
    """(wall, CPU) ms a view of ``work`` over ``count`` views, the best of ``passes``. CPU time is
    the process's, all threads (llvmpipe's too): steady where a shared VM's wall time is not."""
    best = (np.inf, np.inf)
    for _ in range(passes):
        wall, cpu = time.perf_counter(), time.process_time()
        work()
        best = min(best, (time.perf_counter() - wall, time.process_time() - cpu))
    return 1e3 * best[0] / count, 1e3 * best[1] / count


def main(argv=None) -> None:
    ap = parser(__doc__, "32² and 128², 10 views")
    ap.add_argument("--save", help="write the path lengths (npz) for another run's --against")
    ap.add_argument("--against", help="compare the path lengths with a --save file")
    args = outputs(ap.parse_args(argv), "bench_crossings")
    t_start = time.perf_counter()
    command, machine = announce()
    scan = draw(load_dataset_file(dataset_table("128", 1)), 0).scan
    scene = scan.sample_scene()
    detector = scan.detector or Detector()
    longest = float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
    model = spectral_model(scene.materials, scan.spectrum, detector, longest_mm=longest)
    views = list(range(0, scan.geometry.num_views, scan.geometry.num_views // (10 if args.quick else 30)))
    earlier = np.load(args.against) if args.against else None
    rows, kept = [], {}
    say(f"{scene.num_triangles} triangles, {len(views)} views; ms a view")
    say(f"{'pixels':>8} {'path lengths wall / CPU':>24} {'physics wall / CPU':>19} {'max |dL| mm':>12}")
    for pixels in SIZES[:2] if args.quick else SIZES:
        geometry = resampled(scan.geometry, pixels)
        with PathLengthRenderer(geometry, overlap="resolve") as renderer:
            lengths = [renderer.path_lengths(scene, v) for v in views]  # warm-up, and the lengths kept
            gl_ms, gl_cpu = best_ms(lambda: [renderer.path_lengths(scene, v) for v in views], 3, len(views))
            factors = [pixel_photon_factor(renderer.vector_geometry, v) for v in views]
        physics_ms, physics_cpu = best_ms(lambda: [radiograph(lengths_v, scene.materials, scan.spectrum, detector, factor, noise=True,
                                                 rng=np.random.default_rng(v), threads=1, model=model)
                                      for lengths_v, factor, v in zip(lengths, factors, views)], 5, len(views))
        kept[f"n{pixels}"] = np.stack(lengths)
        diff = float(np.abs(kept[f"n{pixels}"] - earlier[f"n{pixels}"]).max()) if earlier is not None else None
        rows.append({"pixels": pixels, "path_lengths_ms": gl_ms, "path_lengths_cpu_ms": gl_cpu, "physics_ms": physics_ms,
                     "physics_cpu_ms": physics_cpu, "max_abs_diff_mm": diff,
                     "max_length_mm": float(kept[f"n{pixels}"].max())})
        say(f"{pixels:>7}² {gl_ms:>13.2f} / {gl_cpu:>8.2f} {physics_ms:>8.2f} / {physics_cpu:>8.2f} "
            f"{'' if diff is None else f'{diff:.2g}':>12}")
    if args.save:
        np.savez_compressed(args.save, **kept)
    conclude(args.json, {"command": command, "machine": machine, "triangles": scene.num_triangles, "views": views,
                         "rows": rows}, machine, t_start)


if __name__ == "__main__":
    main()
