"""Path-length accuracy figures quoted in docs/accuracy.md, measured against float64 references.

    python -m scripts.accuracy_render            # ~10 s on 2 cores
    python -m scripts.accuracy_render --quick    # smoke test: fewer poses, distances and levels

Prints time and error together and writes every number to out/accuracy_render.json
(``--quick``: out/accuracy_render_quick.json).

1. A 10 mm cube at random poses, 512² detector, source 50 mm to 10 m from the axis: |L - L_exact|
   (slab method in float64) at the mean, 99.9th percentile and maximum over all pixels.
2. 1000 random scanner poses around the same cube (48² detector): error percentiles, and for the
   worst pixels the chord's lateral gradient |∇L| (mm per mm), which explains them.
3. Tessellation: interior chord error of icospheres and n-gon prisms against the smooth shapes,
   and the ratio per refinement step that theory predicts (4).
"""

from __future__ import annotations

import time

import numpy as np
import trimesh

import xrayraster as xr
from references.chords import box_chord, cone_rays, cylinder_chord, random_rotation, sphere_chord
from scripts import common
from scripts.common import say


def cube_scene(rot, centre):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, centre
    scene = xr.Scene()
    scene.add(trimesh.creation.box((10.0, 10.0, 10.0)), "c", transform=xr.Transform(m))
    return scene


def cube_over_distances(gl, distances, poses: int) -> list[dict]:
    say(f"1. 10 mm cube, 512², {poses} random poses per distance (errors in mm; time: the second call per pose, best)")
    say(f"{'SOD mm':>8} {'mean':>9} {'p99.9':>9} {'max':>9} {'ms/view':>8}")
    n, rows = 512, []
    for sod in distances:
        rng = np.random.default_rng(int(sod))
        pixel, errors, times = 2 * 22.0 / n, [], []
        for _ in range(poses):
            rot, centre, theta = random_rotation(rng), rng.uniform(-1.5, 1.5, 3), rng.uniform(0, 2 * np.pi)
            geom = xr.ConeBeamGeometry(sod, 2 * sod, (n, n), pixel, [theta])
            scene = cube_scene(rot, centre)
            with xr.Renderer(geom, context=gl) as r:
                r.path_lengths(scene)
                t0 = time.perf_counter()
                got = r.path_lengths(scene)[0]
                times.append(time.perf_counter() - t0)
            exact = box_chord(*cone_rays(sod, 2 * sod, (n, n), pixel, theta), centre, rot, (5, 5, 5))
            errors.append(np.abs(got - exact).ravel())
        e = np.concatenate(errors)
        rows.append({"sod_mm": sod, "poses": poses, "mean_mm": float(e.mean()), "p99.9_mm": float(np.percentile(e, 99.9)),
                     "max_mm": float(e.max()), "best_s_per_view": min(times)})
        say(f"{sod:8.0f} {e.mean():9.2e} {np.percentile(e, 99.9):9.2e} {e.max():9.2e} {1e3 * min(times):8.1f}")
    return rows


def random_poses(gl, poses: int) -> dict:
    say(f"\n2. {poses} random poses, 48² cone beam (SOD 60 mm), 10 mm cube")
    rng = np.random.default_rng(2024)
    base = xr.ConeBeamGeometry(60.0, 120.0, (48, 48), 0.6, [0.0]).to_vec().array[0]
    vectors = [np.concatenate([q @ base[k : k + 3] for k in (0, 3, 6, 9)]) for q in (random_rotation(rng) for _ in range(poses))]
    geom = xr.VectorGeometry("cone", (48, 48), vectors)
    scene = xr.Scene()
    scene.add(trimesh.creation.box((10.0, 10.0, 10.0)), "c")
    errors, gradients, times = [], [], []
    rr, cc = np.mgrid[0:48, 0:48] - 23.5
    with xr.Renderer(geom, context=gl) as r:
        for k, vec in enumerate(vectors):
            s, d, u, w = np.split(np.asarray(vec), 4)
            dirs = d + rr[..., None] * w + cc[..., None] * u - s
            dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
            origins = np.broadcast_to(s, dirs.shape)
            exact = box_chord(origins, dirs, np.zeros(3), np.eye(3), (5, 5, 5))
            t0 = time.perf_counter()
            got = r.path_lengths(scene, k)[0]
            times.append(time.perf_counter() - t0)
            errors.append(np.abs(got - exact).ravel())
            # Lateral sensitivity of the chord: shift the ray by 1e-6 mm along u and v.
            h = 1e-6
            shifted = [box_chord(origins + h * a / np.linalg.norm(a), dirs, np.zeros(3), np.eye(3), (5, 5, 5)) for a in (u, w)]
            gradients.append((np.hypot(shifted[0] - exact, shifted[1] - exact) / h).ravel())
    e, g = np.concatenate(errors), np.concatenate(gradients)
    out = {"poses": poses, "pixels": int(e.size), "mean_mm": float(e.mean()), "p99.9_mm": float(np.percentile(e, 99.9)),
           "p99.99_mm": float(np.percentile(e, 99.99)), "max_mm": float(e.max()), "median_s_per_view": float(np.median(times))}
    say(f"   pixels {e.size}: mean {e.mean():.2e}, p99.9 {np.percentile(e, 99.9):.2e}, "
        f"p99.99 {np.percentile(e, 99.99):.2e}, max {e.max():.2e} mm; {1e3 * out['median_s_per_view']:.1f} ms/view (median, "
        f"first call included)")
    worst = np.argsort(e)[-5:]
    say("   worst pixels: error mm / |∇L| mm per mm / error ÷ |∇L| (the ray offset it corresponds to, mm)")
    out["worst"] = []
    for i in worst[::-1]:
        out["worst"].append({"error_mm": float(e[i]), "gradient": float(g[i])})
        say(f"     {e[i]:.2e} / {g[i]:8.1f} / {e[i] / max(g[i], 1e-30):.1e}")
    return out


def tessellation(gl, steps: int) -> list[dict]:
    say("\n3. Tessellation (interior chord error vs the smooth shape, mm; theory: ÷4 per step; time: the second call, ms)")
    n, pixel, sod, sdd = 128, 0.25, 100.0, 200.0
    geom = xr.ConeBeamGeometry(sod, sdd, (n, n), pixel, [0.3])
    origins, dirs = cone_rays(sod, sdd, (n, n), pixel, 0.3)
    sphere = sphere_chord(origins, dirs, np.zeros(3), 10.0)
    cylinder = cylinder_chord(origins, dirs, 8.0, 6.0)
    cases = [
        ("icosphere r=10, subdivisions", (2, 3, 4, 5), lambda s: trimesh.creation.icosphere(subdivisions=s, radius=10.0),
         sphere, sphere > 2 * 10.0 * np.sqrt(1 - 0.8**2)),
        ("prism r=8 h=12, sections", (16, 32, 64, 128), lambda s: trimesh.creation.cylinder(radius=8.0, height=12.0, sections=s),
         cylinder, cylinder > 0.9 * 2 * 8.0 * np.sqrt(1 - 0.6**2)),
    ]
    rows = []
    with xr.Renderer(geom, context=gl) as r:
        for label, levels, make, exact, interior in cases:
            levels = levels[:steps]
            errs, times = [], []
            for level in levels:
                scene = xr.Scene()
                scene.add(make(level), "m")
                r.path_lengths(scene)  # upload
                t0 = time.perf_counter()
                got = r.path_lengths(scene)[0]
                times.append(time.perf_counter() - t0)
                errs.append(float(np.abs(got - exact)[interior].mean()))
            ratios = [f"{a / b:.2f}" for a, b in zip(errs, errs[1:])]
            rows.append({"shape": label, "levels": list(levels), "mean_interior_error_mm": errs, "s_per_view": times})
            say(f"   {label} {levels}: errors {', '.join(f'{x:.2e}' for x in errs)}; ratios {', '.join(ratios)}; "
                f"ms/view {', '.join(f'{1e3 * t:.1f}' for t in times)}")
    return rows


def main(argv=None) -> int:
    ap = common.parser(__doc__, "2 distances × 2 poses, 100 random poses, 3 tessellation levels: a smoke test")
    args = common.outputs(ap.parse_args(argv), "accuracy_render")
    distances, poses, many, steps = ((50.0, 10000.0), 2, 100, 3) if args.quick else ((50.0, 300.0, 2000.0, 10000.0), 6, 1000, 4)
    start = time.perf_counter()
    command = common.command_line()
    with xr.GLContext() as gl:
        machine = common.machine_info(gl=gl)
        common.print_machine(machine, command)
        payload = {"command": command, "machine": machine}
        payload["distances"] = cube_over_distances(gl, distances, poses)
        payload["random_poses"] = random_poses(gl, many)
        payload["tessellation"] = tessellation(gl, steps)
    say(common.finish(machine))
    payload["total_s"] = time.perf_counter() - start
    common.write_json(args.json, payload)
    say(f"results: {args.json}; total {payload['total_s']:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
