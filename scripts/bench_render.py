"""Renderer benchmark: time per view against path-length error, xrayraster beside gVirtualXRay.

    python -m scripts.bench_render            # full run: ~10 min on 2 CPU cores (llvmpipe)
    python -m scripts.bench_render --quick    # smoke test, < 1 min

The scene
---------
The 3-material weave of :mod:`scripts.weave_scene` (straight closed tubes: warp along x, weft
along y, binders along z; no two touch, so ``overlap='sum'`` is exact), at tessellation levels
N = 6 / 18 / 60 (~12 k / ~100 k / ~1.1 M triangles). The *matrix* scene adds a matrix box
enclosing all yarns at lower priority (the composite case). It is rendered twice:
``overlap='nested'`` (what ``auto`` picks: the single pass, each yarn also taking its length
off the matrix) and forced ``overlap='resolve'`` (per-pixel crossing lists + priority sweep, the
general path for partial overlaps). gVirtualXRay has no priorities, so only xrayraster is
measured on that scene.

What is timed
-------------
``Renderer.path_lengths(scene, view)`` on one shared GLContext: one untimed warm-up call (scene
upload, shader compilation, list-pool sizing), then the best of ``repeats`` calls for each of a
few views at different angles; s/view is the mean of the per-view bests. gVirtualXRay is driven
through ``scripts/peers/gvxr_peer.py`` on the very same vertex/face arrays (mm, same frame), the same
source/detector geometry and the same angles; its time is also best-of-repeats per view and
includes reading every material's L-buffer back into a numpy array, as ours does.

Errors (all in mm, on a fixed seeded sample of detector pixels, pooled over views and materials)
----------------------------------------------------------------------------------------------
* ``exact``:  against float64 chords of the *same polyhedral meshes* along the same rays (the
  pixel-centre ray, or the mean of the k×k sub-pixel rays with supersampling k). Every tube is
  convex, so its chord is the half-space (slab) intersection over its face planes. This is the
  implementation error: what the renderer adds beyond the geometry it was given.
* ``smooth``: against the ideal smooth cylinders along the same rays: tessellation error plus
  implementation error, the tessellation-level trade-off.
* ``pixel``:  against the smooth cylinders averaged over the pixel area (S×S sub-rays): what a
  detector pixel integrates. Supersampling trades time for this one.
For the matrix scene the matrix reference is the box chord minus the yarn chords.

Prints a table as it goes, writes every number to a JSON file (``--json``; default
out/bench_render.json) and plots time-versus-error figures (``--plots-dir``; default docs/,
``--quick``: out/) as PNG via matplotlib when installed.
Our measurements are in :mod:`scripts.render_measure`, gVirtualXRay's (and its frame check) in
:mod:`scripts.render_gvxr`, the plots in :mod:`scripts.render_plots`; this module runs the sweeps.
"""

from __future__ import annotations

import time

import moderngl

import xrayraster as xr
from scripts import common
from scripts.common import say
from scripts.peers import gvxr_peer
from scripts.render_gvxr import check_gvxr_frame, compare, time_gvxr
from scripts.render_measure import HEADER, PIXEL_SUBGRID, evaluate, row, time_ours
from scripts.render_plots import plot
from scripts.weave_scene import ANGLES_DEG, DET_WIDTH, SDD, SOD, References, build_scene


def main(argv=None) -> int:
    ap = common.parser(__doc__, "small sizes only: a smoke test that finishes in < 60 s", plots=True)
    ap.add_argument("--sizes", type=int, nargs="+", help="detector sides of the detector sweep (default 256 512 1024 2048)")
    ap.add_argument("--levels", type=int, nargs="+", help="tessellation levels: sections per warp/weft tube (default 6 18 60)")
    ap.add_argument("--supersampling", type=int, nargs="+", help="k values of the supersampling sweep (default 1 2 3 4)")
    ap.add_argument("--sweep-size", type=int, help="detector side of the tessellation and supersampling sweeps (default 512)")
    ap.add_argument("--no-gvxr", action="store_true", help="do not run gVirtualXRay")
    args = common.outputs(ap.parse_args(argv), "bench_render")

    if args.quick:
        sizes, levels, ks, sweep_size = [64, 128], [6, 12], [1, 2], 128
        repeats, max_views, budget, pixels = 3, 2, 2.0, 1000
    else:
        sizes, levels, ks, sweep_size = [256, 512, 1024, 2048], [6, 18, 60], [1, 2, 3, 4], 512
        repeats, max_views, budget, pixels = 3, 3, 12.0, 3000
    sizes = sorted(args.sizes or sizes)
    levels = sorted(args.levels or levels)
    ks = sorted(set([1, *(args.supersampling or ks)]))
    sweep_size = args.sweep_size or (sweep_size if sweep_size in sizes else sizes[len(sizes) // 2])
    top = levels[-1]

    t_start = time.perf_counter()
    ctx = xr.GLContext()
    command, machine = common.announce(gl=ctx)
    say(f"geometry: cone beam SOD {SOD} mm, SDD {SDD} mm (magnification {SDD / SOD:.1f}), detector {DET_WIDTH} mm wide, "
        f"views at {', '.join(f'{a:g}°' for a in ANGLES_DEG)}")
    say(f"sweeps: tessellation levels {levels} at {sweep_size}², k=1; detector {sizes} and supersampling {ks} at level {top}; "
        f"best of {repeats} per view, up to {max_views} views, ~{budget:g} s budget per configuration; "
        f"errors on {pixels} seeded pixels per view")

    gvxr_reason = "disabled (--no-gvxr)" if args.no_gvxr else gvxr_peer.gvxr_available()
    frame = None
    if gvxr_reason:
        say(f"gVirtualXRay: not run: {gvxr_reason}")
    else:
        frame = check_gvxr_frame(ctx)
        say("gVirtualXRay frame check (mean |ours − gvxr| mm over an asymmetric 2-material object): "
            + "; ".join(f"{k}: " + ", ".join(f"{n} {v:.2e}" for n, v in d.items()) for k, d in frame.items() if k != "match"))
        say(f"gVirtualXRay frame check: {'gvxr_peer images match ours as they are' if frame['match'] else 'MISMATCH: comparisons below are not valid'}")

    refs = References(pixels)
    payload = {"command": command, "machine": machine, "settings": {
        "sod_mm": SOD, "sdd_mm": SDD, "detector_width_mm": DET_WIDTH, "angles_deg": ANGLES_DEG, "sizes": sizes,
        "levels": levels, "supersampling": ks, "sweep_size": sweep_size, "repeats": repeats, "max_views": max_views,
        "budget_s": budget, "pixels_per_view": pixels, "pixel_subgrid": PIXEL_SUBGRID},
        "gvxr": {"available": gvxr_reason is None, "reason": gvxr_reason, "frame_check": frame},
        "scenes": [], "results": [], "comparisons": []}

    # Configurations grouped by level so each scene is built (and uploaded to gvxr) once.
    plan = []
    for level in levels:
        configs = {(sweep_size, 1)}
        if level == top:
            configs |= {(n, 1) for n in sizes} | {(sweep_size, k) for k in ks}
        plan.append((level, sorted(configs, key=lambda c: (c[1], c[0]))))

    records, comparisons = payload["results"], payload["comparisons"]
    for level, configs in plan:
        bench = build_scene(level)
        payload["scenes"].append({"level": level, "triangles": bench.triangles, "by_material": bench.per_material,
                                  "objects": len(bench.solids), "build_s": bench.build_s})
        say(f"\nscene level {level}: {bench.triangles:,} triangles in {len(bench.solids) - 1} tubes "
            f"({', '.join(f'{m} {t:,}' for m, t in bench.per_material.items())}) + 12-triangle matrix box for the matrix scene; "
            f"built in {bench.build_s:.1f} s")
        say(HEADER)
        for n, k in configs:
            rc = refs.pixels(n)
            done = {}
            for method in ("sum", "nested", "resolve"):
                try:
                    meas = time_ours(ctx, bench, method, n, k, repeats, max_views, budget, rc)
                except (xr.RenderError, moderngl.Error) as exc:  # too large for this driver/memory
                    say(f"{bench.triangles:>9,} {n:>5} {k:>2} {method:>7}  skipped: {exc}")
                    continue
                evaluate(meas, refs, bench)
                done[method] = meas
                records.append(meas.record())
                say(row(meas))
            if k == 1 and gvxr_reason is None and "sum" in done:
                try:
                    g = time_gvxr(bench, n, repeats, done["sum"].views, budget, rc)
                except Exception as exc:  # e.g. gvxr out of GPU memory: report it, go on without gvxr
                    gvxr_reason = f"failed at {n}², level {level}: {type(exc).__name__}: {exc}"
                    payload["gvxr"]["reason"] = gvxr_reason
                    say(f"gVirtualXRay {gvxr_reason}; not run from here on")
                    continue
                evaluate(g, refs, bench)
                records.append(g.record())
                say(row(g))
                comparisons.append(compare(done["sum"], g, refs, bench))
                c = comparisons[-1]
                say(f"{'':>9} {'':>5} {'':>2} {'':>7}   gvxr/ours time ratio {c['ratio']:.2f} on {len(c['views_deg'])} view(s); "
                    f"exact max ours {c['ours']['max']:.2e} vs gvxr {c['gvxr']['max']:.2e}, "
                    f"p99.9 {c['ours']['p99.9']:.2e} vs {c['gvxr']['p99.9']:.2e} mm")
            common.write_json(args.json, payload)  # after every configuration: a cut-short run keeps its data
        del bench

    say("\nreference computation (float64, sampled pixels): {:.1f} s".format(refs.seconds))
    if comparisons:
        say("\ntarget: per-view path lengths ≥ 2× faster than gVirtualXRay with equal or lower error "
            "(exact-chord max and p99.9, same views; 'equal' = within 1e-6 mm), on the ≥ 1 M-triangle scene:")
        for c in comparisons:
            say(f"  {c['triangles']:>9,} tris {c['detector']:>5}²: ratio {c['ratio']:5.2f}, error "
                f"{'≤' if c['error_ok'] else '>'} gvxr → {'MET' if c['met'] else 'not met'}"
                + ("" if c["triangles"] >= 1_000_000 else "  (below 1 M triangles: informative only)"))
        big = [c for c in comparisons if c["triangles"] >= 1_000_000]
        if big:
            payload["target_met"] = all(c["met"] for c in big)
            say(f"  overall on ≥ 1 M triangles: {'MET' if payload['target_met'] else 'NOT MET'}")
    say("matrix scene (nested and resolve rows): gVirtualXRay has no priority resolution, so only ours is measured there.")

    for path in plot(records, args.plots_dir, top, sweep_size):
        say(f"plot: {path}")
    common.conclude(args.json, payload, machine, t_start)
    # ctx is deliberately not released: gvxr_peer destroys gvxr's context at exit and then
    # restores the context that was current, which fails (with a traceback) if it was destroyed.
    return 0


if __name__ == "__main__":
    raise SystemExit(main())