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
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import moderngl
import numpy as np
import trimesh

import xrayraster as xr
from scripts import common
from scripts.common import say
from scripts.peers import gvxr_peer
from scripts.weave_scene import ANGLES_DEG, DET_WIDTH, SDD, SOD, YARNS, BenchScene, References, build_scene, geometry

PIXEL_SUBGRID = 16  # S×S sub-rays per pixel for the 'pixel' reference


# ---------------------------------------------------------------------------------------------
# Measurements
# ---------------------------------------------------------------------------------------------


@dataclass
class Measurement:
    """One renderer on one configuration: per-view best times and sampled images."""

    method: str  # 'sum', 'nested', 'resolve' or 'gvxr'
    level: int
    triangles: int
    size: int
    k: int
    repeats: int
    views: list[int] = field(default_factory=list)
    best_s: list[float] = field(default_factory=list)
    samples: list[dict[str, np.ndarray]] = field(default_factory=list)  # per view {material: (m,)}
    setup_s: float = 0.0
    errors: dict = field(default_factory=dict)

    @property
    def s_per_view(self) -> float:
        return float(np.mean(self.best_s))

    def record(self) -> dict:
        return {
            "method": self.method,
            "level": self.level,
            "triangles": self.triangles,
            "detector": self.size,
            "supersampling": self.k,
            "repeats": self.repeats,
            "views_deg": [ANGLES_DEG[v] for v in self.views],
            "best_s_per_view": self.best_s,
            "s_per_view": self.s_per_view,
            "setup_s": self.setup_s,
            "errors_mm": self.errors,
        }


def time_ours(ctx, bench: BenchScene, method: str, n: int, k: int, repeats: int, max_views: int, budget_s: float, rc):
    scene = bench.scene if method == "sum" else bench.resolve_scene
    meas = Measurement(method, bench.level, scene.num_triangles, n, k, repeats)
    renderer = xr.Renderer(geometry(n), supersampling=k, overlap=method, context=ctx)
    try:
        t0 = time.perf_counter()
        renderer.path_lengths(scene, 0)  # warm-up: upload, compile, size the crossing lists
        meas.setup_s = time.perf_counter() - t0
        assert renderer.last_method == method, renderer.last_method
        start = time.perf_counter()
        for view in range(max_views):
            best, out = common.best_of(lambda: renderer.path_lengths(scene, view), repeats)
            meas.views.append(view)
            meas.best_s.append(best)
            meas.samples.append({m: out[i, rc[:, 0], rc[:, 1]].astype(np.float64) for i, m in enumerate(scene.materials)})
            if not common.next_fits(start, len(meas.views), budget_s):
                break  # the next view would overrun this configuration's time budget
    finally:
        renderer.release()
    return meas


def time_gvxr(bench: BenchScene, n: int, repeats: int, views: list[int], budget_s: float, rc):
    meas = Measurement("gvxr", bench.level, bench.triangles, n, 1, repeats)
    start = time.perf_counter()
    for view in views:
        images, best = gvxr_peer.gvxr_path_lengths(bench.gvxr_meshes, SOD, SDD, (n, n), DET_WIDTH / n,
                                                   math.radians(ANGLES_DEG[view]), repeats=repeats)
        meas.views.append(view)
        meas.best_s.append(best)
        meas.samples.append({m: images[m][rc[:, 0], rc[:, 1]] for m in YARNS})
        if not common.next_fits(start, len(meas.views), budget_s):
            break
    return meas


def error_stats(meas: Measurement, refs: References, bench: BenchScene, kind: str, views=None) -> dict:
    """max / p99.9 / mean |error| (mm) pooled over sampled pixels, views and materials."""
    k = PIXEL_SUBGRID if kind == "pixel" else meas.k
    ref_kind = "smooth" if kind == "pixel" else kind
    errs, per = [], {}
    for view, sample in zip(meas.views, meas.samples):
        if views is not None and view not in views:
            continue
        ref = refs.get(bench, ref_kind, meas.size, view, k)
        for m, values in sample.items():
            e = np.abs(values - ref[m])
            errs.append(e)
            per[m] = max(per.get(m, 0.0), float(e.max()))
    e = np.concatenate(errs)
    return {"max": float(e.max()), "p99.9": float(np.percentile(e, 99.9)), "mean": float(e.mean()), "max_by_material": per}


def evaluate(meas: Measurement, refs: References, bench: BenchScene) -> None:
    meas.errors = {kind: error_stats(meas, refs, bench, kind) for kind in ("exact", "smooth", "pixel")}


HEADER = (
    f"{'tris':>9} {'det':>5} {'k':>2} {'method':>7} {'views':>5} {'s/view':>8} │"
    f" {'exact: max':>10} {'p99.9':>8} {'mean':>8} │ {'smooth: max':>11} {'p99.9':>8} {'mean':>8} │"
    f" {'pixel: max':>10} {'p99.9':>8} {'mean':>8}"
)


def row(meas: Measurement) -> str:
    e = meas.errors
    cells = " │ ".join(
        " ".join(f"{e[kind][s]:{w}.2e}" for s, w in (("max", 10 + (kind == "smooth")), ("p99.9", 8), ("mean", 8)))
        for kind in ("exact", "smooth", "pixel")
    )
    return f"{meas.triangles:>9,} {meas.size:>5} {meas.k:>2} {meas.method:>7} {len(meas.views):>5} {meas.s_per_view:>8.4f} │ {cells}"


# ---------------------------------------------------------------------------------------------
# gVirtualXRay frame check
# ---------------------------------------------------------------------------------------------


def check_gvxr_frame(ctx) -> dict:
    """Render an asymmetric two-material object with both renderers; gvxr_peer's images must
    match ours as they are (not flipped, transposed or mirrored in angle)."""

    def box(centre, extents):
        m = trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(centre))
        for _ in range(3):  # small triangles: gvxr interpolates depth across each one in screen space
            m = m.subdivide()
        return np.asarray(m.vertices), np.asarray(m.faces)

    parts = {"a": [box((3.0, -1.0, 2.0), (4.0, 2.0, 1.5)), box((-2.0, 2.0, -3.0), (1.0, 1.0, 1.0))],
             "b": [box((-3.0, 0.0, 1.0), (1.0, 3.0, 5.0))]}
    scene = xr.Scene()
    for mat, meshes in parts.items():
        for v, f in meshes:
            scene.add((v, f), mat)
    shape, pixel = (64, 96), 0.4  # not square, so a transpose could not pass either
    result = {}
    for theta in (0.0, 0.7):
        geom = xr.ConeBeamGeometry(SOD, SDD, shape, pixel, [theta])
        with xr.Renderer(geom, overlap="sum", context=ctx) as r:
            ours = r.path_lengths(scene, 0).astype(np.float64)
        g, _ = gvxr_peer.gvxr_path_lengths(parts, SOD, SDD, shape, pixel, theta, repeats=1)
        g_neg, _ = gvxr_peer.gvxr_path_lengths(parts, SOD, SDD, shape, pixel, -theta, repeats=1)
        variants = {
            "as is": lambda im, m: im[m],
            "rows flipped": lambda im, m: im[m][::-1],
            "cols flipped": lambda im, m: im[m][:, ::-1],
            "both flipped": lambda im, m: im[m][::-1, ::-1],
        }
        diffs = {name: float(np.mean([np.abs(ours[i] - f(g, m)).mean() for i, m in enumerate(scene.materials)]))
                 for name, f in variants.items()}
        diffs["angle negated"] = float(np.mean([np.abs(ours[i] - g_neg[m]).mean() for i, m in enumerate(scene.materials)]))
        diffs["max |diff| as is"] = float(max(np.abs(ours[i] - g[m]).max() for i, m in enumerate(scene.materials)))
        result[f"{theta:g} rad"] = diffs
    ok = all(d["as is"] < 0.01 and d["as is"] == min(v for k, v in d.items() if not k.startswith("max")) for d in result.values())
    result["match"] = ok
    return result


# ---------------------------------------------------------------------------------------------
# Plots
# ---------------------------------------------------------------------------------------------

STYLE = {
    "sum": ("C0", "o", "ours, single pass (sum)"),
    "nested": ("C2", "D", "ours, single pass with nesting (nested)"),
    "resolve": ("C1", "s", "ours, per-pixel lists (resolve)"),
    "gvxr": ("C3", "^", "gVirtualXRay"),
}


def plot(records: list[dict], plots_dir: Path, top: int, sweep_size: int) -> list[Path]:
    plt = common.pyplot()
    if plt is None:
        return []
    import matplotlib.ticker

    # (title, error kind plotted, which records, order along the sweep, point label)
    sweeps = [
        (f"tessellation sweep ({sweep_size}², k=1)", "smooth",
         lambda r: r["detector"] == sweep_size and r["supersampling"] == 1,
         lambda r: r["triangles"], lambda r: f"{r['triangles'] / 1e3:,.0f}k"),
        (f"supersampling sweep ({sweep_size}², {top_tris(records, top)})", "pixel",
         lambda r: r["level"] == top and r["detector"] == sweep_size,
         lambda r: r["supersampling"], lambda r: f"k={r['supersampling']}"),
        (f"detector sweep ({top_tris(records, top)}, k=1)", "exact",
         lambda r: r["level"] == top and r["supersampling"] == 1,
         lambda r: r["detector"], lambda r: f"{r['detector']}²"),
    ]

    def series(sweep, method):
        _, _, select, order, _ = sweep
        return sorted((r for r in records if r["method"] == method and select(r)), key=order)

    def time_vs_error(ax, rs, kind, stat, label, colour, marker, legend):
        x = [r["s_per_view"] for r in rs]
        y = [max(r["errors_mm"][kind][stat], 1e-9) for r in rs]
        common.curve(ax, x, y, [label(r) for r in rs], color=colour, marker=marker, label=legend)

    out = []
    fig, axes = plt.subplots(3, 2, figsize=(11, 13))
    for sweep, row_axes in zip(sweeps, axes):
        title, kind, _, _, label = sweep
        for stat, ax in zip(("max", "p99.9"), row_axes):
            for method, style in STYLE.items():
                if rs := series(sweep, method):
                    time_vs_error(ax, rs, kind, stat, label, *style)
            common.log_axes(ax, "time per view (s)", f"{stat} |error| vs {kind} reference (mm)", f"{title}: {stat}")
    fig.suptitle("xrayraster path lengths: time per view vs error\nerror vs: smooth shapes on the same rays (tessellation), "
                 "smooth shapes averaged over the pixel (supersampling),\nexact chords of the same meshes (detector)", fontsize=9)
    fig.tight_layout()
    out.append(common.save(fig, plots_dir / "bench_render_time_vs_error.png"))

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    sizes = sorted({r["detector"] for r in series(sweeps[2], "sum")})
    for method, (colour, marker, legend) in STYLE.items():
        if not (rs := series(sweeps[2], method)):
            continue
        axes[0].plot([r["detector"] for r in rs], [r["s_per_view"] for r in rs], marker=marker, color=colour, label=legend)
        for ax, stat in zip(axes[1:], ("max", "p99.9")):
            time_vs_error(ax, rs, "exact", stat, sweeps[2][4], colour, marker, legend)
    common.log_axes(axes[0], "detector (pixels)", "time per view (s)")
    axes[0].set_xticks(sizes, [f"{n}²" for n in sizes])
    axes[0].xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    for ax, stat in zip(axes[1:], ("max", "p99.9")):
        common.log_axes(ax, "time per view (s)", f"{stat} |error| vs exact polyhedral chords (mm)")
    fig.suptitle(f"detector sweep, {top_tris(records, top)}, k=1", fontsize=10)
    fig.tight_layout()
    out.append(common.save(fig, plots_dir / "bench_render_detector.png"))
    return out


def top_tris(records, top) -> str:
    tris = [r["triangles"] for r in records if r["level"] == top and r["method"] == "sum"]
    return f"{tris[0]:,} triangles" if tris else f"level {top}"


# ---------------------------------------------------------------------------------------------


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
    command = common.command_line()
    ctx = xr.GLContext()
    machine = common.machine_info(gl=ctx)
    common.print_machine(machine, command)
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
    payload["total_s"] = time.perf_counter() - t_start
    say(common.finish(machine))
    common.write_json(args.json, payload)
    say(f"results: {args.json}")
    say(f"total {payload['total_s']:.1f} s")
    # ctx is deliberately not released: gvxr_peer destroys gvxr's context at exit and then
    # restores the context that was current, which fails (with a traceback) if it was destroyed.
    return 0


def compare(ours: Measurement, gvxr: Measurement, refs: References, bench: BenchScene) -> dict:
    """Time ratio and exact-chord errors of both on the views both rendered."""
    views = [v for v in ours.views if v in gvxr.views]
    t_ours = sum(t for v, t in zip(ours.views, ours.best_s) if v in views)
    t_gvxr = sum(t for v, t in zip(gvxr.views, gvxr.best_s) if v in views)
    e_ours = error_stats(ours, refs, bench, "exact", views)
    e_gvxr = error_stats(gvxr, refs, bench, "exact", views)
    ratio = t_gvxr / t_ours
    error_ok = all(e_ours[s] <= e_gvxr[s] + 1e-6 for s in ("max", "p99.9"))
    return {"triangles": ours.triangles, "detector": ours.size, "views_deg": [ANGLES_DEG[v] for v in views],
            "ours_s_per_view": t_ours / len(views), "gvxr_s_per_view": t_gvxr / len(views), "ratio": ratio,
            "ours": e_ours, "gvxr": e_gvxr, "error_ok": error_ok, "met": ratio >= 2.0 and error_ok}


if __name__ == "__main__":
    raise SystemExit(main())
