"""Path-length accuracy figures quoted in docs/accuracy.md, measured against float64 references.

    python scripts/accuracy_render.py            # ~10 s on 2 cores

1. A 10 mm cube at random poses, 512² detector, source 50 mm to 10 m from the axis: |L - L_exact|
   (slab method in float64) at the mean, 99.9th percentile and maximum over all pixels.
2. 1000 random scanner poses around the same cube (48² detector): error percentiles, and for the
   worst pixels the chord's lateral gradient |∇L| (mm per mm), which explains them.
3. Tessellation: interior chord error of icospheres and n-gon prisms against the smooth shapes,
   and the ratio per refinement step that theory predicts (4).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from references.chords import box_chord, cone_rays, cylinder_chord, random_rotation, sphere_chord  # noqa: E402

import xrayraster as xr  # noqa: E402


def cube_scene(rot, centre):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, centre
    scene = xr.Scene()
    scene.add(trimesh.creation.box((10.0, 10.0, 10.0)), "c", transform=xr.Transform(m))
    return scene


def cube_over_distances(gl):
    print("1. 10 mm cube, 512², 6 random poses per distance (errors in mm)")
    print(f"{'SOD mm':>8} {'mean':>9} {'p99.9':>9} {'max':>9} {'ms/view':>8}")
    n = 512
    for sod in (50.0, 300.0, 2000.0, 10000.0):
        rng = np.random.default_rng(int(sod))
        pixel, errors, times = 2 * 22.0 / n, [], []
        for _ in range(6):
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
        print(f"{sod:8.0f} {e.mean():9.2e} {np.percentile(e, 99.9):9.2e} {e.max():9.2e} {1e3 * min(times):8.1f}")


def thousand_poses(gl):
    print("\n2. 1000 random poses, 48² cone beam (SOD 60 mm), 10 mm cube")
    rng = np.random.default_rng(2024)
    base = xr.ConeBeamGeometry(60.0, 120.0, (48, 48), 0.6, [0.0]).to_vec().array[0]
    vectors = [np.concatenate([q @ base[k : k + 3] for k in (0, 3, 6, 9)]) for q in (random_rotation(rng) for _ in range(1000))]
    geom = xr.VectorGeometry("cone", (48, 48), vectors)
    scene = xr.Scene()
    scene.add(trimesh.creation.box((10.0, 10.0, 10.0)), "c")
    errors, gradients = [], []
    rr, cc = np.mgrid[0:48, 0:48] - 23.5
    with xr.Renderer(geom, context=gl) as r:
        for k, vec in enumerate(vectors):
            s, d, u, w = np.split(np.asarray(vec), 4)
            dirs = d + rr[..., None] * w + cc[..., None] * u - s
            dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
            origins = np.broadcast_to(s, dirs.shape)
            exact = box_chord(origins, dirs, np.zeros(3), np.eye(3), (5, 5, 5))
            errors.append(np.abs(r.path_lengths(scene, k)[0] - exact).ravel())
            # Lateral sensitivity of the chord: shift the ray by 1e-6 mm along u and v.
            h = 1e-6
            shifted = [box_chord(origins + h * a / np.linalg.norm(a), dirs, np.zeros(3), np.eye(3), (5, 5, 5)) for a in (u, w)]
            gradients.append((np.hypot(shifted[0] - exact, shifted[1] - exact) / h).ravel())
    e, g = np.concatenate(errors), np.concatenate(gradients)
    print(f"   pixels {e.size}: mean {e.mean():.2e}, p99.9 {np.percentile(e, 99.9):.2e}, "
          f"p99.99 {np.percentile(e, 99.99):.2e}, max {e.max():.2e} mm")
    worst = np.argsort(e)[-5:]
    print("   worst pixels: error mm / |∇L| mm per mm / error ÷ |∇L| (the ray offset it corresponds to, mm)")
    for i in worst[::-1]:
        print(f"     {e[i]:.2e} / {g[i]:8.1f} / {e[i] / max(g[i], 1e-30):.1e}")


def tessellation(gl):
    print("\n3. Tessellation (interior chord error vs the smooth shape, mm; theory: ÷4 per step)")
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
    with xr.Renderer(geom, context=gl) as r:
        for label, levels, make, exact, interior in cases:
            errs = []
            for level in levels:
                scene = xr.Scene()
                scene.add(make(level), "m")
                errs.append(np.abs(r.path_lengths(scene)[0] - exact)[interior].mean())
            ratios = [f"{a / b:.2f}" for a, b in zip(errs, errs[1:])]
            print(f"   {label} {levels}: errors {', '.join(f'{x:.2e}' for x in errs)}; ratios {', '.join(ratios)}")


def main() -> None:
    with xr.GLContext() as gl:
        print(f"xrayraster {xr.__version__} on {gl.renderer}")
        cube_over_distances(gl)
        thousand_poses(gl)
        tessellation(gl)


if __name__ == "__main__":
    main()
