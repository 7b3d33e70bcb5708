"""Scatter kernels (``[physics] scatter = "kernel"``) against the Monte-Carlo reference, and what
they cost a view.

    python -m scripts.bench_scatter            # 20 million photons a case, the twin's views (~6 min)
    python -m scripts.bench_scatter --quick    # 1 million photons, 4 views (~40 s)

Part 1, error: a water cylinder (1 g/cm³, 40 mm high, 20 or 50 mm across) on the axis of a cone beam
(source 150 mm from the axis, 300 mm from a detector of 32 × 64 pixels of 4 mm), a tungsten tube at
40 or 100 kV behind 1 mm of aluminium, an ideal energy-integrating detector. The reference is
``references/scatter_mc.py`` (photons tracked with xraylib's Compton and Rayleigh cross sections,
every order of scatter); ours the kernels on the renderer's path lengths, one view without and
one with scatter. Compared: the scatter-to-primary ratio (SPR) over the middle 4 × 4 pixels and
the full width at half maximum of the scatter's profile across the middle 16 rows.

Part 2, cost: views of ``examples/twin.toml`` (512², a woven sample, 3 materials, noise and the
spectral table as its scan has them) with and without scatter, taking turns view by view: the path
lengths (pooled: scatter touches no GL) and the physics, median seconds a view.

Part 3, cupping: the middle slice of a 50 mm water cylinder scanned at 60 keV (one energy: no beam
hardening) with and without scatter, SOD 150 mm, SDD 300 mm, 128² detector of 1 mm pixels.

Writes out/bench_scatter.json, docs/bench_scatter.png and docs/scatter_cupping.png.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

import xrayraster as xr
from references.scatter_mc import Setup, simulate
from xrayraster.io.scan_file import load_scan_file
from xrayraster.physics.realism import Realism

from .common import announce, conclude, outputs, parser, pyplot, say

CASES = ((40.0, 20.0), (40.0, 50.0), (100.0, 20.0), (100.0, 50.0))  # kV, cylinder diameter (mm)
MIDDLE = (slice(14, 18), slice(30, 34))
ROWS = slice(8, 24)
PITCH_MM = 4.0


def fwhm_mm(profile: np.ndarray) -> float:
    """Full width at half maximum of a single-peaked profile, its crossings interpolated."""
    half = profile.max() / 2
    above = np.flatnonzero(profile >= half)
    lo, hi = above[0], above[-1]
    left = lo - (profile[lo] - half) / (profile[lo] - profile[lo - 1]) if lo > 0 else lo
    right = hi + (profile[hi] - half) / (profile[hi] - profile[hi + 1]) if hi < len(profile) - 1 else hi
    return float((right - left) * PITCH_MM)


def accuracy(kvp: float, diameter_mm: float, photons: int, gl) -> dict:
    spectrum = xr.Spectrum.from_tube(kvp, filters={"Al": 1.0})
    keep = spectrum.fluence > 1e-4 * spectrum.fluence.max()
    setup = Setup(tuple(spectrum.energies[keep]), tuple(spectrum.fluence[keep]), rows=32, cols=64, pixel_mm=PITCH_MM,
                  diameter_mm=diameter_mm, height_mm=40.0)
    start = time.perf_counter()
    reference = simulate(setup, photons, seed=int(kvp + diameter_mm))
    reference_s = time.perf_counter() - start
    geometry = xr.ConeBeamGeometry(setup.source_to_origin, setup.source_to_detector, (32, 64), PITCH_MM, [0.0])
    cylinder = xr.Scene()
    cylinder.add(trimesh.creation.cylinder(diameter_mm / 2, 40.0, sections=512), xr.Material.from_formula("H2O", 1.0))
    with xr.Renderer(geometry, context=gl) as renderer:
        primary = renderer.project(cylinder, spectrum, output="raw").image.astype(np.float64)
        start = time.perf_counter()
        shot = renderer.project(cylinder, spectrum, output="raw", realism=Realism(scatter="kernel"))
        model_s = time.perf_counter() - start
    scatter = shot.image - primary
    spr = scatter[MIDDLE].sum() / primary[MIDDLE].sum()
    spr_reference = reference.scatter[MIDDLE].sum() / reference.primary[MIDDLE].sum()
    width, width_reference = fwhm_mm(scatter[ROWS].mean(axis=0)), fwhm_mm(reference.scatter[ROWS].mean(axis=0))
    row = {"kvp": kvp, "diameter_mm": diameter_mm, "photons": photons, "spr": spr, "spr_reference": spr_reference,
           "spr_error": spr / spr_reference - 1, "fwhm_mm": width, "fwhm_reference_mm": width_reference,
           "fwhm_error": width / width_reference - 1, "monte_carlo_s": reference_s,
           "kernels_s": model_s, "profile": (scatter[ROWS].mean(axis=0) / primary[ROWS].mean(axis=0)).tolist(),
           "profile_reference": (reference.scatter[ROWS].mean(axis=0) / reference.primary[ROWS].mean(axis=0)).tolist()}
    say(f"{kvp:g} kV, {diameter_mm:g} mm water: SPR {spr:.4f} against the Monte Carlo's {spr_reference:.4f} "
        f"({row['spr_error']:+.1%}), FWHM {width:.1f} against {width_reference:.1f} mm ({row['fwhm_error']:+.1%}); "
        f"Monte Carlo {reference_s:.1f} s for {photons:.0e} photons, kernels {model_s * 1e3:.0f} ms (made and applied)")
    return row


def cost(views: int, gl) -> dict:
    """Median seconds a view without and with scatter, the two taking turns view by view (so both
    meet the same state of the machine); the first of each, which makes what the scan shares, is left out."""
    loaded = load_scan_file("examples/twin.toml")
    scene = loaded.with_mount(loaded.sample_scene())
    times = {s: {"path_lengths": [], "physics": [], "view": []} for s in ("none", "kernel")}
    ratios = []
    with xr.Renderer(loaded.geometry, context=gl) as renderer:
        for view in range(views + 1):
            for scatter in ("none", "kernel"):
                realism = Realism(**{**loaded.realism.to_dict(), "scatter": scatter})
                shot = renderer.project(scene, loaded.spectrum, view * 7, detector=loaded.detector, noise=True,
                                        seed=0, realism=realism, spectral_table=True)
                if view:
                    for key, value in renderer.last_seconds.items():
                        times[scatter][key].append(value)
                    times[scatter]["view"].append(sum(renderer.last_seconds.values()))
                    if scatter == "kernel":
                        ratios.append(shot.spr_centre)
    medians = {s: {k: statistics.median(v) for k, v in t.items()} for s, t in times.items()}
    # Scatter touches no GL: the views' path lengths are pooled (the GL's time swings by 10-20 ms
    # from one call to the next on llvmpipe), and each case's view is that plus its own physics.
    gl_s = statistics.median(times["none"]["path_lengths"] + times["kernel"]["path_lengths"])
    view = {s: gl_s + medians[s]["physics"] for s in medians}
    row = {"views": views, "detector": list(loaded.geometry.detector_shape), "median_s": medians,
           "path_lengths_pooled_s": gl_s, "view_s": view, "ratio": view["kernel"] / view["none"],
           "physics_added_s": medians["kernel"]["physics"] - medians["none"]["physics"],
           "spr_centre": statistics.mean(ratios)}
    say(f"twin view {row['detector'][0]}²: path lengths {gl_s * 1e3:.0f} ms (median of both), physics "
        f"{medians['none']['physics'] * 1e3:.1f} ms without scatter, {medians['kernel']['physics'] * 1e3:.1f} with it: "
        f"a view {view['none'] * 1e3:.0f} against {view['kernel'] * 1e3:.0f} ms, {row['ratio']:.2f}x; its SPR at the "
        f"centre {row['spr_centre']:.3f} (medians of {views} views each)")
    return row


CUPPING_SCAN = """
[[objects]]
name = "water"
mesh = {{ cylinder = 25.0, height = 60.0 }}
material = "water"

[materials.water]
formula = "H2O"
density = 1.0

[source]
monochromatic_kev = 60.0
photons_per_mm2_at_1m = 1e9

[geometry]
beam = "cone"
source_to_origin = 150.0
source_to_detector = 300.0
detector_shape = [128, 128]
pixel_size = 1.0
num_views = 360

[volume]
shape = [1, 192, 192]
voxel_size = 0.3

[scan]
noise = false

[physics]
scatter = "{scatter}"
"""


def cupping() -> dict:
    """The middle slice with and without scatter, and its cupping: 1 − (μ within 5 mm of the axis) /
    (μ 18–22 mm from it)."""
    slices, rows = {}, {}
    with tempfile.TemporaryDirectory() as folder:
        for scatter in ("none", "kernel"):
            path = Path(folder) / f"{scatter}.toml"
            path.write_text(CUPPING_SCAN.format(scatter=scatter))
            result = xr.scan(path)
            mu = result.volume.data[0]
            radius = np.hypot(*(np.indices(mu.shape) - (np.array(mu.shape)[:, None, None] - 1) / 2)) * 0.3
            centre, edge = float(mu[radius < 5].mean()), float(mu[(radius > 18) & (radius < 22)].mean())
            slices[scatter] = mu
            rows[scatter] = {"centre_per_cm": centre, "edge_per_cm": edge, "cupping": 1 - centre / edge,
                             "spr": result.metadata["projections"].get("scatter_to_primary")}
            say(f"cupping, scatter {scatter}: μ {centre:.4f} cm⁻¹ at the centre, {edge:.4f} near the edge: "
                f"{rows[scatter]['cupping']:+.1%}")
    return {"rows": rows, "slices": slices}


def plot_cupping(cup: dict, plots_dir) -> None:
    plt = pyplot()
    if plt is None:
        return
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), layout="constrained")
    water = xr.Material.from_formula("H2O", 1.0).attenuation(60.0) * 10  # cm⁻¹
    for ax, scatter in zip(axes, ("none", "kernel")):
        image = ax.imshow(cup["slices"][scatter], cmap="gray", vmin=0.17, vmax=0.215)
        ax.set_title(f"scatter = \"{scatter}\": cupping {cup['rows'][scatter]['cupping']:+.1%}", fontsize=9)
        ax.axis("off")
    fig.colorbar(image, ax=axes[1], label="μ (cm⁻¹)", shrink=0.8)
    x = (np.arange(192) - 95.5) * 0.3
    for scatter, style in (("none", "-"), ("kernel", "-")):
        axes[2].plot(x, cup["slices"][scatter][96], style, label=f"scatter = \"{scatter}\"")
    axes[2].axhline(water, color="k", linestyle=":", label="water at 60 keV")
    axes[2].set_xlim(-27, 27)
    axes[2].set_ylim(0.17, 0.215)
    axes[2].set_xlabel("mm from the axis")
    axes[2].set_ylabel("μ (cm⁻¹), middle row")
    axes[2].legend(fontsize=7)
    path = plots_dir / "scatter_cupping.png"
    fig.savefig(path, dpi=120)
    say(f"plot: {path}")


def plot(rows: list[dict], costs: dict, plots_dir) -> None:
    plt = pyplot()
    if plt is None:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [2, 1]})
    x = (np.arange(64) - 31.5) * PITCH_MM
    for row, colour in zip(rows, ("C0", "C1", "C2", "C3")):
        label = f"{row['kvp']:g} kV, {row['diameter_mm']:g} mm"
        axes[0].plot(x, row["profile_reference"], ".", color=colour, markersize=3, label=f"{label}: Monte Carlo")
        axes[0].plot(x, row["profile"], "-", color=colour, label=f"kernels ({row['spr_error']:+.0%} at the centre)")
    axes[0].set_xlabel("detector column (mm from the centre)")
    axes[0].set_ylabel("scatter / primary, middle 16 rows")
    axes[0].set_yscale("log")
    axes[0].legend(fontsize=6, ncol=2)
    axes[0].set_title("Water cylinders, SOD 150 mm, SDD 300 mm", fontsize=9)
    parts, gl_ms = costs["median_s"], costs["path_lengths_pooled_s"] * 1e3
    for i, scatter in enumerate(("none", "kernel")):
        axes[1].bar(i, gl_ms, color="C7", label="path lengths (GL)" if not i else None)
        axes[1].bar(i, parts[scatter]["physics"] * 1e3, bottom=gl_ms, color="C0",
                    label="physics (CPU)" if not i else None)
    axes[1].set_xticks([0, 1], ["no scatter", "scatter kernels"])
    axes[1].set_ylabel("ms a view (median)")
    axes[1].set_title(f"Twin view {costs['detector'][0]}²: {costs['ratio']:.2f}x", fontsize=9)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    path = plots_dir / "bench_scatter.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    say(f"plot: {path}")


def main() -> None:
    args = outputs(parser(__doc__, "1 million photons a case, 4 views", plots=True).parse_args(), "bench_scatter")
    t_start = time.perf_counter()
    with xr.GLContext() as gl:
        command, machine = announce(gl=gl)
        rows = [accuracy(kvp, diameter, 1_000_000 if args.quick else 20_000_000, gl) for kvp, diameter in CASES]
        costs = cost(4 if args.quick else 30, gl)
    cup = cupping()
    plot(rows, costs, args.plots_dir)
    plot_cupping(cup, args.plots_dir)
    conclude(args.json, {"command": command, "machine": machine, "rows": rows, "cost": costs,
                         "cupping": cup["rows"]}, machine, t_start)


if __name__ == "__main__":
    main()
