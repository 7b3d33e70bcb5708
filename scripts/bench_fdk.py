"""FDK benchmark: xrayraster's OpenCL FDK beside RTK's CPU FDK, same projections, same grid.

Cases (cone beam, full circle): 128³ voxels from 180 views of 128², 256³ from 360 of 256²,
512³ from 720 of 512². The field of view is 25.6 mm wide whatever the size (voxel 25.6/n mm);
source 100 mm from the axis, detector 200 mm (magnification 2), detector pixels 1.25× the
magnified voxel so the whole phantom is in every view.

Phantom: the 3-D Shepp–Logan head (references/phantoms.py, Schabel's modified table) scaled to a
12 mm "radius", μ of the skull 0.05 mm⁻¹ (0.5 cm⁻¹), projected exactly in float64 (chord lengths,
one ray per pixel centre) and stored as float32; projections are cached in out/bench_fdk_cache/.

Both codes reconstruct with the plain ramp (Ram-Lak), from identical float32 arrays. Times:
ours = ``xr.fdk`` with a warm ``CLContext`` (kernels compiled), the compile time of the first
call measured separately, and, where the device chooses the backprojection itself (``WINDOW_LANES``
"auto": on AVX-512 CPUs ``backproject_columns``), also with the 8-lane (AVX2) windowed kernel
(``ours_8_lanes_s``, and its largest difference from the default volume); RTK = ``FDKConeBeamReconstructionFilter.Update()`` with 2 threads, 16
projections per pass (scripts/peers/rtk_peer.py). Best of ``repeats`` each. Voxel updates per second =
voxels × views / seconds.

Errors against the analytic truth (voxel-centre values): RMSE over voxels whose 3×3×3
neighbourhood of the truth is uniform (away from edges, where a band-limited reconstruction
cannot follow a step), relative to the skull's μ; and the mean over a uniform sphere's inner half
(a second phantom, radius 8 mm, μ 0.05 mm⁻¹, only for the two smaller sizes). Also the largest
difference between ours and RTK, relative to the skull's μ.

Usage::

    python -m scripts.bench_fdk                  # all sizes (~15 min on 2 cores, most of it RTK at 512³)
    python -m scripts.bench_fdk --sizes 128 256  # a subset
    python -m scripts.bench_fdk --quick          # 64³ smoke test

After the sizes, the source-offset, displaced-detector and region-of-interest cases of scripts/bench_fdk_cases.py
(RTK beside us; ``--no-cases`` skips them, ``--quick`` too).

Writes out/bench_fdk.json and docs/bench_fdk.png (``--quick``: out/bench_fdk_quick.json and .png),
and docs/bench_fdk_cases.png.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

import xrayraster as xr
import xrayraster.recon.fdk_stream as fdk_stream
from references.phantoms import project, shepp_logan_3d, sphere, voxel_values
from scripts import bench_fdk_cases, common
from scripts.common import best_of, say
from scripts.peers import rtk_peer

FOV_MM = 25.6
SOD, SDD = 100.0, 200.0
MU = 0.05  # mm⁻¹, the skull
CASES = {64: 90, 128: 180, 256: 360, 512: 720}  # detector and volume size -> views
REPEATS = {64: 3, 128: 3, 256: 2, 512: 1}


def geometry(n: int) -> xr.ConeBeamGeometry:
    voxel = FOV_MM / n
    return xr.ConeBeamGeometry(SOD, SDD, (n, n), 1.25 * voxel * SDD / SOD, xr.full_circle(CASES[n]))


def volume(n: int) -> xr.VolumeGeometry:
    return xr.VolumeGeometry((n, n, n), FOV_MM / n)


def projections(name: str, phantom, n: int, cache: Path) -> np.ndarray:
    """float32 exact projections, cached on disk (they take minutes at 512²)."""
    path = cache / f"{name}_{n}.npy"
    if path.exists():
        return np.load(path)
    g = geometry(n)
    start = time.perf_counter()
    out = np.empty((g.num_views, n, n), np.float32)
    for view in range(g.num_views):
        out[view] = project(phantom, g[view])[0]
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npy")
    np.save(tmp, out)
    os.replace(tmp, path)
    say(f"  projected {name} {g.num_views}×{n}² in {time.perf_counter() - start:.1f} s (cached in {path})")
    return out


def edge_free_mask(truth: np.ndarray) -> np.ndarray:
    """Voxels whose 3×3×3 neighbourhood of the truth is uniform."""
    from numpy.lib.stride_tricks import sliding_window_view

    window = sliding_window_view(np.pad(truth, 1, mode="edge"), (3, 3, 3))
    return np.ptp(window, axis=(-1, -2, -3)) == 0


def run_case(n: int, ctx, with_rtk: bool, cache: Path) -> dict:
    g, vol = geometry(n), volume(n)
    views = g.num_views
    say(f"\n== {n}³ from {views} views of {n}² (voxel {FOV_MM / n:.4g} mm, pixel {g.pixel_size[0]:.4g} mm) ==")
    head = shepp_logan_3d(12.0, MU)
    p = projections("shepp_logan", head, n, cache)
    truth = voxel_values(head, vol)
    mask = edge_free_mask(truth)
    rec = {"size": n, "views": views, "voxel_mm": FOV_MM / n, "pixel_mm": g.pixel_size[0], "updates": n**3 * views}

    t0 = time.perf_counter()
    xr.fdk(p[:1].repeat(views, 0), g, vol, context=ctx)  # warm: first call compiles this size's kernels
    rec["ours_first_call_s"] = time.perf_counter() - t0
    t, ours = best_of(lambda: xr.fdk(p, g, vol, context=ctx).data / 10.0, REPEATS[n])
    rec["ours_s"] = t
    rec["ours_rmse_rel"] = float(np.sqrt(np.mean((ours[mask] - truth[mask]) ** 2)) / MU)
    say(f"  ours: {t:.3f} s ({rec['updates'] / t / 1e9:.2f} G voxel-updates/s; first call incl. compile "
        f"{rec['ours_first_call_s']:.2f} s), RMSE away from edges {rec['ours_rmse_rel']:.5f} of μ_skull")
    if fdk_stream.WINDOW_LANES == "auto":
        fdk_stream.WINDOW_LANES = 8
        try:
            t8, narrow = best_of(lambda: xr.fdk(p, g, vol, context=ctx).data / 10.0, REPEATS[n])
        finally:
            fdk_stream.WINDOW_LANES = "auto"
        rec["ours_8_lanes_s"] = t8
        rec["ours_8_lanes_max_diff_rel"] = float(np.abs(narrow - ours).max() / MU)
        say(f"  ours with 8 lanes (AVX2): {t8:.3f} s, {t8 / t:.2f}× the time; max |8 lanes − default| "
            f"{rec['ours_8_lanes_max_diff_rel']:.2e} of μ_skull")
    if with_rtk:
        runs = [rtk_peer.rtk_fdk(p, g, vol, threads=2) for _ in range(REPEATS[n])]
        rtk = runs[-1]["volume"]
        rec["rtk_s"] = min(r["seconds"] for r in runs)
        rec["rtk_rmse_rel"] = float(np.sqrt(np.mean((rtk[mask] - truth[mask]) ** 2)) / MU)
        rec["ours_minus_rtk_max_rel"] = float(np.abs(ours - rtk).max() / MU)
        rec["ratio"] = rec["rtk_s"] / rec["ours_s"]
        say(f"  RTK:  {rec['rtk_s']:.3f} s ({rec['updates'] / rec['rtk_s'] / 1e9:.2f} G voxel-updates/s), RMSE away "
            f"from edges {rec['rtk_rmse_rel']:.5f} of μ_skull; max |ours − RTK| {rec['ours_minus_rtk_max_rel']:.2e} of μ_skull")
        say(f"  ratio RTK / ours: {rec['ratio']:.2f}×, error {'lower or equal' if rec['ours_rmse_rel'] <= rec['rtk_rmse_rel'] * 1.001 else 'HIGHER'}")
        del runs, rtk
    if n <= 256:  # uniform sphere: the value test of the acceptance, beside RTK's
        ball = [sphere(8.0, MU)]
        ps = projections("sphere", ball, n, cache)
        z, y, x = np.meshgrid(*(vol.axis_centres(a) for a in range(3)), indexing="ij")
        inner = np.sqrt(x**2 + y**2 + z**2) < 4.0
        rec["ours_sphere_err"] = float(xr.fdk(ps, g, vol, context=ctx).data[inner].mean() / 10.0 / MU - 1)
        line = f"  sphere inner-half mean error: ours {rec['ours_sphere_err']:+.4%}"
        if with_rtk:
            rec["rtk_sphere_err"] = float(rtk_peer.rtk_fdk(ps, g, vol, threads=2)["volume"][inner].mean() / MU - 1)
            line += f", RTK {rec['rtk_sphere_err']:+.4%}"
        say(line)
    return rec


def plot(records: list[dict], path: Path) -> Path | None:
    plt = common.pyplot()
    if plt is None:
        return None
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for key, label, colour in (("ours", "xrayraster (OpenCL, PoCL CPU)", "C0"), ("rtk", "RTK 2 threads", "C3")):
        rs = [r for r in records if f"{key}_s" in r]
        if not rs:
            continue
        common.curve(ax, [r["size"] for r in rs], [r[f"{key}_s"] for r in rs], [f"RMSE {r[f'{key}_rmse_rel']:.4f}" for r in rs],
                     color=colour, label=label, offset=(4, -10 if key == "ours" else 6))
        common.curve(ax2, [r[f"{key}_s"] for r in rs], [r[f"{key}_rmse_rel"] for r in rs], [f"{r['size']}³" for r in rs],
                     color=colour, label=label)
    common.log_axes(ax, "n (n³ voxels from 1.4·n views of n² pixels)", "reconstruction time (s), best of runs",
                    "FDK time (labels: RMSE away from edges, fraction of μ)", xbase=2, legend=8)
    common.log_axes(ax2, "time (s)", "RMSE away from edges / μ_skull (3-D Shepp–Logan)", "time vs error", ylog=False, legend=8)
    fig.tight_layout()
    return common.save(fig, path)


def main(argv=None) -> int:
    ap = common.parser(__doc__, "64³ only, a smoke test")
    ap.add_argument("--sizes", type=int, nargs="+", choices=sorted(CASES), default=[128, 256, 512])
    ap.add_argument("--no-rtk", action="store_true", help="do not run RTK")
    ap.add_argument("--no-cases", action="store_true",
                    help="skip the source-offset, displaced-detector and region-of-interest cases (scripts/bench_fdk_cases.py)")
    ap.add_argument("--plot", type=Path, default=None, help="PNG (default docs/bench_fdk.png; --quick: out/bench_fdk_quick.png)")
    args = common.outputs(ap.parse_args(argv), "bench_fdk")
    sizes = [64] if args.quick else args.sizes
    args.plot = args.plot or (common.OUT / "bench_fdk_quick.png" if args.quick else common.DOCS / "bench_fdk.png")
    reason = "disabled (--no-rtk)" if args.no_rtk else rtk_peer.rtk_available()
    ctx = xr.CLContext()
    machine = common.machine_info(cl=ctx)
    common.print_machine(machine, common.command_line())
    say(f"RTK: {reason or 'itk-rtk, 2 threads'}")
    records = []
    start = time.perf_counter()
    for n in sizes:
        records.append(run_case(n, ctx, reason is None, common.OUT / "bench_fdk_cache"))
        common.write_json(args.json, {"machine": machine, "records": records})
    cases = [] if args.quick or args.no_cases else bench_fdk_cases.run(ctx, reason is None)
    say("\n  size  views │ ours s   G upd/s  RMSE     │ RTK s    G upd/s  RMSE     │ RTK/ours")
    for r in records:
        rtk = (f"{r['rtk_s']:>8.3f} {r['updates'] / r['rtk_s'] / 1e9:>8.2f} {r['rtk_rmse_rel']:>8.5f} │ {r['ratio']:>7.2f}×"
               if "rtk_s" in r else f"{'—':>8} {'':>8} {'':>8} │ {'—':>8}")
        say(f"  {r['size']:>4}³ {r['views']:>5} │ {r['ours_s']:>7.3f} {r['updates'] / r['ours_s'] / 1e9:>8.2f} "
            f"{r['ours_rmse_rel']:>8.5f} │ {rtk}")
    png = plot(records, args.plot)
    if cases:
        bench_fdk_cases.plot(cases, bench_fdk_cases.PLOT)
    line = common.finish(machine)
    common.write_json(args.json, {"machine": machine, "records": records, "cases": cases,
                                  "total_s": time.perf_counter() - start})
    say(f"{line}; results {args.json}" + (f"; plot {png}" if png else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
