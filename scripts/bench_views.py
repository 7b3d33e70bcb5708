"""Render time per view against the number of views: a view must cost the same in a long scan.

    python -m scripts.bench_views                 # 90, 1440 and 5760 views of examples/scan_small.toml (~2 min)
    python -m scripts.bench_views --quick         # 90 and 1440 views, the shared views only (~15 s)

The scan of ``examples/scan_small.toml`` (one woven cell, 24 × 64 pixels; its sample meshed once)
is rendered with ``num_views`` set to each count, as ``xrayraster render --views all`` renders it:
``Renderer.project_all``, line integrals, noise off, overlaps resolved by priority. Two times per
count, each per view:

* **shared**: the 90 views whose angles every count has (view k·N/90 of N), best of 3 passes: the
  same work at every count, so any growth with N is overhead per view that grows with the scan;
* **all**: one pass over every view of the count (``--no-all`` skips it), the whole scan.

Error: the path lengths (mm) of the shared views at each count against those of the 90-view run,
largest absolute difference over every pixel and material, and the 90-view run's largest path
length for scale (the same angles give the same lengths: 0 unless an angle differs by an ulp).
The setup (geometry, its vector form and the renderer) is timed apart.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from xrayraster.core.geometry import full_circle
from xrayraster.pipeline import load_scan_file
from xrayraster.simulate.renderer import Renderer

from .common import announce, conclude, outputs, parser, say

SCAN = Path(__file__).resolve().parent.parent / "examples" / "scan_small.toml"
COUNTS = (90, 1440, 5760)
SHARED = 90  # views every count has: N is a multiple of it


def measure(loaded, scene, count: int, every: bool) -> dict:
    """Setup, per-view times and the shared views' path lengths at ``count`` views."""
    start = time.perf_counter()
    geometry = dataclasses.replace(loaded.geometry, angles=full_circle(count))
    with Renderer(geometry, overlap="resolve") as renderer:
        setup = time.perf_counter() - start
        shared = list(range(0, count, count // SHARED))

        def project(views):
            return renderer.project_all(scene, loaded.spectrum, views, detector=loaded.detector, progress=False)

        project(shared[:1])  # upload and compile outside the times
        passes = []
        for _ in range(3):
            t0 = time.perf_counter()
            project(shared)
            passes.append((time.perf_counter() - t0) / len(shared))
        lengths = renderer.path_lengths_all(scene, shared, progress=False).data
        row = {"views": count, "setup_s": setup, "shared_ms_per_view": 1e3 * min(passes)}
        if every:
            t0 = time.perf_counter()
            project(None)
            row["all_ms_per_view"] = 1e3 * (time.perf_counter() - t0) / count
    return row, lengths


def main(argv=None) -> None:
    ap = parser(__doc__, "90 and 1440 views, the shared views only (~15 s)")
    ap.add_argument("--counts", type=int, nargs="+", help=f"view counts, multiples of {SHARED} (default {COUNTS})")
    ap.add_argument("--no-all", action="store_true", help="skip the pass over every view of each count")
    args = outputs(ap.parse_args(argv), "bench_views")
    counts = args.counts or (COUNTS[:2] if args.quick else COUNTS)
    if any(n % SHARED for n in counts):
        ap.error(f"--counts must be multiples of {SHARED}")
    t_start = time.perf_counter()
    command, machine = announce()
    loaded = load_scan_file(SCAN)
    scene = loaded.with_mount(loaded.sample_scene())
    say(f"scene: {SCAN.name}, {scene.num_triangles} triangles, detector {loaded.geometry.detector_shape}")
    rows, reference = [], None
    say(f"{'views':>6} {'setup s':>8} {'shared ms/view':>15} {'all ms/view':>12} {'max |dL| mm':>12}")
    for count in counts:
        row, lengths = measure(loaded, scene, count, not (args.no_all or args.quick))
        reference = lengths if reference is None else reference
        row["max_abs_diff_mm"] = float(np.abs(lengths - reference).max())
        rows.append(row)
        say(f"{count:>6} {row['setup_s']:>8.3f} {row['shared_ms_per_view']:>15.2f} "
            f"{row.get('all_ms_per_view', float('nan')):>12.2f} {row['max_abs_diff_mm']:>12.3g}")
    ratio = rows[-1]["shared_ms_per_view"] / rows[0]["shared_ms_per_view"]
    say(f"shared views: {rows[-1]['views']} views cost {ratio:.2f}x a view of {rows[0]['views']}; "
        f"largest path length {float(reference.max()):.3f} mm")
    payload = {"command": command, "machine": machine, "scan": str(SCAN), "triangles": scene.num_triangles,
               "rows": rows, "ratio_last_to_first": ratio, "largest_path_length_mm": float(reference.max())}
    conclude(args.json, payload, machine, t_start)


if __name__ == "__main__":
    main()
