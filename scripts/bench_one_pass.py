"""Woven samples in one pass: the path lengths of a woven scene with its overlaps as signed
intersection meshes (method "nested") against the per-pixel sort (method "resolve").

    python -m scripts.bench_one_pass            # twin_small at 128², 256² and 512², the twin at 512² (~3 min)
    python -m scripts.bench_one_pass --quick    # twin_small at 128² and 256², 4 views (~20 s)
    LP_NUM_THREADS=1 python -m scripts.bench_one_pass --passes   # and each GL pass apart, on one llvmpipe thread

The scenes are the samples of ``examples/twin_small.toml`` (2 × 2 woven cells, the dataset
benchmark's sample) and ``examples/twin.toml`` (the reference twin), meshed as ``xr.scan`` meshes
them, rendered at the detector sizes of the dataset benchmark's samples (128², 256²) and of the twin
(512²) with the scan's geometry otherwise. Per case: the preparation (the overlap test, which both
methods pay under ``overlap="auto"``, and the terms, which only one pass needs), the terms'
triangles beside the scene's, and the time a view of each method, the best of three passes over the
same views, the methods alternating. Error: the largest absolute difference (mm) between the two
methods' path lengths over every pixel, material and view, and the 99.99th percentile.

Beside them, the plain sum (method "sum": every object counted whole, overlaps counted twice, so
its lengths are wrong on these scenes and not compared): the same crossing passes with nothing for
the overlaps, the floor of any one-pass scheme on this machine.

With ``--passes``, one more pass over the views per method times each GL pass apart (the driver
finishes its work before and after each, so the sum exceeds a view's time a little): crossing
pass 1 (``pathlength_small``), its indirect dispatch's groups, 1b (``pathlength_candidates``), 2
(``pathlength_large``, the rasteriser) and the sort (``pathlength_resolve``), ms a view.
``LP_NUM_THREADS=1`` gives a dataset build's worker's share of llvmpipe on two cores.
"""

from __future__ import annotations

import collections
import dataclasses
import time
from contextlib import contextmanager

import numpy as np

from xrayraster.gl.context import GLContext
from xrayraster.gl.pathlengths import PathLengthRenderer
from xrayraster.pipeline import load_scan_file

from .common import ROOT, announce, conclude, outputs, parser, pyplot, say

CASES = {  # name: (scan file, detector pixels across)
    "twin_small 128²": ("twin_small.toml", 128),
    "twin_small 256²": ("twin_small.toml", 256),
    "twin_small 512²": ("twin_small.toml", 512),
    "twin 512²": ("twin.toml", 512),
}
QUICK = ("twin_small 128²", "twin_small 256²")


@contextmanager
def pass_timer():
    """A dict that fills, inside the block, with the seconds of every GL pass by shader name: each
    dispatch and draw of a :class:`GLContext` is timed between two ``finish`` calls."""
    seconds: dict[str, float] = collections.defaultdict(float)
    originals = {name: getattr(GLContext, name) for name in ("dispatch", "dispatch_indirect", "draw_indirect")}

    def timed(original):
        def call(gl, what, *args, **kwargs):
            program = getattr(what, "program", what)  # a draw's vertex array: its program
            name = next(key[0] for key, p in gl._programs.items() if p.glo == program.glo)
            gl.ctx.finish()
            start = time.perf_counter()
            original(gl, what, *args, **kwargs)
            gl.ctx.finish()
            seconds[name.rsplit(".", 1)[0]] += time.perf_counter() - start
        return call

    try:
        for name, original in originals.items():
            setattr(GLContext, name, timed(original))
        yield seconds
    finally:
        for name, original in originals.items():
            setattr(GLContext, name, original)


def measure(name: str, views: int, passes: bool = False) -> dict:
    path, pixels = CASES[name]
    loaded = load_scan_file(ROOT / "examples" / path)
    scene = loaded.with_mount(loaded.sample_scene())
    start = time.perf_counter()
    pairs = scene.overlaps()
    overlaps_s = time.perf_counter() - start
    start = time.perf_counter()
    one_pass = scene.one_pass()
    terms_s = time.perf_counter() - start
    g = loaded.geometry
    geometry = dataclasses.replace(g, detector_shape=(pixels, pixels),
                                   pixel_size=g.pixel_size[1] * g.detector_shape[1] / pixels)
    picks = np.linspace(0, geometry.num_views, views, endpoint=False).astype(int)
    times = {"nested": [], "resolve": [], "sum": []}
    lengths = {}
    renderers = {m: PathLengthRenderer(geometry, overlap=m) for m in times}
    try:
        for r in renderers.values():
            r.path_lengths(scene, 0)  # upload and compile outside the times
        for _ in range(3):
            for method, r in renderers.items():
                start = time.perf_counter()
                lengths[method] = np.stack([r.path_lengths(scene, int(v)) for v in picks])
                times[method].append((time.perf_counter() - start) / views)
        by_pass = {}
        for method, r in renderers.items() if passes else ():
            with pass_timer() as seconds:
                for v in picks:
                    r.path_lengths(scene, int(v))
            by_pass[method] = {k: 1e3 * s / views for k, s in seconds.items()}
    finally:
        for r in renderers.values():
            r.release()
    diff = np.abs(lengths["nested"] - lengths["resolve"])
    row = {"case": name, "pixels": pixels, "views": views, "triangles": scene.num_triangles,
           "pairs": len(pairs), "terms": len(one_pass.terms),
           "term_triangles": sum(len(t.mesh.faces) for t in one_pass.terms),
           "overlaps_s": overlaps_s, "terms_s": terms_s,
           "nested_ms": 1e3 * min(times["nested"]), "resolve_ms": 1e3 * min(times["resolve"]),
           "sum_ms": 1e3 * min(times["sum"]),
           "max_diff_mm": float(diff.max()), "p9999_diff_mm": float(np.quantile(diff, 0.9999)),
           "max_length_mm": float(lengths["resolve"].max())}
    row["speedup"] = row["resolve_ms"] / row["nested_ms"]
    row["floor_speedup"] = row["resolve_ms"] / row["sum_ms"]
    if passes:
        row["passes_ms"] = by_pass
    say(f"{name}: {row['triangles']} triangles + {row['term_triangles']} in {row['terms']} terms; overlaps "
        f"{overlaps_s:.2f} s, terms {terms_s:.3f} s; a view: nested {row['nested_ms']:.1f} ms, resolve "
        f"{row['resolve_ms']:.1f} ms ({row['speedup']:.2f}x; the plain sum, its floor: {row['sum_ms']:.1f} ms, "
        f"{row['floor_speedup']:.2f}x); max |diff| {row['max_diff_mm']:.2g} mm "
        f"(p99.99 {row['p9999_diff_mm']:.2g}) of {row['max_length_mm']:.1f} mm")
    for method, ms in row.get("passes_ms", {}).items():
        say(f"    {method} by pass, ms a view: " + ", ".join(f"{k} {v:.2f}" for k, v in ms.items()))
    return row


def plot(rows: list[dict], plots_dir) -> None:
    plt = pyplot()
    if plt is None:
        return
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    x = np.arange(len(rows))
    ax.bar(x - 0.27, [r["resolve_ms"] for r in rows], 0.27, label="resolve (per-pixel sort)")
    ax.bar(x, [r["nested_ms"] for r in rows], 0.27, label="nested + overlap terms (one pass)")
    ax.bar(x + 0.27, [r["sum_ms"] for r in rows], 0.27, label="plain sum (overlaps ignored: the floor)")
    for k, r in enumerate(rows):
        ax.annotate(f"max |Δ| {r['max_diff_mm']:.1g} mm", (k, r["nested_ms"]), fontsize=7, ha="center",
                    xytext=(0, 3), textcoords="offset points")
    ax.set_xticks(x, [r["case"] for r in rows], fontsize=8)
    ax.set_ylabel("ms a view (path lengths)")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.set_title("Woven scenes: one pass against the per-pixel sort (llvmpipe, 2 cores)", fontsize=9)
    fig.tight_layout()
    path = plots_dir / "bench_one_pass.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    say(f"plot: {path}")


def main() -> None:
    ap = parser(__doc__, "twin_small at 128² and 256², 4 views", plots=True)
    ap.add_argument("--passes", action="store_true", help="also time each GL pass apart")
    args = outputs(ap.parse_args(), "bench_one_pass")
    t_start = time.perf_counter()
    command, machine = announce()
    names = QUICK if args.quick else tuple(CASES)
    rows = [measure(name, 4 if args.quick else 12, args.passes) for name in names]
    plot(rows, args.plots_dir)
    conclude(args.json, {"command": command, "machine": machine, "rows": rows}, machine, t_start)


if __name__ == "__main__":
    main()
