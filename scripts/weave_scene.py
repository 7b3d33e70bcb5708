"""The benchmarks' 3-material weave scene and its float64 references (bench_render, bench_physics).

The scene
---------
A 3-D orthogonal "weave" of straight closed tubes in three materials, ~12 mm across:
warp tubes along x and weft tubes along y in alternating layers, and thin binder tubes along z
threading the gaps between them. No two objects touch (their bounding boxes are disjoint,
checked), so the single-pass ``overlap='sum'`` path is exact for it. The *matrix* scene adds a
fourth object, a matrix box enclosing all yarns at lower priority (the composite case).

One tessellation level ``N`` (sections around a warp/weft tube) sets every mesh: binder tubes
get proportionally fewer sections (half the radius, same edge length) and all tubes are cut
along their length into near-square quads, as a yarn mesh would be. N = 6 / 18 / 60 gives
~12 k / ~100 k / ~1.1 M triangles.

References
----------
:class:`References` gives per-material float64 path lengths on a seeded sample of detector
pixels, from rays written out from the documented convention (xrayraster/core/geometry.py), not
from the renderer's ray set-up: ``exact``, the chords of the very polyhedral meshes rendered
(every tube is convex: half-space intersection over its face planes), and ``smooth``, the chords
of the ideal cylinders. For the matrix scene the matrix entry is the box chord minus the yarn chords.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import trimesh

import xrayraster as xr
from references.chords import cylinder_chord, rot_z

# -- geometry: cone beam, magnification 2.5; the scene (≤ 8.9 mm from the axis) fills ~80–90 % of
#    a 48 mm detector at every angle. Pixel size = DET_WIDTH / n, so all detector sizes see the
#    same field of view and only the sampling changes.
SOD, SDD, DET_WIDTH = 40.0, 100.0, 48.0
ANGLES_DEG = (10.0, 37.0, 71.0)  # off the axes: no ray family is exactly parallel to a tube

# -- scene layout (mm)
YARNS = ("warp", "weft", "binder")
MATRIX = "matrix"
R_YARN, R_BINDER, LENGTH = 0.6, 0.3, 12.0
BOX_HALF = 6.25  # matrix box: encloses the yarns (which end at ±6) without sharing a face plane


# ---------------------------------------------------------------------------------------------
# Scene
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Tube:
    """A straight closed tube along one axis: the ideal shape and its tessellation."""

    material: str
    centre: tuple[float, float, float]
    axis: int  # 0 = x, 1 = y, 2 = z
    radius: float

    @property
    def bbox(self) -> np.ndarray:
        """(2, 3) box holding the smooth tube and hence its inscribed tessellation."""
        half = np.full(3, self.radius)
        half[self.axis] = LENGTH / 2
        return np.stack([np.subtract(self.centre, half), np.add(self.centre, half)])

    def sections(self, level: int) -> int:
        # Thinner tubes get fewer sections, so every triangle has about the same size.
        return max(4, round(level * self.radius / R_YARN))

    def mesh(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """Closed convex prism: vertices on the cylinder, near-square quads along the length."""
        n = self.sections(level)
        m = max(1, round(LENGTH * n / (2 * math.pi * self.radius)))
        z = np.linspace(-LENGTH / 2, LENGTH / 2, m + 1)
        profile = np.vstack([[0, -LENGTH / 2], np.column_stack([np.full(m + 1, self.radius), z]), [0, LENGTH / 2]])
        local = trimesh.creation.revolve(profile, sections=n)  # about local z
        v = np.empty_like(local.vertices)
        a = self.axis  # cyclic permutation of the axes = a proper rotation (keeps the winding)
        v[:, (a + 1) % 3], v[:, (a + 2) % 3], v[:, a] = local.vertices.T
        return v + self.centre, np.asarray(local.faces)

    def smooth_chord(self, src: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Chord of the ideal capped cylinder along unit rays from ``src``, float64."""
        a = self.axis
        axes = [(a + 1) % 3, (a + 2) % 3, a]  # the tube's frame: its axis last, as cylinder_chord's z
        return cylinder_chord((src - np.asarray(self.centre))[axes], dirs[:, axes], self.radius, LENGTH / 2)


def yarn_layout() -> list[Tube]:
    """Warp (x) and weft (y) layers alternating in z, binders (z) through the gaps.

    Binders sit half a pitch away from every warp/weft axis (1 mm > 0.6 + 0.3 mm), and warp and
    weft layers are 2 mm apart (> 2 × 0.6 mm), so nothing overlaps.
    """
    odd = (-5.0, -3.0, -1.0, 1.0, 3.0, 5.0)
    even = (-4.0, -2.0, 0.0, 2.0, 4.0)
    tubes = [Tube("warp", (0.0, y, z), 0, R_YARN) for z in (-5.0, -1.0, 3.0) for y in odd]
    tubes += [Tube("weft", (x, 0.0, z), 1, R_YARN) for z in (-3.0, 1.0, 5.0) for x in odd]
    tubes += [Tube("binder", (x, y, 0.0), 2, R_BINDER) for x in even for y in even]
    return tubes


def face_planes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct face planes (unit normal n, offset h; inside is n·x ≤ h) of a closed convex mesh.

    Coplanar faces (two per side quad, a fan per cap) give the same plane up to rounding, so one
    representative each turns a 20 k-face tube into ~60 planes: the same polyhedron (to ~1e-15 mm)
    at a cost that does not grow with the length subdivision.
    """
    a, b, c = (np.asarray(vertices, np.float64)[faces[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = np.einsum("ij,ij->i", n, a)
    key = np.round(np.column_stack([n, h / (1.0 + np.abs(h).max())]) * 1e9)
    _, first = np.unique(key, axis=0, return_index=True)
    return n[first], h[first]


def convex_chord(src: np.ndarray, dirs: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Exact float64 chord of unit rays from ``src`` through the polyhedron ∩{n·x ≤ h}."""
    out = np.empty(len(dirs))
    dist = offsets - normals @ src  # ≥ 0 where the source is inside the half-space
    step = max(1, 4_000_000 // max(1, len(normals)))  # bound the (rays × planes) temporaries
    for s in range(0, len(dirs), step):
        nd = dirs[s : s + step] @ normals.T
        with np.errstate(divide="ignore", invalid="ignore"):
            t = dist / nd
        enter = np.maximum(np.where(nd < 0, t, -np.inf).max(axis=1), 0.0)
        leave = np.where(nd > 0, t, np.inf).min(axis=1)
        chord = np.maximum(leave - enter, 0.0)
        chord[((nd == 0) & (dist < 0)).any(axis=1)] = 0.0  # parallel to a face, outside it
        out[s : s + step] = chord
    return out


@dataclass
class Solid:
    """One scene object as the references see it."""

    material: str
    bbox: np.ndarray
    planes: tuple[np.ndarray, np.ndarray]  # of the mesh actually rendered
    smooth: object  # callable (src, dirs) -> chord of the ideal shape

    def chord(self, kind: str, src, dirs) -> np.ndarray:
        if kind == "exact":
            return convex_chord(src, dirs, *self.planes)
        return self.smooth(src, dirs)


@dataclass
class BenchScene:
    level: int
    scene: xr.Scene  # yarns only: single pass
    resolve_scene: xr.Scene  # the matrix scene: yarns + lower-priority matrix box
    solids: list[Solid]  # yarns, then the box
    gvxr_meshes: dict[str, list]  # material -> [(vertices, faces)], the very arrays we render
    triangles: int
    build_s: float
    per_material: dict[str, int] = field(default_factory=dict)


def build_scene(level: int) -> BenchScene:
    t0 = time.perf_counter()
    tubes = yarn_layout()
    boxes = np.stack([t.bbox for t in tubes])
    for i in range(len(boxes)):  # disjoint boxes ⇒ disjoint objects ⇒ 'sum' is exact
        lo, hi = boxes[i]
        apart = np.any((boxes[:, 1] <= lo) | (boxes[:, 0] >= hi), axis=1)
        apart[i] = True
        assert apart.all(), f"tube {i} overlaps another: fix yarn_layout()"
    scene, resolve_scene = xr.Scene(), xr.Scene()
    solids, meshes = [], {m: [] for m in YARNS}
    for i, tube in enumerate(tubes):
        obj = scene.add(tube.mesh(level), tube.material, name=f"{tube.material}{i}")
        resolve_scene.add(obj.mesh, tube.material, name=obj.name)  # same checked Mesh, not copied
        solids.append(Solid(tube.material, tube.bbox, face_planes(obj.mesh.vertices, obj.mesh.faces), tube.smooth_chord))
        meshes[tube.material].append((obj.mesh.vertices, obj.mesh.faces))
    box = resolve_scene.add(trimesh.creation.box(extents=(2 * BOX_HALF,) * 3), MATRIX, name="matrix", priority=-1)
    planes = face_planes(box.mesh.vertices, box.mesh.faces)
    solids.append(Solid(MATRIX, np.array([[-BOX_HALF] * 3, [BOX_HALF] * 3]), planes, lambda s, d: convex_chord(s, d, *planes)))
    per = {m: sum(len(f) for _, f in meshes[m]) for m in YARNS}
    return BenchScene(level, scene, resolve_scene, solids, meshes, scene.num_triangles, time.perf_counter() - t0, per)


# ---------------------------------------------------------------------------------------------
# Rays and references (straight from the documented convention in xrayraster/core/geometry.py, not
# from the renderer's ray set-up, so a frame or offset bug in the renderer shows as an error)
# ---------------------------------------------------------------------------------------------


def geometry(n: int, angles=None) -> xr.ConeBeamGeometry:
    angles = [math.radians(a) for a in ANGLES_DEG] if angles is None else angles
    return xr.ConeBeamGeometry(SOD, SDD, (n, n), DET_WIDTH / n, angles)


def sub_offsets(k: int) -> np.ndarray:
    """(k², 2) (row, col) offsets in pixels of the centres of a regular k×k sub-grid."""
    f = (np.arange(k) + 0.5) / k - 0.5
    return np.stack(np.meshgrid(f, f, indexing="ij"), axis=-1).reshape(-1, 2)


def rays(theta: float, n: int, rc: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Source and (m, q, 3) unit directions to sub-pixel points (rc: (m, 2) pixel rows/cols)."""
    r = rot_z(theta)
    pixel = DET_WIDTH / n
    row = rc[:, 0, None] + offsets[None, :, 0] - (n - 1) / 2
    col = rc[:, 1, None] + offsets[None, :, 1] - (n - 1) / 2
    local = np.stack(np.broadcast_arrays(col * pixel, SDD - SOD, row * pixel), axis=-1)
    src = r @ np.array([0.0, -SOD, 0.0])
    d = local @ r.T - src
    return src, d / np.linalg.norm(d, axis=-1, keepdims=True)


def projected_box(theta: float, n: int, bbox: np.ndarray) -> np.ndarray:
    """(row_lo, row_hi, col_lo, col_hi) fractional pixel indices of a box's shadow."""
    corners = np.array(np.meshgrid(*bbox.T, indexing="ij")).reshape(3, -1).T
    local = corners @ rot_z(theta)  # = R_z(−θ)·p: the frame where the source is at −y
    t = SDD / (local[:, 1] + SOD) / (DET_WIDTH / n)
    row, col = local[:, 2] * t + (n - 1) / 2, local[:, 0] * t + (n - 1) / 2
    return np.array([row.min(), row.max(), col.min(), col.max()])


def sample_pixels(n: int, count: int, seed: int = 12345) -> np.ndarray:
    """A fixed (seeded per detector size) random subset of pixels, (m, 2) rows/cols."""
    rng = np.random.default_rng([seed, n])
    flat = np.sort(rng.choice(n * n, size=min(count, n * n), replace=False))
    return np.column_stack(np.divmod(flat, n))


class References:
    """Per-material reference path lengths on the sampled pixels, cached (they are reused
    across methods, and 'smooth'/'pixel' across tessellation levels)."""

    def __init__(self, pixels_per_view: int, pixels: dict[int, np.ndarray] | None = None):
        """``pixels``: {detector side: (m, 2) rows/cols} to use instead of a seeded sample."""
        self.count = pixels_per_view
        self._cache: dict = {("pixels", n): rc for n, rc in (pixels or {}).items()}
        self.seconds = 0.0

    def pixels(self, n: int) -> np.ndarray:
        key = ("pixels", n)
        if key not in self._cache:
            self._cache[key] = sample_pixels(n, self.count)
        return self._cache[key]

    def get(self, bench: BenchScene, kind: str, n: int, view: int, k: int) -> dict[str, np.ndarray]:
        """{material: (m,) mm}: mean over the k×k sub-rays of each sampled pixel of the chords
        of the polyhedral meshes (kind 'exact') or of the smooth shapes ('smooth'); the
        matrix entry is the box chord minus all yarn chords (it has the lowest priority)."""
        key = (kind, bench.level if kind == "exact" else None, n, view, k)
        if key in self._cache:
            return self._cache[key]
        t0 = time.perf_counter()
        theta = math.radians(ANGLES_DEG[view])
        rc = self.pixels(n)
        offsets = sub_offsets(k)
        out = {m: np.zeros(len(rc)) for m in (*YARNS, MATRIX)}
        for solid in bench.solids:
            r0, r1, c0, c1 = projected_box(theta, n, solid.bbox)
            # ±1 pixel: sub-rays reach half a pixel beyond the sampled pixel's centre.
            hit = (rc[:, 0] >= r0 - 1) & (rc[:, 0] <= r1 + 1) & (rc[:, 1] >= c0 - 1) & (rc[:, 1] <= c1 + 1)
            if not hit.any():
                continue
            src, d = rays(theta, n, rc[hit], offsets)
            chord = solid.chord(kind, src, d.reshape(-1, 3)).reshape(d.shape[:2]).mean(axis=1)
            out[solid.material][hit] += chord
        out[MATRIX] -= sum(out[m] for m in YARNS)  # box minus the yarns it holds
        self._cache[key] = out
        self.seconds += time.perf_counter() - t0
        return out
