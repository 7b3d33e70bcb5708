"""bench_render's gVirtualXRay side: its frame checked against ours, its per-view times and
sampled path lengths, and the comparison with ours on the views both rendered.
"""

from __future__ import annotations

import math
import time

import numpy as np
import trimesh

import xrayraster as xr
from scripts import common
from scripts.peers import gvxr_peer
from scripts.render_measure import Measurement, error_stats
from scripts.weave_scene import ANGLES_DEG, DET_WIDTH, SDD, SOD, YARNS, BenchScene, References


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

