"""FDK on the hard scan geometries, beside RTK in the same run: RTK's own FDK test (a source offset),
a displaced detector and a region-of-interest (truncated) scan. Time and error of each, for both codes.

* **Source offset**: RTK's rtkfdktest (source 600 mm from the axis, moved 20 mm sideways and 15 mm
  up, detector 1200 mm from it, 180 views over 360° of 128² pixels of 4 mm, RTK's Shepp–Logan at
  scale 116 mm): its case 1 (128³ voxels of 2 mm) and case 5 (a 64³ region off the centre),
  scored as RTK scores itself: the reconstruction outside RTK's field-of-view mask set to 0
  (``rtk.FieldOfViewImageFilter``; without RTK, ``references.fdk.seen_in_every_view``), then error
  per voxel (threshold 0.03) and PSNR (peak 2, threshold 26 dB) over the whole grid. Ours with
  ``displaced="auto"`` told the phantom's reach (½ weights: it lies within the radius both sides
  of the detector see) and forced to Wang's weights; RTK's FDKConeBeamReconstructionFilter as in
  its test. RTK's cases 2 and 4 reconstruct case 1's voxel centres (in another axis order;
  streamed in slabs), which for us is case 1 again: case 4's slabs are checked to give case 1's
  bytes to float32 rounding. Case 3 (and RTK's case 5, which keeps case 3's direction matrix) uses an oblique grid,
  which ``VolumeGeometry`` (axis-aligned, shared with the labels) does not describe; case 5 is run
  on the axis-aligned grid with its origin and size, for both codes.

* **Displaced detector**: RTK's rtkdisplaceddetectortest at full size (source 600 mm, detector
  1200 mm, 180 views over 360° of 128² pixels of 4 mm, RTK's Shepp–Logan at scale 128 mm,
  128³ voxels of 2 mm), the detector moved by +120 mm and to a projection origin of −400 mm.
  Ours: ``xr.fdk`` (Wang's weights chosen from the coverage); RTK: DisplacedDetectorImageFilter
  then FDKConeBeamReconstructionFilter. Scored as RTK scores itself over the whole volume: error
  per voxel (threshold 0.061) and PSNR (peak 2, threshold 24 dB).
* **Region of interest**: a homogeneous cylinder (μ 0.02 mm⁻¹) 1.5× wider than the field of
  view; source 200 mm, detector 400 mm, 360 views of 64 rows × 128 columns of 1 mm, the field of
  view's square on 128² × 16 voxels. Ours with the truncation correction off and on (default
  width, half the detector on each side); RTK without and with its own (``SetTruncationCorrection
  (0.5)``, the same width). Scored inside 0.9 of the field of view's radius, relative to μ: mean
  bias, cupping (the rim 0.75–0.85 minus the centre 0–0.15) and RMSE.

Projections are exact chord lengths (references/phantoms.py) in float64, stored as float32; both
codes get the same arrays. Times: best of ``REPEATS`` (ours with a warm ``CLContext``; RTK with 2
threads, 16 projections per pass); the first of ours compiles the kernels, so the best is warm.

Usage::

    python -m scripts.bench_fdk_cases   # ~70 s on 2 cores (scripts/bench_fdk.py runs them too)

Writes out/bench_fdk_cases.json and docs/bench_fdk_cases.png.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

import xrayraster as xr
from references.fdk import seen_in_every_view
from references.phantoms import Ellipsoid, project, rtk_shepp_logan, voxel_values
from scripts import common
from scripts.common import say
from scripts.peers import rtk_peer
from xrayraster.recon.truncation import DEFAULT_WIDTH

REPEATS = 3
DISPLACED = {"offset +120 mm": 120.0, "origin −400 mm": -146.0}  # detector centre's offset, mm
# RTK's rtkfdktest: AddProjection(600, 1200, angle, 0, 0, 0, 0, 20, 15), on our (row, col) axes.
FDKTEST = xr.ConeBeamGeometry(600.0, 1200.0, (128, 128), 4.0, xr.full_circle(180), source_offset=(15.0, 20.0))
# Its grids on our (z, y, x) axes: RTK's (X, Y, Z) are our (x, z, −y); case 5's first voxel at (−5, −13, −20).
FDKTEST_GRIDS = {"case 1": xr.VolumeGeometry((128, 128, 128), 2.0),
                 "case 5": xr.VolumeGeometry((64, 64, 64), 2.0, offset=(50.0, -43.0, 58.0))}
ROI_SCALE = 1.5  # cylinder radius / field-of-view radius
PLOT = common.DOCS / "bench_fdk_cases.png"
MU = 0.02  # mm⁻¹


def timed(run) -> tuple[float, np.ndarray]:
    """(best seconds of REPEATS runs, the last volume in mm⁻¹); ``run()`` gives (seconds, volume)."""
    results = [run() for _ in range(REPEATS)]
    return min(seconds for seconds, _ in results), results[-1][1]


def ours(*args, **options):
    start = time.perf_counter()
    volume = xr.fdk(*args, **options).data / 10.0  # cm⁻¹ -> mm⁻¹
    return time.perf_counter() - start, volume


def rtk(*args, **options):
    """RTK's FDK; its time is the filter's Update() alone, as bench_fdk times it."""
    out = rtk_peer.rtk_fdk(*args, threads=2, **options)
    return out["seconds"], out["volume"]


def rtk_score(volume_mm, truth, mask) -> dict:
    """RTK's CheckImageQuality on the masked reconstruction: error per voxel and PSNR (peak 2)."""
    error = np.where(mask, volume_mm, 0.0) - truth
    return {"error_per_voxel": float(np.abs(error).mean()),
            "psnr_db": float(20 * math.log10(2.0) - 10 * math.log10(np.mean(error**2)))}


def fdktest_cases(ctx, with_rtk: bool) -> list[dict]:
    phantom = rtk_shepp_logan(116.0)
    reach = max(max(e.semi_axes[:2]) for e in phantom)  # mm: the outer ellipsoid, centred and unturned
    p = project(phantom, FDKTEST).astype(np.float32)
    records = []
    for name, volume in FDKTEST_GRIDS.items():
        truth = voxel_values(phantom, volume)
        mask = rtk_peer.rtk_fov_mask(FDKTEST, volume) if with_rtk else seen_in_every_view(FDKTEST, volume)
        runs = {"ours": lambda: ours(p, FDKTEST, volume, object_radius_mm=reach, context=ctx),
                "ours, Wang's weights": lambda: ours(p, FDKTEST, volume, displaced=True, context=ctx)}
        if with_rtk:
            runs["rtk"] = lambda: rtk(p, FDKTEST, volume)
        rec = {"case": "fdktest", "name": name, "mask": "RTK's" if with_rtk else "references.fdk"}
        volumes = {}
        for code, run in runs.items():
            t, volumes[code] = timed(run)
            rec[code] = {"seconds": t, **rtk_score(volumes[code], truth, mask)}
        if name == "case 1":  # RTK's case 4, streamed: ours in slabs, planned for 6 MiB (the volume takes 8)
            slabs = ours(p, FDKTEST, volume, object_radius_mm=reach, context=ctx, memory_limit=6 << 20)[1]
            rec["case 4 slabs minus case 1"] = float(np.abs(slabs - volumes["ours"]).max())
        records.append(rec)
        say(f"  rtkfdktest {name}: " + "; ".join(
            f"{code} {r['seconds']:.2f} s, error per voxel {r['error_per_voxel']:.5f}, PSNR {r['psnr_db']:.3f} dB"
            for code, r in rec.items() if isinstance(r, dict))
            + (f"; case 4 in slabs: max |slabs − whole| {rec['case 4 slabs minus case 1']:.1e}" if name == "case 1" else ""))
    return records


def displaced_cases(ctx, with_rtk: bool) -> list[dict]:
    phantom = rtk_shepp_logan(128.0)
    volume = xr.VolumeGeometry((128, 128, 128), 2.0)
    truth = voxel_values(phantom, volume)
    records = []
    for name, offset in DISPLACED.items():
        g = xr.ConeBeamGeometry(600.0, 1200.0, (128, 128), 4.0, xr.full_circle(180), detector_offset=(0.0, offset))
        p = project(phantom, g).astype(np.float32)
        rec = {"case": "displaced", "name": name}
        runs = {"ours": lambda: ours(p, g, volume, context=ctx)}
        if with_rtk:
            runs["rtk"] = lambda: rtk(p, g, volume, displaced=True)
        volumes = {}
        for code, run in runs.items():
            t, out = timed(run)
            error = out - truth
            rec[code] = {"seconds": t, "error_per_voxel": float(np.abs(error).mean()),
                         "psnr_db": float(20 * math.log10(2.0) - 10 * math.log10(np.mean(error**2)))}
            volumes[code] = out
        if with_rtk:
            rec["ours_minus_rtk_max"] = float(np.abs(volumes["ours"] - volumes["rtk"]).max())
        records.append(rec)
        say(f"  displaced, {name}: " + "; ".join(
            f"{code} {r['seconds']:.2f} s, error per voxel {r['error_per_voxel']:.4f}, PSNR {r['psnr_db']:.2f} dB"
            for code, r in rec.items() if isinstance(r, dict))
            + (f"; max |ours − RTK| {rec['ours_minus_rtk_max']:.4f}" if with_rtk else ""))
    return records


def roi_case(ctx, with_rtk: bool) -> dict:
    source, detector, rows, cols = 200.0, 400.0, 64, 128
    g = xr.ConeBeamGeometry(source, detector, (rows, cols), 1.0, xr.full_circle(360))
    fov = source * math.sin(math.atan(cols / 2 / detector))
    volume = xr.VolumeGeometry((16, 128, 128), 2 * fov / 128)
    p = project([Ellipsoid((0.0, 0.0, 0.0), (ROI_SCALE * fov, ROI_SCALE * fov, 1e5), 0.0, MU)], g).astype(np.float32)
    y, x = np.meshgrid(*(np.arange(128) - 63.5,) * 2, indexing="ij")
    r = np.hypot(x, y) / 64  # share of the field of view's radius
    inside, rim, centre = r < 0.9, (r > 0.75) & (r < 0.85), r < 0.15

    def score(volume_mm):
        error = volume_mm / MU - 1
        return {"bias": float(error[:, inside].mean()), "cupping": float(error[:, rim].mean() - error[:, centre].mean()),
                "rmse": float(np.sqrt(np.mean(error[:, inside] ** 2)))}

    runs = {"ours, off": lambda: ours(p, g, volume, truncation=False, context=ctx),
            "ours, corrected": lambda: ours(p, g, volume, context=ctx)}
    if with_rtk:
        runs["RTK, off"] = lambda: rtk(p, g, volume)
        runs["RTK, corrected"] = lambda: rtk(p, g, volume, truncation=DEFAULT_WIDTH)
    rec = {"case": "roi", "name": f"cylinder {ROI_SCALE}× the field of view", "fov_radius_mm": fov}
    for name, run in runs.items():
        t, out = timed(run)
        rec[name] = {"seconds": t, **score(out)}
        say(f"  ROI, {name}: {t:.2f} s, interior bias {rec[name]['bias']:+.4f}, cupping {rec[name]['cupping']:+.4f}, "
            f"RMSE {rec[name]['rmse']:.4f} (of μ)")
    return rec


def run(ctx, with_rtk: bool) -> list[dict]:
    """Every case; ``scripts/bench_fdk.py`` runs them after its sizes too."""
    say("\n== source offset, displaced detector and region of interest (scripts/bench_fdk_cases.py) ==")
    return fdktest_cases(ctx, with_rtk) + displaced_cases(ctx, with_rtk) + [roi_case(ctx, with_rtk)]


def plot(records: list[dict], path: Path) -> Path | None:
    plt = common.pyplot()
    if plt is None:
        return None
    fig, (ax0, ax, ax2) = plt.subplots(1, 3, figsize=(16, 4.5))
    for rec in (r for r in records if r["case"] == "fdktest"):
        for code, colour in (("ours", "C0"), ("ours, Wang's weights", "C2"), ("rtk", "C3")):
            if code in rec:
                common.curve(ax0, [rec[code]["seconds"]], [rec[code]["error_per_voxel"]], [rec["name"]], color=colour,
                             marker="o" if rec["name"] == "case 1" else "s",
                             label=f"{'RTK 2 threads' if code == 'rtk' else 'xrayraster' + code[4:]}, {rec['name']}")
    ax0.axhline(0.03, color="0.5", ls="--", lw=1)
    common.log_axes(ax0, "time (s)", "error per voxel (RTK's threshold 0.03 dashed)",
                    "source offset (20, 15) mm, RTK's rtkfdktest", ylog=False, legend=7)
    for rec in (r for r in records if r["case"] == "displaced"):
        for code, colour in (("ours", "C0"), ("rtk", "C3")):
            if code in rec:
                common.curve(ax, [rec[code]["seconds"]], [rec[code]["error_per_voxel"]], [rec["name"]], color=colour,
                             label=f"{'xrayraster' if code == 'ours' else 'RTK 2 threads'}, {rec['name']}")
    ax.axhline(0.061, color="0.5", ls="--", lw=1)
    common.log_axes(ax, "time (s)", "error per voxel (RTK's threshold 0.061 dashed)",
                    "displaced detector, RTK's functional test", ylog=False, legend=7)
    roi = next(r for r in records if r["case"] == "roi")
    for name, colour in (("ours, off", "C0"), ("ours, corrected", "C0"), ("RTK, off", "C3"), ("RTK, corrected", "C3")):
        if name in roi:
            common.curve(ax2, [roi[name]["seconds"]], [abs(roi[name]["bias"])], [name], color=colour,
                         marker="o" if "corrected" in name else "x", label=name)
    common.log_axes(ax2, "time (s)", "|interior bias| / μ", f"region of interest: {roi['name']}", legend=7)
    fig.tight_layout()
    return common.save(fig, path)


def main(argv=None) -> int:
    ap = common.parser(__doc__, "the same (the cases are small)")
    ap.add_argument("--no-rtk", action="store_true", help="do not run RTK")
    args = common.outputs(ap.parse_args(argv), "bench_fdk_cases")
    reason = "disabled (--no-rtk)" if args.no_rtk else rtk_peer.rtk_available()
    ctx = xr.CLContext()
    machine = common.machine_info(cl=ctx)
    common.print_machine(machine, common.command_line())
    say(f"RTK: {reason or 'itk-rtk, 2 threads'}")
    start = time.perf_counter()
    records = run(ctx, reason is None)
    png = plot(records, PLOT)
    line = common.finish(machine)
    common.write_json(args.json, {"machine": machine, "records": records, "total_s": time.perf_counter() - start})
    say(f"{line}; results {args.json}" + (f"; plot {png}" if png else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
