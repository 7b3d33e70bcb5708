"""bench_render's measurements of xrayraster: per-view best times of ``Renderer.path_lengths``
on sampled pixels, their errors against the weave scene's float64 references, the table rows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

import xrayraster as xr
from scripts import common
from scripts.weave_scene import ANGLES_DEG, BenchScene, References, geometry

PIXEL_SUBGRID = 16  # S×S sub-rays per pixel for the 'pixel' reference


@dataclass
class Measurement:
    """One renderer on one configuration: per-view best times and sampled images."""

    method: str  # 'sum', 'nested', 'resolve' or 'gvxr'
    level: int
    triangles: int
    size: int
    k: int
    repeats: int
    views: list[int] = field(default_factory=list)
    best_s: list[float] = field(default_factory=list)
    samples: list[dict[str, np.ndarray]] = field(default_factory=list)  # per view {material: (m,)}
    setup_s: float = 0.0
    errors: dict = field(default_factory=dict)

    @property
    def s_per_view(self) -> float:
        return float(np.mean(self.best_s))

    def record(self) -> dict:
        return {
            "method": self.method,
            "level": self.level,
            "triangles": self.triangles,
            "detector": self.size,
            "supersampling": self.k,
            "repeats": self.repeats,
            "views_deg": [ANGLES_DEG[v] for v in self.views],
            "best_s_per_view": self.best_s,
            "s_per_view": self.s_per_view,
            "setup_s": self.setup_s,
            "errors_mm": self.errors,
        }


def time_ours(ctx, bench: BenchScene, method: str, n: int, k: int, repeats: int, max_views: int, budget_s: float, rc):
    scene = bench.scene if method == "sum" else bench.resolve_scene
    meas = Measurement(method, bench.level, scene.num_triangles, n, k, repeats)
    renderer = xr.Renderer(geometry(n), supersampling=k, overlap=method, context=ctx)
    try:
        t0 = time.perf_counter()
        renderer.path_lengths(scene, 0)  # warm-up: upload, compile, size the crossing lists
        meas.setup_s = time.perf_counter() - t0
        assert renderer.last_method == method, renderer.last_method
        start = time.perf_counter()
        for view in range(max_views):
            best, out = common.best_of(lambda: renderer.path_lengths(scene, view), repeats)
            meas.views.append(view)
            meas.best_s.append(best)
            meas.samples.append({m: out[i, rc[:, 0], rc[:, 1]].astype(np.float64) for i, m in enumerate(scene.materials)})
            if not common.next_fits(start, len(meas.views), budget_s):
                break  # the next view would overrun this configuration's time budget
    finally:
        renderer.release()
    return meas

def error_stats(meas: Measurement, refs: References, bench: BenchScene, kind: str, views=None) -> dict:
    """max / p99.9 / mean |error| (mm) pooled over sampled pixels, views and materials."""
    k = PIXEL_SUBGRID if kind == "pixel" else meas.k
    ref_kind = "smooth" if kind == "pixel" else kind
    errs, per = [], {}
    for view, sample in zip(meas.views, meas.samples):
        if views is not None and view not in views:
            continue
        ref = refs.get(bench, ref_kind, meas.size, view, k)
        for m, values in sample.items():
            e = np.abs(values - ref[m])
            errs.append(e)
            per[m] = max(per.get(m, 0.0), float(e.max()))
    e = np.concatenate(errs)
    return {"max": float(e.max()), "p99.9": float(np.percentile(e, 99.9)), "mean": float(e.mean()), "max_by_material": per}


def evaluate(meas: Measurement, refs: References, bench: BenchScene) -> None:
    meas.errors = {kind: error_stats(meas, refs, bench, kind) for kind in ("exact", "smooth", "pixel")}


HEADER = (
    f"{'tris':>9} {'det':>5} {'k':>2} {'method':>7} {'views':>5} {'s/view':>8} │"
    f" {'exact: max':>10} {'p99.9':>8} {'mean':>8} │ {'smooth: max':>11} {'p99.9':>8} {'mean':>8} │"
    f" {'pixel: max':>10} {'p99.9':>8} {'mean':>8}"
)


def row(meas: Measurement) -> str:
    e = meas.errors
    cells = " │ ".join(
        " ".join(f"{e[kind][s]:{w}.2e}" for s, w in (("max", 10 + (kind == "smooth")), ("p99.9", 8), ("mean", 8)))
        for kind in ("exact", "smooth", "pixel")
    )
    return f"{meas.triangles:>9,} {meas.size:>5} {meas.k:>2} {meas.method:>7} {len(meas.views):>5} {meas.s_per_view:>8.4f} │ {cells}"
