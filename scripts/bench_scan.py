"""Virtual-scan benchmark: ``xr.scan`` end to end beside the same scan glued from gVirtualXRay and RTK.

    python -m scripts.bench_scan                # 200 views: 5–7.5 min on 2 cores (+1.5 min the first time: the reference)
    python -m scripts.bench_scan --views 400    # the whole reduced twin: ~17 min under load
    python -m scripts.bench_scan --quick        # smoke test: 36 views, 64² detector, 64³ grid (~1 min)

The reduced twin
----------------
Half the digital twin of ``examples/twin.toml`` in every direction: a woven sample of 2 × 2 cells of
the default layer-to-layer angle-interlock cell (20 × 20 × 4 mm; weft C 1.72 g/cm³, warp C 1.82,
matrix C 40.4 %, H 48.1 %, Cl 1.9 %, O 9.6 % by mass at 1.08 g/cm³), a 40 kV tungsten tube through
2 mm Al at 1.25 mAs, source 60 mm from the axis and detector 140 mm from the source, 256 × 256
pixels of 0.2697 mm (0.1156 mm at the axis), a 256³ grid of 0.1156 mm voxels, Ram-Lak filter. The
scan file is written by :func:`scan_file_text`; the weave's mesh resolution is the one the grid
chooses (``mesh_tolerance_voxels`` 0.05: 48 points per section, ~11.7 rings per mm, 1.7 M
triangles). The twin has 400 views; by default 200 are measured, since gVirtualXRay renders
this sample at 0.8–1 s a view here (``--views 400`` runs them all, about twice as long).

The two pipelines, noise off
----------------------------
* **ours**: ``xr.scan(scan_file)`` (mesh the weave, ``Renderer.project_all``, ``xr.fdk``,
  ``xr.voxelize``), stage times from ``result.metadata["seconds"]``; it also makes the labels.
* **peer**, as a user without us glues it: the same weave (``ScanFile.weave``, same mesh knobs)
  as one closed mesh per family, made disjoint with ``Sample.parts(per="family",
  resolve="boolean")`` (gVirtualXRay has no priorities: overlapping meshes would count twice)
  and centred as the scan places it; edges longer than ``--peer-max-edge`` (2 mm) split
  (``trimesh.remesh.subdivide_to_size``: gVirtualXRay interpolates depth across each triangle in
  screen space, wrong across big triangles with a near source: the matrix's box faces are a few
  large triangles; ``--peer-max-edge 0`` shows the difference), which gives it its best error for
  few more triangles; gVirtualXRay renders every view polychromatically with the
  scan's own spectrum bins (photons per pixel at the detector, energy-integrating, its default bin
  cut-off) through ``scripts.peers.gvxr_peer.gvxr_scan_images``; flat-field and −log in NumPy;
  RTK's CPU FDK (2 threads, ``scripts.peers.rtk_peer.rtk_fdk``) on the same grid. No labels.
  Library start-up (gvxr's import and context, ITK's import) is timed apart and left out of the
  end-to-end time, as importing xrayraster is.
Photon noise is off in both (gVirtualXRay has none); ``--noise-run`` also times ours with it on.

The float64 reference
---------------------
Our own pipeline with noise off is not independent, and a labels × μ map is not what FDK of a
polychromatic scan converges to (beam hardening), so the reference is the reconstruction of exact
projections of the same meshes:

1. **Path lengths**: float64 ray–triangle intersection written here from the geometry's
   definition (``references.mesh_paths.exact_path_lengths``): each triangle of the disjoint family meshes (float64
   vertices) is projected centrally onto the detector, every pixel centre inside it is a ray that
   crosses it, and the crossing's distance from the source along the ray, + on leaving and − on
   entering a closed surface, sums to the length inside (``--self-check`` compares it with
   ``references.chords.box_chord`` on a box). The boolean partition
   is the priority partition of ``xr.scan``'s scene (higher priority keeps shared space), to
   manifold3d's float64 rounding.
2. **Line integrals**: −ln of Σ_b N_b E_b exp(−Σ_m μ_mb L_m) / Σ_b N_b E_b over every non-empty
   bin of the scan's spectrum, μ straight from ``xraylib.CS_Total`` and the mass fractions.
3. **Reconstruction**: ``references.fdk.fdk_reference`` (plain NumPy float64 FDK, Ram-Lak), on
   ``--slices`` z positions of the grid (default 0 and 0.4 mm: the middle weft layer and the binder
   gap above it), on the voxels over the sample's footprint (x, y inside the box). Only the
   detector rows those voxels project to (plus one for interpolation) are computed; every other
   row is outside their backprojection and the filter runs along rows only.

Errors: RMSE of each pipeline's reconstruction against the reference on those voxels (cm⁻¹); of
their line integrals against the exact ones on the computed rows; of each pipeline's FDK alone
(``xr.fdk``, RTK) given the exact line integrals, which separates what the projections add from
what the reconstruction adds; the difference between the two pipelines over the whole volume
(RMSE over the sample's voxels and over all, and each class's mean one voxel inside its
boundaries by our labels).

Writes out/bench_scan.json and docs/bench_scan.png (``--quick``: out/), prints the table.
The reference is cached in out/bench_scan_cache/ (keyed by meshes, geometry, spectrum, slices).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import xrayraster as xr
from references.fdk import fdk_reference
from references.mesh_paths import exact_path_lengths
from scripts import common
from scripts.common import say
from scripts.peers import gvxr_peer, rtk_peer
from xrayraster.pipeline import load_scan_file

CLASSES = {1: "matrix", 2: "weft", 3: "warp"}  # the scan's labels (docs/scan.md)
FULL = {"views": 200, "detector": 256, "pixel_mm": 0.2697, "grid": 256, "voxel_mm": 0.1156}
QUICK = {"views": 36, "detector": 64, "pixel_mm": 4 * 0.2697, "grid": 64, "voxel_mm": 4 * 0.1156}
SLICES_MM = (0.0, 0.4)  # z of the reference slices: the middle weft layer, the binder gap above it


def scan_file_text(views: int, detector: int, pixel_mm: float, grid: int, voxel_mm: float, noise: bool) -> str:
    """The reduced twin's scan file (module docstring)."""
    return f"""\
[weave.sample]
cells = [2, 2]

[weave.materials]
matrix = "matrix"
weft = "weft_carbon"
warp = "warp_carbon"

[materials.weft_carbon]
element = "C"
density = 1.72

[materials.warp_carbon]
element = "C"
density = 1.82

[materials.matrix]
mass_fractions = {{ C = 0.404, H = 0.481, Cl = 0.019, O = 0.096 }}
density = 1.08

[source]
kvp = 40.0
anode = "W"
filters = {{ Al = 2.0 }}
mas = 1.25

[geometry]
beam = "cone"
source_to_origin = 60.0
source_to_detector = 140.0
detector_shape = [{detector}, {detector}]
pixel_size = {pixel_mm!r}
num_views = {views}

[volume]
shape = [{grid}, {grid}, {grid}]
voxel_size = {voxel_mm!r}

[scan]
noise = {'true' if noise else 'false'}
filter = "ram-lak"
"""


# ---------------------------------------------------------------------------------------------
# The two pipelines
# ---------------------------------------------------------------------------------------------


def run_ours(scan_file) -> dict:
    """``xr.scan`` with the projections kept (for their error); stage times as it reports them."""
    t0 = time.perf_counter()
    result = xr.scan(scan_file, keep_projections=True)
    wall = time.perf_counter() - t0
    seconds = dict(result.metadata["seconds"])
    return {"seconds": seconds, "wall_s": wall, "volume": result.volume.data, "labels": result.labels.data,
            "lineint": result.projections.data,
            "triangles": result.metadata["triangles"], "devices": result.metadata["devices"],
            "peak_rss_mib": result.metadata["peak_rss_mib"]}


def peer_parts(loaded) -> list:
    """The weave as a gVirtualXRay user needs it: one disjoint closed mesh per family, centred as the scan places it."""
    weave = loaded.weave
    lo, hi = weave.sample.box
    parts, _ = weave.sample.parts(weave.materials, per="family", resolve="boolean", measure=False)
    shift = -(lo + hi) / 2
    return [dataclasses.replace(p, mesh=p.mesh.copy().apply_translation(shift)) for p in parts]


def run_peer(loaded, max_edge_mm: float) -> dict:
    """Mesh + boolean (+ long edges split) → gVirtualXRay projections → flat-field and −log → RTK FDK (mm⁻¹ → cm⁻¹)."""
    import trimesh

    g, seconds = loaded.geometry, {}
    t0 = time.perf_counter()
    parts = peer_parts(loaded)
    meshes = {p.name: [(np.asarray(p.mesh.vertices), np.asarray(p.mesh.faces)) if max_edge_mm <= 0 else
                       trimesh.remesh.subdivide_to_size(p.mesh.vertices, p.mesh.faces, max_edge=max_edge_mm)]
              for p in parts}
    seconds["sample"] = time.perf_counter() - t0

    materials = {p.name: (list(p.material.mass_fractions), list(p.material.mass_fractions.values()), p.material.density)
                 for p in parts}
    photons = loaded.spectrum.photons_per_pixel(g.source_to_detector, g.pixel_size[0] * g.pixel_size[1])
    t0 = time.perf_counter()
    shots = gvxr_peer.gvxr_scan_images(meshes, materials, loaded.spectrum.energies, photons, g.source_to_origin,
                                       g.source_to_detector, g.detector_shape, g.pixel_size[0], g.angles)
    lineint = -np.log(shots.pop("transmission"))
    seconds["projections"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    rec = rtk_peer.rtk_fdk(lineint, g, loaded.volume, threads=2)
    volume = rec["volume"] * 10.0  # mm⁻¹ → cm⁻¹, as ours
    seconds["fdk"] = time.perf_counter() - t0
    seconds["total"] = sum(seconds.values())
    details = {"gvxr_setup_s": shots["setup_seconds"], "gvxr_views_s": shots["seconds"],
               "gvxr_bins_given": shots["bins_given"], "gvxr_bins_kept": shots["bins_kept"],
               "rtk_update_s": rec["seconds"], "rtk_setup_s": rec["setup_seconds"],
               "triangles": int(sum(len(f) for [(_, f)] in meshes.values())), "max_edge_mm": max_edge_mm}
    return {"seconds": seconds, "details": details, "volume": volume, "lineint": lineint, "parts": parts}


# ---------------------------------------------------------------------------------------------
# The float64 reference
# ---------------------------------------------------------------------------------------------


def self_check() -> float:
    """Largest difference (mm) between ``references.mesh_paths.exact_path_lengths`` and
    ``references.chords.box_chord`` for an off-centre box (its 12 triangles) at three angles, every
    pixel of a 64 × 48 detector (tests/scripts/test_bench_scan_reference.py checks the same)."""
    import trimesh

    from references.chords import box_chord, cone_rays

    centre, half = np.array([1.5, -2.0, 0.7]), np.array([4.0, 2.5, 1.5])
    box = trimesh.creation.box(extents=2 * half)
    box.apply_translation(centre)
    shape, worst = (48, 64), 0.0
    for theta in (0.0, 0.9, 4.0):
        got = exact_path_lengths(np.asarray(box.vertices), np.asarray(box.faces), 60.0, 140.0, 0.3, shape, theta,
                                 (0, shape[0] - 1))
        origins, directions = cone_rays(60.0, 140.0, shape, 0.3, theta)
        worst = max(worst, float(np.abs(got - box_chord(origins, directions, centre, np.eye(3), half)).max()))
    return worst


def attenuation_mm(material, energies_kev) -> np.ndarray:
    """μ (mm⁻¹) from xraylib's total cross sections (coherent included) and the mass fractions."""
    import xraylib

    per_gram = [sum(w * xraylib.CS_Total(int(z), float(e)) for z, w in material.composition) for e in energies_kev]
    return np.asarray(per_gram) * material.density / 10.0


def footprint(volume: xr.VolumeGeometry, box_mm: np.ndarray, z_mm: float) -> xr.VolumeGeometry:
    """The grid's voxels nearest z = ``z_mm`` whose centres lie over the sample's box in x and y."""
    z = volume.axis_centres(0)
    k = int(np.argmin(np.abs(z - z_mm)))
    centres, sizes = [z[k]], [1]
    for axis, dim in ((1, 1), (2, 0)):
        c = volume.axis_centres(axis)
        inside = c[(c >= box_mm[0][dim]) & (c <= box_mm[1][dim])]
        centres.append(float(inside.mean()))
        sizes.append(len(inside))
    return xr.VolumeGeometry(tuple(sizes), volume.voxel_size, tuple(centres))


def band_rows(geometry: xr.ConeBeamGeometry, slices: list[xr.VolumeGeometry]) -> tuple[int, int]:
    """Detector rows that the slices' voxels project onto in any view, one more for bilinear interpolation."""
    nrow = geometry.detector_shape[0]
    rows = []
    for s in slices:
        (z,), (_, hy, hx) = s.axis_centres(0), (np.asarray(s.shape) - 1) / 2 * np.asarray(s.voxel_size)
        reach = np.hypot(hx + abs(s.offset[2]), hy + abs(s.offset[1]))  # farthest voxel from the axis
        for depth in (geometry.source_to_origin - reach, geometry.source_to_origin + reach):
            rows.append(z * geometry.source_to_detector / depth / geometry.pixel_size[0] + (nrow - 1) / 2)
    return max(int(np.floor(min(rows))), 0), min(int(np.floor(max(rows))) + 1, nrow - 1)


def reference(parts, loaded, slices_mm, cache: Path) -> dict:
    """Exact float64 line integrals on the rows the reference slices need, and those slices reconstructed (cm⁻¹)."""
    g, spectrum = loaded.geometry, loaded.spectrum
    slices = list({s.offset: s for s in (footprint(loaded.volume, loaded.box_mm, z) for z in slices_mm)}.values())
    rows = band_rows(g, slices)
    key = hashlib.blake2b(digest_size=12)
    for p in parts:
        key.update(np.ascontiguousarray(p.mesh.vertices, np.float64).data)
        key.update(np.ascontiguousarray(p.mesh.faces, np.int64).data)
        key.update(repr(p.material).encode())
    key.update(repr((g.to_dict(), spectrum.energies.tolist(), spectrum.fluence.tolist(),
                     [s.to_dict() for s in slices], rows)).encode())
    path = cache / f"reference_{key.hexdigest()}.npz"
    if path.exists():
        with np.load(path) as f:
            return {"lineint": f["lineint"], "rows": rows, "slices": slices, "volumes": list(f["volumes"]),
                    "seconds": float(f["seconds"]), "cached": True}

    t0 = time.perf_counter()
    # Only triangles within reach of the band's rays: z between the band's edges scaled to the
    # sample's nearest and farthest depth.
    v = (np.array(rows) - (g.detector_shape[0] - 1) / 2 + np.array([-0.5, 0.5])) * g.pixel_size[0]
    reach = float(np.hypot(*np.abs(loaded.box_mm).max(axis=0)[:2]))
    k = np.array([g.source_to_origin - reach, g.source_to_origin + reach]) / g.source_to_detector
    z_lo, z_hi = min(v[0] * k), max(v[1] * k)
    surfaces = []
    for p in parts:
        vertices, faces = np.asarray(p.mesh.vertices, np.float64), np.asarray(p.mesh.faces)
        z = vertices[faces][..., 2]
        surfaces.append((vertices, faces[(z.max(1) >= z_lo) & (z.min(1) <= z_hi)]))
    keep = spectrum.fluence > 0
    energies, weights = spectrum.energies[keep], spectrum.fluence[keep] * spectrum.energies[keep]  # energy-integrating
    mu = np.stack([attenuation_mm(p.material, energies) for p in parts])  # (materials, bins)
    lineint = np.zeros((g.num_views, *g.detector_shape))
    for view, theta in enumerate(g.angles):
        lengths = np.stack([exact_path_lengths(vs, fs, g.source_to_origin, g.source_to_detector, g.pixel_size[0],
                                               g.detector_shape, theta, rows) for vs, fs in surfaces])
        signal = np.tensordot(weights, np.exp(-np.tensordot(mu.T, lengths, axes=1)), axes=1)
        lineint[view, rows[0]:rows[1] + 1] = -np.log(signal / weights.sum())
    volumes = [10.0 * fdk_reference(lineint, g, s, window="ram-lak")[0] for s in slices]  # mm⁻¹ → cm⁻¹
    seconds = time.perf_counter() - t0
    band = lineint[:, rows[0]:rows[1] + 1]
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, lineint=band, volumes=np.array(volumes), seconds=seconds)
    os.replace(tmp, path)
    return {"lineint": band, "rows": rows, "slices": slices, "volumes": volumes, "seconds": seconds, "cached": False}


def fdk_of_exact(ref: dict, loaded) -> dict:
    """Each pipeline's FDK (``xr.fdk``, RTK) of the exact line integrals on the reference slices (cm⁻¹):
    what the reconstruction alone adds, apart from the projections' error. The rows outside the
    computed band stay 0; the slices' voxels never reach them and both filter along rows only."""
    g = loaded.geometry
    exact = np.zeros((g.num_views, *g.detector_shape), np.float32)
    exact[:, ref["rows"][0]:ref["rows"][1] + 1] = ref["lineint"]
    with xr.CLContext() as cl:
        ours = [xr.fdk(exact, g, s, filter="ram-lak", context=cl).data[0] for s in ref["slices"]]
    peer = [10.0 * rtk_peer.rtk_fdk(exact, g, s, threads=2)["volume"][0] for s in ref["slices"]]
    return {"ours": np.stack(ours), "peer": np.stack(peer)}


# ---------------------------------------------------------------------------------------------
# Comparisons
# ---------------------------------------------------------------------------------------------


def rmse(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def erode(mask: np.ndarray, steps: int) -> np.ndarray:
    """``mask`` shrunk by ``steps`` face-neighbour steps (voxels at the array's border count as outside)."""
    for _ in range(steps):
        inner = np.zeros_like(mask)
        inner[1:-1, 1:-1, 1:-1] = mask[1:-1, 1:-1, 1:-1]
        for axis in range(3):
            inner &= np.roll(mask, 1, axis) & np.roll(mask, -1, axis)
        mask = inner
    return mask


def grid_slice(volume: xr.VolumeGeometry, part: xr.VolumeGeometry) -> tuple[slice, ...]:
    """Index ranges of the sub-grid ``part`` (same lattice) inside ``volume``'s arrays."""
    out = []
    for axis in range(3):
        start = int(np.argmin(np.abs(volume.axis_centres(axis) - part.axis_centres(axis)[0])))
        out.append(slice(start, start + part.shape[axis]))
    return tuple(out)


def mean(values: np.ndarray, mask: np.ndarray) -> float | None:
    return float(values[mask].mean()) if mask.any() else None


def compare(ours: dict, peer: dict, ref: dict, exact_fdk: dict, loaded) -> dict:
    # one voxel in from every boundary: the yarns are 2.8–3.3 voxels thick at the full size, so two would empty them
    cores = {name: erode(ours["labels"] == label, 1) for label, name in CLASSES.items()}
    sample = ours["labels"] > 0
    out = {"volume_difference": {
        "rmse_sample_cm": rmse(ours["volume"][sample], peer["volume"][sample]),
        "rmse_all_cm": rmse(ours["volume"], peer["volume"]),
        "max_abs_cm": float(np.abs(ours["volume"] - peer["volume"]).max()),
        "class_means_cm": {name: {"ours": mean(ours["volume"], m), "peer": mean(peer["volume"], m),
                                  "voxels": int(m.sum())} for name, m in cores.items()}}}
    rows = slice(ref["rows"][0], ref["rows"][1] + 1)
    for key, run in (("ours", ours), ("peer", peer)):
        diff = run["lineint"][:, rows] - ref["lineint"]
        out[f"{key}_lineint"] = {"rmse": float(np.sqrt(np.mean(diff ** 2))), "max_abs": float(np.abs(diff).max())}
    per_slice, stacked = [], {"ours": [], "peer": [], "ref": []}
    for s, ref_volume in zip(ref["slices"], ref["volumes"]):
        index = grid_slice(loaded.volume, s)
        entry = {"z_mm": float(s.offset[0]), "voxels": int(np.prod(s.shape))}
        for key, run in (("ours", ours), ("peer", peer)):
            entry[f"{key}_rmse_cm"] = rmse(run["volume"][index][0], ref_volume)
            stacked[key].append(run["volume"][index][0])
        stacked["ref"].append(ref_volume)
        entry["class_means_cm"] = {
            name: {key: mean(v, m[index][0])
                   for key, v in (("ours", stacked["ours"][-1]), ("peer", stacked["peer"][-1]), ("ref", ref_volume))}
            for name, m in cores.items()}
        per_slice.append(entry)
    out["slices"] = per_slice
    out["ours_rmse_cm"] = rmse(np.stack(stacked["ours"]), np.stack(stacked["ref"]))
    out["peer_rmse_cm"] = rmse(np.stack(stacked["peer"]), np.stack(stacked["ref"]))
    out["ref_sample_mean_cm"] = float(np.mean(np.stack(stacked["ref"])))
    out["fdk_of_exact_rmse_cm"] = {key: rmse(v, np.stack(stacked["ref"])) for key, v in exact_fdk.items()}
    out["images"] = {key: np.stack(v) for key, v in stacked.items()}
    return out


# ---------------------------------------------------------------------------------------------
# Plot, table, run
# ---------------------------------------------------------------------------------------------


def plot(payload: dict, images: dict, path: Path) -> Path | None:
    """Time against error, the stages, and the first reference slice beside each pipeline's difference from it."""
    plt = common.pyplot()
    if plt is None:
        return None
    ours, peer, errors, settings = payload["ours"], payload["peer"], payload["errors"], payload["settings"]
    fig = plt.figure(figsize=(13, 9.5), layout="constrained")
    upper, lower = fig.subfigures(2, 1, height_ratios=(1, 1.15))
    ax, bars = upper.subplots(1, 2)
    for key, label, colour in (("ours", "xrayraster: xr.scan", "C0"), ("peer", "gVirtualXRay + RTK", "C3")):
        t, e = payload[key]["seconds"]["total"], errors[f"{key}_rmse_cm"]
        common.curve(ax, [t], [e], [f"{t:.0f} s, {e:.1e} cm⁻¹"], color=colour, label=label)
    ax.set_yscale("log")
    ax.set_xlim(0, 1.3 * max(ours["seconds"]["total"], peer["seconds"]["total"]))
    ax.set_xlabel("end-to-end time (s)")
    ax.set_ylabel("RMSE vs the float64 reference (cm⁻¹)")
    ax.set_title(f"{settings['views']} views, {settings['detector']}² pixels, {settings['grid']}³ voxels, noise off "
                 "(lower left is better)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    stages = [s for s in dict.fromkeys([*ours["seconds"], *peer["seconds"]]) if s != "total"]
    left = np.zeros(2)
    for k, stage in enumerate(stages):
        widths = np.array([payload[key]["seconds"].get(stage, 0.0) for key in ("ours", "peer")])
        bars.barh(["xr.scan", "gVirtualXRay + RTK"], widths, left=left, color=f"C{k}", label=stage)
        left += widths
    bars.set_xlabel("seconds, stages stacked")
    bars.set_title(f"end to end: peer / ours = {payload['ratio']:.2f}×", fontsize=9)
    bars.legend(fontsize=8)
    ref = images["ref"][0]
    spread = max(float(np.abs(images[k][0] - ref).max()) for k in ("ours", "peer"))
    panels = [("reference (float64 projections + FDK), cm⁻¹", ref, "gray", None),
              ("ours − reference", images["ours"][0] - ref, "RdBu_r", spread),
              ("peer − reference", images["peer"][0] - ref, "RdBu_r", spread),
              ("ours − peer", images["ours"][0] - images["peer"][0], "RdBu_r", spread)]
    for ax, (title, image, cmap, limit) in zip(lower.subplots(1, 4), panels):
        shown = ax.imshow(image, cmap=cmap, origin="lower", vmin=None if limit is None else -limit, vmax=limit)
        ax.set_title(f"{title}\nz = {errors['slices'][0]['z_mm']:+.3f} mm (x right, y up)", fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
        lower.colorbar(shown, ax=ax, shrink=0.6, location="bottom")
    return common.save(fig, path)


def table(payload: dict) -> None:
    ours, peer, errors = payload["ours"], payload["peer"], payload["errors"]
    stages = [s for s in dict.fromkeys([*ours["seconds"], *peer["seconds"]]) if s != "total"]
    say(f"\n{'stage':<14}{'ours s':>10}{'peer s':>10}")
    for stage in stages:
        a, b = ours["seconds"].get(stage), peer["seconds"].get(stage)
        say(f"{stage:<14}{'—' if a is None else f'{a:.2f}':>10}{'—' if b is None else f'{b:.2f}':>10}")
    say(f"{'end to end':<14}{ours['seconds']['total']:>10.2f}{peer['seconds']['total']:>10.2f}   "
        f"ratio peer / ours {payload['ratio']:.2f}× ({payload['ratio_without_labels']:.2f}× without our labels stage)")
    say(f"{'':<14}RMSE vs float64 reference over {sum(s['voxels'] for s in errors['slices']):,} voxels "
        f"(reference mean {errors['ref_sample_mean_cm']:.4f} cm⁻¹): "
        f"ours {errors['ours_rmse_cm']:.2e}, peer {errors['peer_rmse_cm']:.2e} cm⁻¹")
    for s in errors["slices"]:
        say(f"{'':<14}  z = {s['z_mm']:+.3f} mm: ours {s['ours_rmse_cm']:.2e}, peer {s['peer_rmse_cm']:.2e} cm⁻¹; "
            + "; ".join(f"{n} ours/peer/ref " + "/".join("—" if v is None else f"{v:.4f}" for v in m.values())
                        for n, m in s["class_means_cm"].items()))
    say(f"{'':<14}line integrals vs exact (rows {payload['reference']['rows'][0]}–{payload['reference']['rows'][1]}): "
        f"ours RMSE {errors['ours_lineint']['rmse']:.2e} max {errors['ours_lineint']['max_abs']:.2e}; "
        f"peer RMSE {errors['peer_lineint']['rmse']:.2e} max {errors['peer_lineint']['max_abs']:.2e}")
    say(f"{'':<14}FDK alone, of the exact line integrals, vs the reference: xr.fdk {errors['fdk_of_exact_rmse_cm']['ours']:.2e}, "
        f"RTK {errors['fdk_of_exact_rmse_cm']['peer']:.2e} cm⁻¹")
    d = errors["volume_difference"]
    say(f"{'':<14}ours − peer: RMSE {d['rmse_sample_cm']:.5f} cm⁻¹ over the sample's voxels, {d['rmse_all_cm']:.5f} over "
        f"all, max |diff| {d['max_abs_cm']:.4f}; class means one voxel inside (ours / peer cm⁻¹): "
        + ", ".join(f"{n} {m['ours']:.4f} / {m['peer']:.4f}" for n, m in d["class_means_cm"].items() if m["voxels"]))
    target = payload["target"]
    say(f"target (≥ 6× end to end, error ≤ peer's): {target['ratio']:.2f}×, RMSE "
        f"{'≤' if target['error_ok'] else '>'} peer → {'MET' if target['met'] else 'not met'}")


def main(argv=None) -> int:
    ap = common.parser(__doc__, "36 views, 64² detector, 64³ grid: a smoke test", plots=True)
    ap.add_argument("--views", type=int, help=f"views of the scan (default {FULL['views']}; the twin has 400)")
    ap.add_argument("--slices", type=float, nargs="+", default=list(SLICES_MM),
                    help="z (mm) of the reference slices, nearest voxel centres (default 0 0.4)")
    ap.add_argument("--peer-max-edge", type=float, default=2.0,
                    help="mm: split the peer's mesh edges longer than this before gVirtualXRay (0: no split; default 2)")
    ap.add_argument("--noise-run", action="store_true", help="also time xr.scan with photon noise on")
    ap.add_argument("--self-check", action="store_true", help="only check the float64 path lengths against box chords")
    args = common.outputs(ap.parse_args(argv), "bench_scan")
    if args.self_check:
        worst = self_check()
        say(f"exact_path_lengths vs references.chords.box_chord: max |diff| {worst:.2e} mm")
        return 0 if worst < 1e-9 else 1
    sizes = dict(QUICK if args.quick else FULL)
    sizes["views"] = args.views or sizes["views"]

    t_start = time.perf_counter()
    command, machine = common.announce()
    reasons = {"gvxr": gvxr_peer.gvxr_available, "rtk": rtk_peer.rtk_available}
    for name, check in reasons.items():  # library start-up, timed apart from the pipelines
        t0 = time.perf_counter()
        reasons[name] = check()
        machine[f"{name}_startup_s"] = time.perf_counter() - t0
        if reasons[name]:
            raise SystemExit(f"{name} unavailable: {reasons[name]} (pip install '.[bench]')")
    say(f"library start-up (not in the end-to-end times): gvxr {machine['gvxr_startup_s']:.1f} s, "
        f"RTK {machine['rtk_startup_s']:.1f} s")

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin_reduced.toml"
        path.write_text(scan_file_text(**sizes, noise=False))
        loaded = load_scan_file(path)
        noisy = None
        if args.noise_run:
            (Path(tmp) / "noisy.toml").write_text(scan_file_text(**sizes, noise=True))
            noisy = load_scan_file(Path(tmp) / "noisy.toml")
    say(f"scan: {sizes['views']} views, {sizes['detector']}² pixels of {sizes['pixel_mm']:.4g} mm, "
        f"{sizes['grid']}³ voxels of {sizes['voxel_mm']:.4g} mm; mesh {loaded.mesh_resolution['points_per_section']} "
        f"points per section, {loaded.mesh_resolution['samples_per_mm']:.2f} per mm; "
        f"{loaded.spectrum.n_bins} spectrum bins")

    say("ours: xr.scan ...")
    ours = run_ours(loaded)
    say(f"  {ours['seconds']} ({ours['triangles']:,} triangles; GL {ours['devices']['gl_renderer']}, "
        f"OpenCL {ours['devices']['opencl_device']})")
    if noisy is not None:
        ours_noisy = run_ours(noisy)
        say(f"  with photon noise: {ours_noisy['seconds']}")
    say("peer: boolean → gVirtualXRay → −log → RTK FDK ...")
    peer = run_peer(loaded, args.peer_max_edge)
    say(f"  { {k: round(v, 3) for k, v in peer['seconds'].items()} } ({peer['details']['triangles']:,} triangles; "
        f"gvxr kept {peer['details']['gvxr_bins_kept']} of {peer['details']['gvxr_bins_given']} bins)")
    say("reference: float64 path lengths, line integrals, FDK slices ...")
    ref = reference(peer.pop("parts"), loaded, args.slices, common.OUT / "bench_scan_cache")
    say(f"  rows {ref['rows'][0]}–{ref['rows'][1]}, {len(ref['slices'])} slices, "
        f"{ref['seconds']:.1f} s{' (cached)' if ref['cached'] else ''}")
    errors = compare(ours, peer, ref, fdk_of_exact(ref, loaded), loaded)
    images = errors.pop("images")

    without_labels = ours["seconds"]["total"] - ours["seconds"].get("labels", 0.0)
    ratio = peer["seconds"]["total"] / ours["seconds"]["total"]
    error_ok = errors["ours_rmse_cm"] <= errors["peer_rmse_cm"]
    payload = {
        "command": command, "machine": machine, "date": time.strftime("%Y-%m-%d"),
        "settings": {**sizes, "cells": [2, 2], "mesh_resolution": loaded.mesh_resolution,
                     "geometry": {"source_to_origin_mm": 60.0, "source_to_detector_mm": 140.0},
                     "spectrum": loaded.spectrum.description, "spectrum_bins": loaded.spectrum.n_bins,
                     "slices_mm": args.slices, "noise": False},
        "ours": {k: ours[k] for k in ("seconds", "wall_s", "triangles", "devices", "peak_rss_mib")},
        "peer": {k: peer[k] for k in ("seconds", "details")},
        "reference": {"rows": list(ref["rows"]), "slices": [s.to_dict() for s in ref["slices"]],
                      "seconds": ref["seconds"], "cached": ref["cached"]},
        "errors": errors, "ratio": ratio, "ratio_without_labels": peer["seconds"]["total"] / without_labels,
        "target": {"ratio": ratio, "error_ok": error_ok, "met": ratio >= 6.0 and error_ok},
    }
    if noisy is not None:
        payload["ours_noise"] = {k: ours_noisy[k] for k in ("seconds", "wall_s")}
    table(payload)
    png = plot(payload, images, args.plots_dir / f"bench_scan{'_quick' if args.quick else ''}.png")
    if png:
        say(f"plot: {png}")
    common.conclude(args.json, payload, machine, t_start, top_level_load=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
