"""Tessellation error of the yarn meshes, measured against the smooth yarns and against the
predictions of ``xrayraster.weave.tessellation``.

    python -m scripts.weave_tessellation            # full run, ~20 s on 2 cores
    python -m scripts.weave_tessellation --quick    # smoke test, ~5 s

(a) Sections. Each shape at the default cell's weft size (2.25 × 0.384 mm): ellipse, lenticular,
power_ellipse n = 3, rounded_rectangle corner 0.5, for points_per_section k in 8 … 64. Area error:
the outline's shoelace area against the exact area (xrayraster.weave.sections), predicted by
``area_error_mm2``. Crossing error: the path-length error of one boundary crossing at normal
incidence, i.e. the distance along the smooth outline's inward normal to the polygon, the largest
over a reference outline of 2^16 points on the exact curve (parametrised here independently:
polar angle for the superellipse, arc length for the rounded rectangle, angle on each lens arc,
with exact normals), predicted by ``section_error_mm``. Through-thickness chords: rays along the
section's height at 2^14 offsets across the width, polygon chord against the analytic chord of
every shape: the largest error over the middle half of the width (incidence within 10° of normal
for these four) and the mean over the whole width (the area error over the width). Their
largest error overall is at the yarn's sides, where the rays graze: it converges more slowly, on a
band of rays too thin for a fixed set of rays to sample reliably, so it is not tabulated. Time: ``yarn_mesh`` of a straight 10 mm weft (best of 5), whose
volume is checked against polygon area × length.

(b) Path. The default warp section (lenticular 2.0 × 0.32 mm, k = 24) swept with
``rotation_minimising_frames`` and ``sweep`` along an exact circular arc of radius 0.5 mm (the
default binder's tightest bend is 0.43 mm) and length 1 mm, bent in the height direction, at
samples_per_mm 1 … 16. Volume against Pappus (polygon area × arc length; the section is centred),
predicted 1 − sin θ / θ with θ = h / R (the ruled solid between two rings has volume A·R·sin θ).
Centre-line deviation: dense arc points to the sampled polyline, predicted R(1 − cos(θ/2)).
Surface deviation: radius of each ring vertex about the bend's axis minus that of the midpoint of
its edge to the next ring, predicted by ``path_error_mm``.

(c) The default 1 × 1 sample's 16 binders, meshed and clipped by ``Sample.meshes()`` at a few
(k, samples_per_mm): total binder volume against the finest setting, predicted from the section's
area loss (``area_error_mm2`` × length in the cell) plus the path's: A·h³κ²/6 per ring-to-ring
step inside the cell, h its length and κ the centre line's curvature at its middle, over the steps
``adaptive_params`` chose.

(d) If an OpenGL context opens: the renderer's path-length image of a straight weft (power ellipse
n = 3, 4 mm long) in a parallel beam through its thickness, 0.005 mm pixels across its width,
against the analytic chord and against the polygon's exact chord.

Writes out/weave_tessellation.json and docs/images/weave_tessellation.png (--quick: out/, names
ending in _quick).
"""

from __future__ import annotations

import math
import time
from functools import partial
from pathlib import Path

import numpy as np

import xrayraster as xr
from scripts import common
from scripts.common import best_of, say
from xrayraster.weave import Sample, Section, UnitCell
from xrayraster.weave.sample import section_outline
from xrayraster.weave.sections import (
    ellipse_area,
    lenticular_area,
    polygon_area,
    power_ellipse_area,
    rounded_rectangle_area,
)
from xrayraster.weave.sweep import CubicSpline3, adaptive_params, rotation_minimising_frames, sweep, yarn_mesh
from xrayraster.weave.tessellation import (
    area_error_mm2,
    binder_curvature,
    path_error_mm,
    section_error_mm,
)

CELL = UnitCell()
WIDTH, HEIGHT = CELL.weft_width, CELL.weft_height
SHAPES = {
    "ellipse": Section("ellipse"),
    "lenticular": Section("lenticular"),
    "power_ellipse n=3": Section("power_ellipse", exponent=3.0),
    "rounded_rectangle 0.5": Section("rounded_rectangle", corner=0.5),
}
ARC_RADIUS, ARC_LENGTH, ARC_K = 0.5, 1.0, 24
WEFT_LENGTH = 10.0


# ---------------------------------------------------------------------------------------------
# (a) the smooth sections, parametrised independently of xrayraster.weave.sections
# ---------------------------------------------------------------------------------------------


def exact_area(section: Section) -> float:
    return {"ellipse": lambda: ellipse_area(WIDTH, HEIGHT),
            "lenticular": lambda: lenticular_area(WIDTH, HEIGHT),
            "power_ellipse": lambda: power_ellipse_area(WIDTH, HEIGHT, section.exponent),
            "rounded_rectangle": lambda: rounded_rectangle_area(WIDTH, HEIGHT, section.corner)}[section.shape]()


def reference_outline(section: Section, m: int) -> tuple[np.ndarray, np.ndarray]:
    """About ``m`` points on the exact smooth outline and its outward unit normals, ``(m, 2)`` each."""
    a, b = WIDTH / 2, HEIGHT / 2
    phi = 2 * np.pi * (np.arange(m) + 0.5) / m
    if section.shape == "ellipse":
        p = np.column_stack([a * np.cos(phi), b * np.sin(phi)])
        n = p / np.array([a * a, b * b])  # the gradient of (u/a)² + (v/b)²
    elif section.shape == "power_ellipse":
        e = section.exponent
        r = (np.abs(np.cos(phi) / a) ** e + np.abs(np.sin(phi) / b) ** e) ** (-1 / e)  # polar form
        p = r[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
        n = np.sign(p) * np.abs(p) ** (e - 1) / np.array([a**e, b**e])
    elif section.shape == "lenticular":
        radius = (a * a + b * b) / (2 * b)
        alpha = math.atan2(a, radius - b)
        theta = np.pi / 2 + alpha * (2 * (np.arange(m // 2) + 0.5) / (m // 2) - 1)
        n = np.column_stack([np.cos(theta), np.sin(theta)])
        upper = radius * n + [0.0, b - radius]
        p, n = np.concatenate([upper, -upper]), np.concatenate([n, -n])
    else:  # rounded rectangle: four quarter circles and four sides, points uniform in arc length
        r = section.corner * min(a, b)
        cx, cy = a - r, b - r
        s = (np.arange(m) + 0.5) / m * (4 * (cx + cy) + 2 * np.pi * r)
        p, n = np.empty((m, 2)), np.empty((m, 2))
        start = 0.0
        for corner, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
            theta0 = corner * np.pi / 2
            side = 2 * (cy if corner % 2 == 0 else cx)  # the side before this corner, counter-clockwise
            on_side = (s >= start) & (s < start + side)
            t = s[on_side] - start - side / 2
            normal = np.array([math.cos(theta0), math.sin(theta0)])
            n[on_side] = normal
            p[on_side] = np.column_stack([normal[0] * (cx + r) - normal[1] * t, normal[1] * (cy + r) + normal[0] * t])
            start += side
            on_arc = (s >= start) & (s < start + np.pi / 2 * r)
            theta = theta0 + (s[on_arc] - start) / r
            n[on_arc] = np.column_stack([np.cos(theta), np.sin(theta)])
            p[on_arc] = [sx * cx, sy * cy] + r * n[on_arc]
            start += np.pi / 2 * r
    return p, n / np.linalg.norm(n, axis=1)[:, None]


def exact_thickness_chord(section: Section, u: np.ndarray) -> np.ndarray:
    """The smooth section's chord along its height at width coordinates ``u``, mm (analytic)."""
    a, b = WIDTH / 2, HEIGHT / 2
    x = np.abs(u)
    if section.shape == "ellipse":
        return 2 * b * np.sqrt(np.maximum(1 - (x / a) ** 2, 0))
    if section.shape == "power_ellipse":
        return 2 * b * np.maximum(1 - (x / a) ** section.exponent, 0) ** (1 / section.exponent)
    if section.shape == "lenticular":
        radius = (a * a + b * b) / (2 * b)
        return 2 * np.maximum(b - radius + np.sqrt(np.maximum(radius * radius - x * x, 0)), 0)
    r = section.corner * min(a, b)
    cx, cy = a - r, b - r
    return np.where(x <= cx, 2 * b, 2 * (cy + np.sqrt(np.maximum(r * r - (x - cx) ** 2, 0))))


def crossing_errors(polygon: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Distance from each smooth-outline point along its inward normal to the (convex) polygon, mm."""
    edge = np.roll(polygon, -1, axis=0) - polygon
    out_n = np.column_stack([edge[:, 1], -edge[:, 0]]) / np.linalg.norm(edge, axis=1)[:, None]
    offset = np.einsum("ij,ij->i", out_n, polygon)
    outside = points @ out_n.T - offset  # > 0: beyond that edge's line
    closing = normals @ out_n.T  # the inward ray moves toward the edge's line where this is > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        entry = np.where(closing > 0, outside / closing, -np.inf)
    return np.maximum(entry.max(axis=1), 0.0)


def polygon_thickness_chord(polygon: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The convex polygon's chord along v at abscissae ``u``, mm."""
    p, q = polygon, np.roll(polygon, -1, axis=0)
    du = q[:, 0] - p[:, 0]
    keep = du != 0
    p, q, du = p[keep], q[keep], du[keep]
    s = (u[:, None] - p[None, :, 0]) / du[None, :]
    v = p[None, :, 1] + s * (q[None, :, 1] - p[None, :, 1])
    hit = (s >= 0) & (s <= 1)
    top = np.where(hit, v, -np.inf).max(axis=1)
    bottom = np.where(hit, v, np.inf).min(axis=1)
    return np.maximum(top - bottom, 0.0)


def sections_table(ks, reference_points: int, rays: int) -> list[dict]:
    say(f"\n== (a) sections at the weft's size {WIDTH:g} × {HEIGHT:g} mm ==")
    say("area: relative error of the polygon's area (measured; predicted by area_error_mm2). crossing: path-length error "
        f"of one boundary crossing at normal incidence, mm (largest over {reference_points} points of the exact outline; "
        f"predicted by section_error_mm). thickness rays: chord error along the height, {rays} rays across the width, mm "
        "(middle: max over |u| <= width/4; mean over the width = area error / width). mesh ms: yarn_mesh of a straight 10 mm weft")
    say(f"{'shape':<22} {'k':>3} │ {'area meas':>9} {'pred':>9} │ {'crossing meas':>13} {'pred':>9} {'pred/meas':>9} │ "
        f"{'thick. middle':>13} {'mean':>9} │ {'mesh ms':>7}")
    u = np.linspace(-WIDTH / 2, WIDTH / 2, rays + 2)[1:-1]
    middle = np.abs(u) <= WIDTH / 4
    rows = []
    for name, section in SHAPES.items():
        area = exact_area(section)
        points, normals = reference_outline(section, reference_points)
        smooth_chord = exact_thickness_chord(section, u)
        for k in ks:
            polygon = section_outline(section, WIDTH, HEIGHT, k)
            nodes = np.array([[0.0, 0.0, 0.0], [WEFT_LENGTH, 0.0, 0.0]])
            seconds, mesh = best_of(partial(yarn_mesh, nodes, polygon, 1.0), 5)
            chord_error = smooth_chord - polygon_thickness_chord(polygon, u)
            row = {"shape": name, "k": k,
                   "area_rel_measured": (area - polygon_area(polygon)) / area,
                   "area_rel_predicted": area_error_mm2(section, WIDTH, HEIGHT, k) / area,
                   "crossing_measured_mm": float(crossing_errors(polygon, points, normals).max()),
                   "crossing_predicted_mm": section_error_mm(section, WIDTH, HEIGHT, k),
                   "thickness_chord_middle_max_mm": float(chord_error[middle].max()),
                   "thickness_chord_mean_mm": float(chord_error.mean()),
                   "straight_volume_rel_vs_polygon": mesh.volume / (polygon_area(polygon) * WEFT_LENGTH) - 1,
                   "mesh_s": seconds}
            rows.append(row)
            say(f"{name:<22} {k:>3} │ {row['area_rel_measured']:>9.2e} {row['area_rel_predicted']:>9.2e} │ "
                f"{row['crossing_measured_mm']:>13.3e} {row['crossing_predicted_mm']:>9.3e} "
                f"{row['crossing_predicted_mm'] / row['crossing_measured_mm']:>9.6f} │ "
                f"{row['thickness_chord_middle_max_mm']:>13.3e} {row['thickness_chord_mean_mm']:>9.2e} │ {1e3 * seconds:>7.2f}")
    worst = max(abs(r["straight_volume_rel_vs_polygon"]) for r in rows)
    say(f"straight 10 mm wefts: |volume / (polygon area × length) − 1| <= {worst:.1e}")
    return rows


# ---------------------------------------------------------------------------------------------
# (b) the path knob on an exact circular arc
# ---------------------------------------------------------------------------------------------


def swept(points, tangents, polygon):
    return sweep(points, polygon, rotation_minimising_frames(points, tangents), cap=True)


def arc_table(rates) -> list[dict]:
    radius, length, k = ARC_RADIUS, ARC_LENGTH, ARC_K
    polygon = section_outline(CELL.warp_section, CELL.warp_width, CELL.warp_height, k)
    reach = CELL.warp_height / 2
    say(f"\n== (b) path: warp section (lenticular {CELL.warp_width:g} × {CELL.warp_height:g} mm, k = {k}) on a circular "
        f"arc, R = {radius:g} mm, length {length:g} mm ==")
    say("volume: relative to Pappus with the polygon's area (predicted 1 − sin θ/θ, θ = h/R); centre line and surface: "
        "largest deviation from the arc and from the smooth tube, mm (predicted R(1 − cos θ/2) and path_error_mm)")
    say(f"{'samples/mm':>10} {'steps':>5} │ {'volume meas':>11} {'pred':>9} │ {'centre meas':>11} {'pred':>9} │ "
        f"{'surface meas':>12} {'pred':>9} │ {'sweep ms':>8}")
    axis = np.array([0.0, radius])  # the bend's axis, along x through (y, z) = (0, R)
    rows = []
    for rate in rates:
        steps = round(length * rate)
        phi = np.linspace(0.0, length / radius, steps + 1)
        points = np.column_stack([np.zeros_like(phi), radius * np.sin(phi), radius * (1 - np.cos(phi))])
        tangents = np.column_stack([np.zeros_like(phi), np.cos(phi), np.sin(phi)])
        seconds, (vertices, faces) = best_of(partial(swept, points, tangents, polygon), 5)
        mesh_volume = float(np.einsum("ij,ij->i", vertices[faces[:, 0]],
                                      np.cross(vertices[faces[:, 1]], vertices[faces[:, 2]])).sum() / 6)
        theta = length / radius / steps
        fine = np.linspace(0.0, length / radius, 64 * steps + 1)[:, None]
        dense = np.column_stack([radius * np.sin(fine[:, 0]), radius * (1 - np.cos(fine[:, 0]))])
        step = np.minimum((fine[:, 0] / theta).astype(int), steps - 1)
        a, b = points[step, 1:], points[step + 1, 1:]
        along = np.clip(np.einsum("ij,ij->i", dense - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
        centre_dev = np.linalg.norm(dense - (a + along[:, None] * (b - a)), axis=1).max()
        rings = vertices[: (steps + 1) * k].reshape(steps + 1, k, 3)[:, :, 1:] - axis
        mid = 0.5 * (rings[:-1] + rings[1:])
        surface_dev = (np.linalg.norm(rings[:-1], axis=2) - np.linalg.norm(mid, axis=2)).max()
        row = {"samples_per_mm": rate, "steps": steps,
               "volume_rel_measured": 1 - mesh_volume / (polygon_area(polygon) * length),
               "volume_rel_predicted": 1 - math.sin(theta) / theta,
               "centre_measured_mm": float(centre_dev), "centre_predicted_mm": radius * (1 - math.cos(theta / 2)),
               "surface_measured_mm": float(surface_dev),
               "surface_predicted_mm": path_error_mm(radius, rate, reach), "sweep_s": seconds}
        rows.append(row)
        say(f"{rate:>10g} {steps:>5} │ {row['volume_rel_measured']:>11.3e} {row['volume_rel_predicted']:>9.3e} │ "
            f"{row['centre_measured_mm']:>11.3e} {row['centre_predicted_mm']:>9.3e} │ {row['surface_measured_mm']:>12.3e} "
            f"{row['surface_predicted_mm']:>9.3e} │ {1e3 * seconds:>8.2f}")
    return rows


# ---------------------------------------------------------------------------------------------
# (c) the default cell's binders
# ---------------------------------------------------------------------------------------------


def binder_table(settings) -> list[dict]:
    section, w, h = CELL.warp_section, CELL.warp_width, CELL.warp_height
    area = lenticular_area(w, h)
    curves = binder_curvature(CELL)
    length = sum(float(s[-1] - s[0]) for s, _ in curves)
    bend = sum(float(np.trapezoid(kappa**2, s)) for s, kappa in curves)  # Σ ∫κ² ds over the binders in the cell
    say(f"\n== (c) the default 1 × 1 sample's {len(curves)} binders ({length:.2f} mm of binder in the cell, "
        f"∫κ² ds = {bend:.2f} /mm) ==")
    say("volume change: (V − V_finest) / V_finest, measured (Sample.meshes(), clipped) and predicted "
        "(section: −area_error_mm2 × length; path: −Σ A h³ κ² / 6 over the adaptive steps in the cell)")

    def predicted_loss(k, rate):
        sample = Sample(CELL, samples_per_mm=rate)
        path = 0.0
        for yarn in sample.yarns():
            if yarn.kind != "binder":
                continue
            spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
            params = adaptive_params(spline, yarn.outline, sample.path_sagitta_mm, rate)
            points, kappa = spline(params), spline.curvature((params[1:] + params[:-1]) / 2)
            steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
            inside = (points[:-1, 1] >= 0) & (points[1:, 1] <= CELL.size[1])  # y grows along a binder
            path += float(np.sum((steps**3 * kappa**2)[inside]))
        return area_error_mm2(section, w, h, k) * length + area * path / 6

    say(f"{'k':>4} {'samples/mm':>10} │ {'triangles':>9} {'mesh+clip s':>11} │ {'volume mm³':>11} {'change meas':>11} "
        f"{'pred':>10}")
    rows = []
    for k, rate in settings:
        sample = Sample(CELL, points_per_section=k, samples_per_mm=rate)
        t0 = time.perf_counter()
        meshes = [mesh for yarn, mesh in sample.meshes() if yarn.kind == "binder"]
        rows.append({"k": k, "samples_per_mm": rate, "seconds": time.perf_counter() - t0,
                     "triangles": sum(len(m.faces) for m in meshes), "volume_mm3": sum(m.volume for m in meshes),
                     "predicted_loss_mm3": predicted_loss(k, rate)})
    finest = rows[-1]
    for row in rows:
        row["change_measured"] = row["volume_mm3"] / finest["volume_mm3"] - 1
        row["change_predicted"] = (finest["predicted_loss_mm3"] - row["predicted_loss_mm3"]) / finest["volume_mm3"]
        say(f"{row['k']:>4} {row['samples_per_mm']:>10g} │ {row['triangles']:>9} {row['seconds']:>11.2f} │ "
            f"{row['volume_mm3']:>11.5f} {row['change_measured']:>11.3e} {row['change_predicted']:>10.3e}")
    return rows


# ---------------------------------------------------------------------------------------------
# (d) the renderer's path lengths through a straight weft
# ---------------------------------------------------------------------------------------------


def render_table(ks, pixel: float) -> list[dict]:
    section = CELL.weft_section
    try:
        ctx = xr.GLContext()
    except xr.GLContextError as exc:
        say(f"\n(d) skipped: no OpenGL context ({exc})")
        return []
    rows_px, cols = math.ceil(1.05 * WIDTH / pixel), 4
    geom = xr.ParallelBeamGeometry((rows_px, cols), pixel, [0.0])  # rays along +y, rows along z
    z = (np.arange(rows_px) - (rows_px - 1) / 2) * pixel
    u = -z  # the section's width axis U = V × T = y × x = −z
    smooth = exact_thickness_chord(section, u)
    inside = smooth > 0
    say(f"\n== (d) renderer: straight weft (power ellipse n = 3) along x, height along y, parallel beam along y, "
        f"{pixel:g} mm pixels ({ctx.ctx.info['GL_RENDERER']}) ==")
    say("error of the pixel-centre path length, mm: against the smooth chord (max over the yarn; mean; max over its "
        "middle half) and against the polygon's exact chord (the renderer's own error)")
    say(f"{'k':>3} │ {'vs smooth max':>13} {'mean':>9} {'middle max':>10} │ {'vs polygon max':>14} │ {'2·section_error':>15}")
    rows = []
    with xr.Renderer(geom, context=ctx) as renderer:
        for k in ks:
            polygon = section_outline(section, WIDTH, HEIGHT, k)
            scene = xr.Scene()
            scene.add(yarn_mesh([[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0]], polygon, 1.0, up=(0.0, 1.0, 0.0)), "weft")
            image = renderer.path_lengths(scene, 0)[0].astype(np.float64)
            got = image.mean(axis=1)  # the image is constant along the yarn (columns): average the float32 rounding
            versus_smooth = np.abs(got - smooth)[inside]
            middle = np.abs(u) <= WIDTH / 4
            row = {"k": k, "vs_smooth_max_mm": float(versus_smooth.max()), "vs_smooth_mean_mm": float(versus_smooth.mean()),
                   "vs_smooth_middle_max_mm": float(np.abs(got - smooth)[middle].max()),
                   "vs_polygon_max_mm": float(np.abs(image - polygon_thickness_chord(polygon, u)[:, None]).max()),
                   "two_section_error_mm": 2 * section_error_mm(section, WIDTH, HEIGHT, k)}
            rows.append(row)
            say(f"{k:>3} │ {row['vs_smooth_max_mm']:>13.3e} {row['vs_smooth_mean_mm']:>9.2e} {row['vs_smooth_middle_max_mm']:>10.2e} │ "
                f"{row['vs_polygon_max_mm']:>14.2e} │ {row['two_section_error_mm']:>15.3e}")
    return rows


# ---------------------------------------------------------------------------------------------
# Rates and the figure
# ---------------------------------------------------------------------------------------------


def order(x, y) -> float:
    """Convergence order: minus the least-squares slope of log y against log x."""
    return float(-np.polyfit(np.log(x), np.log(y), 1)[0])


def rates(sections, arc, ks_fit) -> dict:
    out = {}
    say("\n== convergence orders (−slope of log error vs log resolution) ==")
    for name in SHAPES:
        rs = [r for r in sections if r["shape"] == name and r["k"] >= ks_fit]
        k = [r["k"] for r in rs]
        out[name] = {key: order(k, [abs(r[key]) for r in rs]) for key in
                     ("area_rel_measured", "crossing_measured_mm", "thickness_chord_middle_max_mm",
                      "thickness_chord_mean_mm")}
        say(f"{name:<22} k >= {ks_fit}: area {out[name]['area_rel_measured']:.2f}, crossing "
            f"{out[name]['crossing_measured_mm']:.2f}, thickness rays: middle max {out[name]['thickness_chord_middle_max_mm']:.2f}, "
            f"mean {out[name]['thickness_chord_mean_mm']:.2f}")
    rs = [r for r in arc if r["steps"] >= 2]
    x = [r["samples_per_mm"] for r in rs]
    out["arc"] = {key: order(x, [r[key] for r in rs]) for key in ("volume_rel_measured", "centre_measured_mm",
                                                                  "surface_measured_mm")}
    say(f"{'arc':<22} samples/mm >= {min(x):g}: volume {out['arc']['volume_rel_measured']:.2f}, centre line "
        f"{out['arc']['centre_measured_mm']:.2f}, surface {out['arc']['surface_measured_mm']:.2f}")
    return out


def plot(sections, arc, binders, path: Path) -> Path | None:
    plt = common.pyplot()
    if plt is None:
        return None
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    ax = axes[0]
    for i, name in enumerate(SHAPES):
        rs = [r for r in sections if r["shape"] == name]
        k = [r["k"] for r in rs]
        first = i == 0
        ax.plot(k, [r["crossing_measured_mm"] for r in rs], "o", color=f"C{i}", label=name)
        ax.plot(k, [r["crossing_predicted_mm"] for r in rs], "-", color=f"C{i}", alpha=0.6,
                label="lines: section_error_mm" if first else None)
        ax.plot(k, [r["thickness_chord_mean_mm"] for r in rs], "s:", color=f"C{i}", ms=3, alpha=0.6,
                label="squares: mean chord error, thickness rays" if first else None)
    common.log_axes(ax, "points_per_section k", "mm", f"sections at {WIDTH:g} × {HEIGHT:g} mm; "
                    "circles: crossing error at normal incidence", xbase=2, legend=6)
    ax = axes[1]
    x = [r["samples_per_mm"] for r in arc]
    for key, label, c in (("surface", "surface deviation", "C0"), ("centre", "centre-line deviation", "C1")):
        ax.plot(x, [r[f"{key}_measured_mm"] for r in arc], "o", color=c, label=f"{label}, measured (mm)")
        ax.plot(x, [r[f"{key}_predicted_mm"] for r in arc], "-", color=c, alpha=0.6, label="predicted")
    ax.plot(x, [r["volume_rel_measured"] for r in arc], "s", color="C2", label="volume, relative, measured")
    ax.plot(x, [r["volume_rel_predicted"] for r in arc], "-", color="C2", alpha=0.6, label="1 − sin θ / θ")
    common.log_axes(ax, "samples_per_mm", "error", f"path: arc R = {ARC_RADIUS:g} mm, lenticular warp", xbase=2, legend=6)
    ax = axes[2]
    rs = binders[:-1]
    common.curve(ax, [r["triangles"] for r in rs], [abs(r["change_measured"]) for r in rs],
                 [f"k={r['k']}, {r['samples_per_mm']:g}/mm" for r in rs], color="C0", label="|volume change|, measured")
    ax.plot([r["triangles"] for r in rs], [abs(r["change_predicted"]) for r in rs], "-", color="C0", alpha=0.5,
            label="predicted")
    common.log_axes(ax, "binder triangles (16 binders)", "relative volume change vs the finest",
                    f"default binders (finest: k={binders[-1]['k']}, {binders[-1]['samples_per_mm']:g}/mm)", legend=6)
    fig.suptitle("yarn tessellation error: measured (markers) and predicted (lines)", fontsize=10)
    fig.tight_layout()
    return common.save(fig, path)


def main(argv=None) -> int:
    ap = common.parser(__doc__, "fewer resolutions and smaller references: a smoke test of a few seconds", plots=True)
    args = ap.parse_args(argv)
    args.plots_dir = args.plots_dir or (common.OUT if args.quick else common.DOCS / "images")
    args = common.outputs(args, "weave_tessellation")
    if args.quick:
        ks, reference_points, rays, arc_rates = (8, 16, 32), 2**12, 2**10, (1, 2, 4)
        binder_settings, render_ks = ((12, 2), (24, 4)), (16,)
    else:
        ks, reference_points, rays, arc_rates = (8, 12, 16, 24, 32, 48, 64), 2**16, 2**14, (1, 2, 4, 8, 16)
        binder_settings, render_ks = ((8, 1), (12, 2), (24, 4), (48, 8), (96, 16)), (8, 16, 32, 64)

    t_start = time.perf_counter()
    command, machine = common.announce()
    payload = {"command": command, "machine": machine}
    payload["sections"] = sections_table(ks, reference_points, rays)
    payload["arc"] = arc_table(arc_rates)
    payload["binders"] = binder_table(binder_settings)
    payload["render"] = render_table(render_ks, 0.005)
    payload["orders"] = rates(payload["sections"], payload["arc"], ks_fit=16)
    figure = plot(payload["sections"], payload["arc"], payload["binders"],
                  args.plots_dir / f"weave_tessellation{'_quick' if args.quick else ''}.png")
    if figure is not None:
        say(f"plot: {figure}")
    common.conclude(args.json, payload, machine, t_start)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
