"""Physics benchmark: the spectral sum, and the whole radiograph beside gVirtualXRay's.

    python -m scripts.bench_physics            # full run, ~4 min on 2 cores
    python -m scripts.bench_physics --quick    # smoke test, < 60 s

Part 1: spectral-sum sweep
--------------------------
``beer_lambert.expected_signal`` (noise-free Σ_b w_b·N_b·a(p)·exp(−Σ_c μ_cb·L_c(p))), the whole
physics step ``radiograph(...)`` (bin trimming, attenuation table, spectral sum, flat
normalisation; output "transmission") and, separately, the noisy ``beer_lambert.sampled_signal``
(integrating detector: one Poisson draw per bin and pixel), on synthetic path lengths: float32
``(channels, n, n)``, each channel uniform in a realistic range (0–8 mm carbon fibre, 0–3 mm
glass, 0–10 mm epoxy, 0–4 mm aluminium). Spectrum: SpekPy 80 kVp W, 2 mm Al, 0.25 keV bins,
regrouped into ``B`` contiguous bins of about equal photon count (photon-weighted mean energy);
detector without scintillator (η = 1, integrating: w = E); per-pixel photon factor of a real
cone-beam view. Error: max relative difference of the transmission (signal ÷ open-beam signal)
against a float64 evaluation straight from the definition (a loop over bins, no trimming) on
2000 seeded pixels. Time: best of up to 3 calls; configurations predicted to exceed the
per-configuration budget are skipped and listed.

Part 2: whole radiograph vs gVirtualXRay
----------------------------------------
The 3-material weave of ``scripts.weave_scene.build_scene`` (level 60: 1,117,440 triangles), materials
real: warp = carbon fibre (C, 1.80 g/cm³), weft = E-glass fibre (2.55 g/cm³), binder = epoxy
(DGEBA, C21H24O4, 1.16 g/cm³); spectrum SpekPy 40 kVp W, 2 mm Al, 0.5 keV bins; detector without
scintillator (η = 1, energy-integrating), same cone-beam geometry and views as bench_render.
Ours: ``Renderer.project(scene, spectrum, view, output="transmission")`` (render + physics), and
separately with ``noise=True``. gVirtualXRay: ``computeXRayImage`` (energy fluence, MeV) ÷ its
flat (``scripts.peers.gvxr_peer.gvxr_xray_image``), with its default bin cut-off and with every bin.
Error of both: relative to a float64 transmission on 2000 seeded pixels per view from the exact
polyhedral chords of the same meshes (weave_scene.References, kind "exact") × μ from our
Material (xraylib CS_Total), every non-empty bin, no trimming.

Writes out/bench_physics.json and docs/bench_physics_spectral_sum.png,
docs/bench_physics_radiograph.png (``--quick``: out/, names ending in _quick).
Part 1 is :mod:`scripts.physics_sweep`, part 2 :mod:`scripts.physics_radiograph`; this module runs them.
"""

from __future__ import annotations

import time
from pathlib import Path

import xrayraster as xr
from scripts import common
from scripts import physics_radiograph as part2
from scripts import physics_sweep as part1
from scripts import weave_scene as weave
from scripts.common import say
from scripts.peers import gvxr_peer


def plot(sweep_records, rows, plots_dir: Path, suffix: str) -> list[Path]:
    plt = common.pyplot()
    if plt is None:
        return []
    paths = [part1.plot(plt, sweep_records, plots_dir, suffix), part2.plot(plt, rows, plots_dir, suffix)]
    return [p for p in paths if p is not None]


# ---------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = common.parser(__doc__, "small sizes only: a smoke test that finishes in < 60 s", plots=True)
    ap.add_argument("--no-gvxr", action="store_true", help="do not run gVirtualXRay")
    ap.add_argument("--skip-sweep", action="store_true", help="part 2 only")
    ap.add_argument("--skip-radiograph", action="store_true", help="part 1 only")
    args = common.outputs(ap.parse_args(argv), "bench_physics")

    if args.quick:
        sizes, channels, bins, repeats, budget, noise_budget = [128, 256], [1, 3], [1, 10, 80], 2, 1.0, 1.0
        level, rsizes, views = 18, [256], 1
    else:
        sizes, channels, bins, repeats, budget, noise_budget = [512, 1024, 2048], [1, 2, 3, 4], [1, 10, 40, 80, 150], 3, 4.0, 6.0
        level, rsizes, views = 60, [512, 1024], 3

    t_start = time.perf_counter()
    ctx = xr.GLContext()
    command, machine = common.announce(gl=ctx)
    payload = {"command": command, "machine": machine, "settings": {
        "sweep_sizes": sizes, "sweep_channels": channels, "sweep_bins": bins, "repeats": repeats,
        "budget_s": budget, "noise_budget_s": noise_budget, "ref_pixels": part1.REF_PIXELS, "level": level,
        "radiograph_sizes": rsizes, "views": views, "sod_mm": weave.SOD, "sdd_mm": weave.SDD, "detector_width_mm": weave.DET_WIDTH}}

    if not args.skip_sweep:
        recs, skipped, desc = part1.sweep(sizes, channels, bins, repeats, budget, noise_budget)
        payload["sweep"] = {"spectrum": desc, "records": recs, "skipped": skipped}
        common.write_json(args.json, payload)
        say(f"part 1: {time.perf_counter() - t_start:.1f} s so far")

    rows = []
    if not args.skip_radiograph:
        reason = "disabled (--no-gvxr)" if args.no_gvxr else gvxr_peer.gvxr_available()
        rows, info = part2.whole(level, rsizes, views, repeats, reason is None, reason, ctx)
        payload["radiograph"] = {"info": info, "rows": rows, "gvxr_reason": reason}
        payload["radiograph"]["comparisons"], target_met = part2.targets(rows, info)
        if target_met is not None:
            payload["target_met"] = target_met
        common.write_json(args.json, payload)

    for path in plot(payload.get("sweep", {}).get("records", []), rows, args.plots_dir, "_quick" if args.quick else ""):
        say(f"plot: {path}")
    common.conclude(args.json, payload, machine, t_start, top_level_load=True)
    return 0  # ctx deliberately not released (see bench_render.main)


if __name__ == "__main__":
    raise SystemExit(main())
