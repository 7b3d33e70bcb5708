"""Voxelizer benchmark: ``xr.voxelize`` beside VTK's stencil voxelizer, same scene, same grid.

The scene (mm, scanner frame; three overlapping convex objects, 1.31 M triangles)
------------------------------------------------------------------------------
* "matrix": a 20 × 17 × 14 mm box, tilted (5° about x, then 8° about z) and shifted off the
  grid centre; label 1, priority 0 (12 triangles);
* "sphere": a radius-6 mm icosphere with 8 subdivisions (1,310,720 triangles) off-centre,
  poking out through the matrix's +z face; label 2, priority 1;
* "rod": a 14 × 2.5 × 3.5 mm box turned 25°/40°/60° about x/y/z, crossing the sphere's
  surface and the matrix's; label 3, priority 2 (12 triangles).
Every object lies inside the field of view. ``--quick`` uses a 3-subdivision sphere (1,280
triangles).

Grids: n³ voxels for n = 256 and 512 (``--quick``: 64), one field of view 25.6 mm wide
whatever n (voxel 25.6/n mm), centred on the scanner origin.

What is timed
-------------
* ours: ``xr.voxelize(scene, volume, context=ctx)`` with one ``xr.GLContext`` made at start.
  The first call for each size is timed and reported on its own (at the first size it compiles
  the shaders; at every size it uploads the scene and sizes the crossing lists); then the best
  of 2 calls (256³, 64³) or 1 call (512³).
* ours, ``method="stencil"``: the classic slice-by-slice stencil counting in the same GL
  pipeline (xrayraster/gl/voxelize_stencil.py), one call per size, for comparison.
* VTK: ``scripts/peers/vtk_peer.py``'s ``vtk_voxelize``: one ``vtkPolyDataToImageStencil`` +
  ``vtkImageStencilToImage`` per object on the same grid (VTK's default tolerance), numpy
  views, and the priority painting of the masks. The time compared is the end-to-end label
  volume (``total_seconds``: VTK work + painting), best of the same number of calls as ours.
  VTK's stencil is single-threaded; ours runs on Mesa llvmpipe's threads.

Errors (independent reference)
------------------------------
10⁵ voxel centres drawn at random (seeded per size, with replacement). Every object is a
convex polyhedron, so a point p is inside it exactly when max_f (n_f·p − h_f) < 0 over its
face planes (outward unit normals n_f, offsets h_f, float64 from the placed mesh's very
vertices). For an inside point −max is its distance to the surface; for an outside point max
is a lower bound of the distance. Points within 10⁻³ voxel of any object's surface by that
measure are left out (conservatively: a few farther outside points may be left out too), and
the rest get the label of the highest (priority, insertion order) object containing them.
Cheap bounds skip the plane test away from a surface: p is inside if |p − c| < r_in − ε (c the
vertex mean, r_in the smallest plane distance from c) and outside if |p − c| > r_out + ε
(r_out the largest vertex distance), so only points in the sphere's 2.7e-5 mm thin shell meet
its 1.3 M planes (none of the 10⁵ do at 256³ or 512³; the plane test is exercised by the
boxes and, with ``--quick``, by the coarse sphere). The inside tests of meshes of ≤ 100 k triangles are also cross-checked
against trimesh's signed distance on the first 2·10⁴ points (both boxes always; the sphere
only with ``--quick``: trimesh would take minutes on 1.3 M triangles).
Reported: disagreement counts of ours and of VTK with the reference, and the number of voxels
(whole volume) where ours and VTK differ.

Usage::

    python -m scripts.bench_voxelize           # 256³ and 512³ (~2 min on 2 cores, most of it VTK)
    python -m scripts.bench_voxelize --quick   # 64³ smoke test with a small mesh

Prints a table, writes out/bench_voxelize.json (``--quick``: out/bench_voxelize_quick.json) and
plots docs/bench_voxelize.png (``--quick``: out/bench_voxelize_quick.png).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

import xrayraster as xr
from scripts import common
from scripts.common import say
from scripts.peers import vtk_peer
from scripts.weave_scene import face_planes

FOV_MM = 25.6
REPEATS = {64: 2, 256: 2, 512: 1}  # timed calls after the first (ours) / calls (VTK); best taken
POINTS = 100_000
MIN_DISTANCE = 1e-3  # voxels: reference points closer than this to a surface are left out
CROSS_CHECK_MAX_TRIANGLES = 100_000  # trimesh signed-distance cross-check of the reference: meshes up to this size,
CROSS_CHECK_POINTS = 20_000  # on this many of the points (trimesh takes ~3 s per 20 k points on 1,280 triangles)


def rotation_deg(ax: float, ay: float, az: float) -> xr.Transform:
    """Rotation about x, then y, then z (degrees)."""
    r = xr.Transform.rotation
    return r((0, 0, 1), math.radians(az)) @ r((0, 1, 0), math.radians(ay)) @ r((1, 0, 0), math.radians(ax))


# ---------------------------------------------------------------------------------------------
# Scene and reference
# ---------------------------------------------------------------------------------------------


@dataclass
class ConvexSolid:
    """A placed convex mesh as the reference sees it: face planes (inside n·x ≤ h), mm."""

    name: str
    label: int
    rank: tuple[float, int]  # (priority, insertion order): higher owns the overlap
    triangles: int
    normals: np.ndarray
    offsets: np.ndarray
    centre: np.ndarray  # the vertex mean: inside a convex polyhedron
    r_in: float  # radius of the largest ball about centre inside every plane
    r_out: float  # radius of the smallest ball about centre holding every vertex
    mesh: trimesh.Trimesh

    @classmethod
    def of(cls, obj: xr.SceneObject) -> "ConvexSolid":
        v, f = obj.mesh.vertices, obj.mesh.faces
        normals, offsets = face_planes(v, f)  # coplanar faces merged: a box is 6 planes
        centre = v.mean(axis=0)
        depth = offsets - normals @ centre
        if depth.min() <= 0:
            raise ValueError(f"{obj.name}: the vertex mean is not strictly inside every face plane (not convex?)")
        return cls(obj.name, obj.label, obj.rank, len(f), normals, offsets, centre, float(depth.min()),
                   float(np.linalg.norm(v - centre, axis=1).max()), trimesh.Trimesh(v, f, process=False))

    def classify(self, points: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
        """(inside, far): exact inside test of (m, 3) points; far = farther than eps mm from the
        surface (exactly for inside points, by a lower bound for outside ones)."""
        rho = np.linalg.norm(points - self.centre, axis=1)
        surely_in = rho < self.r_in - eps  # then every plane is farther than eps
        surely_out = rho > self.r_out + eps  # then the whole polyhedron is farther than eps
        inside, far = surely_in.copy(), surely_in | surely_out
        rest = np.flatnonzero(~far)
        step = max(1, 8_000_000 // len(self.normals))  # bound the (points × planes) temporaries
        for s in range(0, len(rest), step):
            idx = rest[s : s + step]
            top = (points[idx] @ self.normals.T - self.offsets).max(axis=1)
            inside[idx] = top < 0
            far[idx] = np.abs(top) > eps
        return inside, far


def build_scene(quick: bool) -> tuple[xr.Scene, float]:
    """The three-object scene (see the module docstring) and the build time, s."""
    t0 = time.perf_counter()
    scene = xr.Scene()
    scene.add(trimesh.creation.box((20.0, 17.0, 14.0)), "matrix", label=1, priority=0, name="matrix",
              transform=xr.Transform.translation((0.3, -0.2, 0.1)) @ rotation_deg(5, 0, 8))
    scene.add(trimesh.creation.icosphere(subdivisions=3 if quick else 8, radius=6.0), "sphere", label=2, priority=1,
              name="sphere", transform=xr.Transform.translation((0.7, -0.4, 2.5)))
    scene.add(trimesh.creation.box((14.0, 2.5, 3.5)), "rod", label=3, priority=2, name="rod",
              transform=xr.Transform.translation((1.5, 1.0, -1.0)) @ rotation_deg(25, 40, 60))
    lo, hi = scene.bounds
    assert np.all(np.abs(lo) < FOV_MM / 2) and np.all(np.abs(hi) < FOV_MM / 2), "scene leaves the field of view"
    return scene, time.perf_counter() - t0


def volume(n: int) -> xr.VolumeGeometry:
    return xr.VolumeGeometry((n, n, n), FOV_MM / n)


def random_voxels(vol: xr.VolumeGeometry, count: int, seed: int = 2024) -> tuple[np.ndarray, np.ndarray]:
    """(count, 3) voxel indices (k, j, i) and their centres (x, y, z) mm, seeded per grid size."""
    rng = np.random.default_rng([seed, *vol.shape])
    idx = np.stack([rng.integers(0, n, count) for n in vol.shape], axis=1)
    centres = np.stack([vol.axis_centres(2)[idx[:, 2]], vol.axis_centres(1)[idx[:, 1]],
                        vol.axis_centres(0)[idx[:, 0]]], axis=1)
    return idx, centres


def reference_labels(solids: list[ConvexSolid], points: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray, dict]:
    """Labels by the priority rule over exact convex inside tests; far mask; cross-check info."""
    label = np.zeros(len(points), np.int64)
    far = np.ones(len(points), bool)
    checks = {}
    for solid in sorted(solids, key=lambda s: s.rank):  # lowest (priority, order) first: later ones overwrite
        inside, far_here = solid.classify(points, eps)
        far &= far_here
        label[inside] = solid.label
        if solid.triangles <= CROSS_CHECK_MAX_TRIANGLES:
            m = CROSS_CHECK_POINTS
            d = trimesh.proximity.signed_distance(solid.mesh, points[:m])  # positive inside
            sure = far_here[:m] & (np.abs(d) > eps)
            checks[solid.name] = {"points": int(sure.sum()), "disagree": int(np.count_nonzero((d[sure] > 0) != inside[:m][sure]))}
    return label, far, checks


# ---------------------------------------------------------------------------------------------
# One grid size
# ---------------------------------------------------------------------------------------------


def run_case(n: int, scene: xr.Scene, solids: list[ConvexSolid], ctx: xr.GLContext, with_vtk: bool) -> dict:
    vol = volume(n)
    voxel = FOV_MM / n
    repeats = REPEATS[n]
    say(f"\n== {n}³ voxels of {voxel:.4g} mm ==")
    rec = {"size": n, "voxel_mm": voxel, "voxels": n**3, "repeats": repeats}

    t0 = time.perf_counter()
    ours = xr.voxelize(scene, vol, context=ctx).data
    rec["ours_first_call_s"] = time.perf_counter() - t0
    del ours  # free each output before the next call: at 512³ it is 128 MiB
    times, ours = common.repeat(lambda: xr.voxelize(scene, vol, context=ctx).data, repeats, free_previous=True)
    rec["ours_s"], rec["ours_all_s"] = min(times), times
    say(f"  ours: {rec['ours_s']:.3f} s (best of {repeats}; first call {rec['ours_first_call_s']:.3f} s), "
        f"{n**3 / rec['ours_s'] / 1e6:.1f} M voxels/s")

    t0 = time.perf_counter()
    idx, points = random_voxels(vol, POINTS)
    ref, far, checks = reference_labels(solids, points, MIN_DISTANCE * voxel)
    rec["reference_s"] = time.perf_counter() - t0
    rec["points"], rec["points_far"] = POINTS, int(far.sum())
    rec["reference_cross_check"] = checks
    k, j, i = idx[far].T
    rec["ours_disagree"] = int(np.count_nonzero(ours[k, j, i] != ref[far]))
    say(f"  reference: {rec['points_far']:,} of {POINTS:,} random voxel centres farther than {MIN_DISTANCE:g} voxel "
        f"from every surface ({rec['reference_s']:.2f} s); labels {np.bincount(ref[far], minlength=4).tolist()} "
        f"(background, matrix, sphere, rod)")
    if checks:
        say("  reference inside tests cross-checked against trimesh's signed distance (points far by both): "
            + ", ".join(f"{name} {c['disagree']} of {c['points']:,} disagree" for name, c in checks.items()))
    say(f"  ours: {rec['ours_disagree']} disagreeing with the reference")

    # The classic stencil method (method="stencil"), the method, in our pipeline: once.
    t0 = time.perf_counter()
    stencil = xr.voxelize(scene, vol, method="stencil", context=ctx).data
    rec["stencil_s"] = time.perf_counter() - t0
    rec["stencil_disagree"] = int(np.count_nonzero(stencil[k, j, i] != ref[far]))
    rec["stencil_vs_ours_voxels"] = int(np.count_nonzero(stencil != ours))
    say(f"  ours, method='stencil' (slice by slice): {rec['stencil_s']:.3f} s (1 call), {rec['stencil_disagree']} "
        f"disagreeing with the reference; {rec['stencil_vs_ours_voxels']:,} voxels differ from method='exact'")
    del stencil

    if with_vtk:
        runs = []
        for _ in range(repeats):
            runs.append(vtk_peer.vtk_voxelize(scene, vol))
            theirs = runs[-1].pop("labels")  # keep only the latest volume
        best = min(runs, key=lambda r: r["total_seconds"])
        rec["vtk_s"] = best["total_seconds"]
        rec["vtk_all_s"] = [r["total_seconds"] for r in runs]
        rec["vtk_stencil_s"] = best["seconds"]
        rec["vtk_per_object_s"] = dict(zip((o.name for o in scene.objects), best["per_object_seconds"]))
        rec["vtk_combine_s"] = best["combine_seconds"]
        rec["vtk_tolerance_voxels"] = best["tolerance"]
        rec["vtk_disagree"] = int(np.count_nonzero(theirs[k, j, i] != ref[far]))
        rec["ours_vs_vtk_voxels"] = int(np.count_nonzero(ours != theirs))
        rec["ratio"] = rec["vtk_s"] / rec["ours_s"]
        say(f"  VTK:  {rec['vtk_s']:.3f} s (best of {repeats}; stencils "
            + ", ".join(f"{name} {s:.3f}" for name, s in rec["vtk_per_object_s"].items())
            + f" s, priority painting {rec['vtk_combine_s']:.3f} s), {n**3 / rec['vtk_s'] / 1e6:.1f} M voxels/s; "
            f"{rec['vtk_disagree']} disagreeing with the reference")
        say(f"  ours vs VTK: {rec['ours_vs_vtk_voxels']:,} of {n**3:,} voxels differ; ratio VTK / ours {rec['ratio']:.2f}×")
        del theirs, runs
    del ours
    return rec


# ---------------------------------------------------------------------------------------------
# Plot, main
# ---------------------------------------------------------------------------------------------


def plot(records: list[dict], path: Path, title: str) -> Path | None:
    plt = common.pyplot()
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(6.5, 4.8))
    series = (("ours", "xrayraster (OpenGL, llvmpipe)", "C0", "o", -14),
              ("stencil", "xrayraster method='stencil' (classic, per slice)", "C2", "D", 8),
              ("vtk", "VTK vtkPolyDataToImageStencil", "C3", "s", 8))
    for key, label, colour, marker, dy in series:
        rs = [r for r in records if f"{key}_s" in r]
        if not rs:
            continue
        common.curve(ax, [r["size"] for r in rs], [r[f"{key}_s"] for r in rs],
                     [f"{r[f'{key}_disagree']} / {r['points_far']:,} disagree" for r in rs],
                     color=colour, marker=marker, label=label, offset=(6, dy))
    first = [r for r in records if "ours_first_call_s" in r]
    ax.plot([r["size"] for r in first], [r["ours_first_call_s"] for r in first], ls=":", marker="o", mfc="none",
            color="C0", alpha=0.6, label="xrayraster, first call per size")
    common.log_axes(ax, f"label volume (voxels; field of view {FOV_MM} mm)", "time (s), best of runs", title,
                    xbase=2, legend=None)
    sizes = [r["size"] for r in records]
    ax.set_xticks(sizes, [f"{n}³" for n in sizes])
    ax.minorticks_off()
    if len(sizes) == 1:
        ax.set_xlim(sizes[0] / 1.6, sizes[0] * 1.6)
    ax.legend(fontsize=8, loc="upper left")
    fig.text(0.01, 0.01, "labels: disagreements with the exact reference at random voxel centres "
             f"> {MIN_DISTANCE:g} voxel from every surface", fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return common.save(fig, path)


def main(argv=None) -> int:
    ap = common.parser(__doc__, "64³ with a 1,280-triangle sphere: a smoke test")
    ap.add_argument("--sizes", type=int, nargs="+", choices=[256, 512], default=[256, 512])
    ap.add_argument("--no-vtk", action="store_true", help="do not run VTK")
    ap.add_argument("--plot", type=Path, default=None, help="PNG (default docs/bench_voxelize.png; --quick: "
                    "out/bench_voxelize_quick.png)")
    args = common.outputs(ap.parse_args(argv), "bench_voxelize")
    sizes = [64] if args.quick else sorted(args.sizes)
    args.plot = args.plot or (common.OUT / "bench_voxelize_quick.png" if args.quick else common.DOCS / "bench_voxelize.png")

    start = time.perf_counter()
    command = common.command_line()
    reason = "disabled (--no-vtk)" if args.no_vtk else vtk_peer.vtk_available()
    ctx = xr.GLContext()
    machine = common.machine_info(gl=ctx)
    common.print_machine(machine, command)
    say(f"VTK: {reason or vtk_peer.vtk_version()}")

    scene, build_s = build_scene(args.quick)
    solids = [ConvexSolid.of(o) for o in scene.objects]
    objects = [{"name": o.name, "label": o.label, "priority": o.priority, "triangles": len(o.mesh.faces)}
               for o in scene.objects]
    say(f"scene: {scene.num_triangles:,} triangles ("
        + ", ".join(f"{d['name']} {d['triangles']:,}, label {d['label']}, priority {d['priority']:g}" for d in objects)
        + f"), built in {build_s:.1f} s; field of view {FOV_MM} mm; sizes {', '.join(f'{n}³' for n in sizes)}")
    payload = {"command": command, "machine": machine,
               "settings": {"fov_mm": FOV_MM, "repeats": {n: REPEATS[n] for n in sizes}, "points": POINTS,
                            "min_distance_voxels": MIN_DISTANCE, "quick": args.quick},
               "scene": {"triangles": scene.num_triangles, "objects": objects, "build_s": build_s},
               "vtk": {"available": reason is None, "reason": reason}, "records": []}
    records = payload["records"]
    for n in sizes:
        records.append(run_case(n, scene, solids, ctx, reason is None))
        common.write_json(args.json, payload)  # after every size: a cut-short run keeps its data

    say("\n  size │ ours s   first s  M vox/s  disagree │ stencil s disagree │ VTK s     M vox/s  disagree │ VTK/ours  "
        "ours≠VTK voxels   (disagree: of the far reference points)")
    for r in records:
        vtk = (f"{r['vtk_s']:>8.3f} {r['voxels'] / r['vtk_s'] / 1e6:>8.1f} {r['vtk_disagree']:>9} │ {r['ratio']:>7.2f}×  "
               f"{r['ours_vs_vtk_voxels']:>10,}" if "vtk_s" in r else f"{'—':>8} {'':>8} {'':>9} │ {'—':>8}")
        say(f"  {r['size']:>3}³ │ {r['ours_s']:>7.3f} {r['ours_first_call_s']:>8.3f} {r['voxels'] / r['ours_s'] / 1e6:>8.1f} "
            f"{r['ours_disagree']:>9} │ {r['stencil_s']:>9.3f} {r['stencil_disagree']:>8} │ {vtk}   of {r['points_far']:,}")
    png = plot(records, args.plot, f"label voxelization, {scene.num_triangles:,} triangles in 3 overlapping objects")
    line = common.finish(machine)
    payload["total_s"] = time.perf_counter() - start
    common.write_json(args.json, payload)
    say(f"{line}; results {args.json}"
        + (f"; plot {png}" if png else "") + f"; total {payload['total_s']:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
