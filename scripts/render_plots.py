"""bench_render's plots: time per view against error for the tessellation, supersampling and
detector sweeps (matplotlib, loaded on first use by :func:`scripts.common.pyplot`).
"""

from __future__ import annotations

from pathlib import Path

from scripts import common

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
