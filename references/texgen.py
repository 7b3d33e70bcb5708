"""TexGen (``pytexgen`` on PyPI, GPL-2.0-or-later) as an independent peer of ``xrayraster.weave``:
the weave benchmark (scripts/bench_weave.py) compares with it, tests/references/test_texgen_peer.py checks it.

TexGen is the textile modeller users of layer-to-layer weaves have; this module builds the same
layer-to-layer angle interlock as ``xrayraster.weave.Sample(cell, cells=(nx, ny))`` with TexGen's
``CTextileLayerToLayer`` (an orthogonal cell too: one binder a position, moved between the top and
the bottom of the stack, its stuffers in every inner gap), meshes every yarn with TexGen and reports what the weave benchmark
compares: generation time, triangle count, how many yarn meshes are closed, and the volume the
yarns share (:func:`yarn_overlap`). Bench extra only: the package never imports it (GPL), and
pytexgen is loaded on first use (:func:`texgen_available` gives the reason when it is missing).

Mapping (our frame, mm: weft along x spaced in y, warps along y spaced in x, z the thickness)
-------------------------------------------------------------------------------------------
* Axes. TexGen's X yarns (warps and binders) run along its x, its Y yarns (wefts) along its y,
  so TexGen (x, y, z) = our (y, x, z − margin_z): TexGen puts z = 0 at the bottom of weft layer 0.
  The x/y swap is a mirror, so the triangles' winding is reversed on the way back.
* Tiling. One textile of ``warp_columns · nx`` X yarns by ``weft_per_layer · ny`` Y yarns (as
  textomos tiles), its binder pattern repeated per cell, so each of our yarns is one TexGen
  yarn, and each TexGen yarn carries TexGen's own periodic repeats.
* Counts and sizes. ``CTextileLayerToLayer(X yarns, Y yarns, warp_spacing, weft_spacing,
  warp_height, weft_height, L)`` with ``SetupLayers(weft_layers − 1, weft_layers, L)``, where L
  is the binders per warp position; X yarn widths ``warp_width``, Y yarn widths ``weft_width``;
  gap size 0. Our weft column j and binder position p sit where TexGen puts Y yarn j and X yarn p
  (centres at (index + 0.5) · spacing), so no shift is needed.
* Binder pattern. TexGen moves the L binders of a position as one stack of consecutive gaps:
  ``SetBinderPosition(column, position, weft_layers − top gap)``. A cell whose binders of one
  position do not form such a stack (same count L at every position, consecutive gaps, never
  swapping order) cannot be built and raises WeaveError. The default cell's binders are such
  stacks (they move two gaps at a time, which SetBinderPosition does in one step).
* Stuffers. TexGen's warp (non-binder) yarns fill every inner gap, so ``stuffers`` must be 0 or
  ``weft_layers − 1``; the X yarns alternate binder, stuffer (``SetBinderPattern``) as our columns do.
* Sections. CTextileLayerToLayer gives every yarn TexGen's power ellipse
  (x = a·cos t, z = b·sign(sin t)·|sin t|^p), and its binder shaping reads the weft's section as
  one, so each of our sections is replaced by the power ellipse of the same width, height and
  area (:func:`texgen_power`): the ellipse exactly (p = 1); the default weft's superellipse
  (exponent 3, squarer) becomes p = 0.456, the default 2.0 × 0.32 mm lenticular binder p = 1.964
  (pointier edges). The outlines differ; their areas, so the yarn volumes, do not.
* Domain. ``CDomainPlanes`` equal to our yarn box, [0, nx·size_x] × [0, ny·size_y] ×
  [0, thickness] in our frame (in x and y that is TexGen's default domain; in z ours keeps the
  margin_z the binder loops live in, TexGen's default adds its own).
* Resolution. One knob, ``resolution``: TexGen's points per cross-section (``SetResolution``);
  TexGen then picks the points along each yarn so their spacing matches (our Sample has two knobs,
  ``points_per_section`` and ``samples_per_mm``).
* Meshes. ``CYarn.AddSurfaceToMesh(mesh, domain, bAddEndCaps=True, bFillGaps=True)`` per yarn:
  every periodic repeat of the yarn that meets the domain, clipped by TexGen to the domain and
  capped on its faces; quads are split by ``CMesh.ConvertQuadstoTriangles``; vertices as TexGen
  numbers them (no merging). A yarn's repeats that meet the box are separate pieces of its mesh
  (up to three for a binder whose TexGen path turns at the box face), each closed or not as
  TexGen's clipping leaves it.

Differences that remain (TexGen's model, not the mapping)
----------------------------------------------------------
* Binder paths: TexGen wraps each binder around a quadrant of the weft it passes (nodes placed on
  the weft's section, offset by half the binder height) and drops it almost vertically between
  wefts, Bezier-interpolated; ours is a clamped C² spline through a plateau of four nodes per
  weft column (docs/weave.md).
* Binder stacks: TexGen drops every binder of a position's stack at the same place between two
  wefts, so when the stack moves by two gaps (the default cell does) neighbouring binders of the
  stack share about one gap pitch of their drop: most of TexGen's interpenetration in the default
  cell (3.7 of 4.1 mm³ per cell at resolution 24; binder-weft 0.3 mm³).
* Surface loops: both put a binder in gap 0 / weft_layers half a binder height below / above the
  outer weft layer, inside margin_z; TexGen's wefts stay flat in a layer-to-layer textile, as ours.
* Clipping: TexGen clips and caps each yarn against the domain itself; the result is not always a
  closed surface, which is what :attr:`TexGenResult.watertight_fraction` and ``refused`` report.

TexGen logs every build step to stdout; the module turns TexGen's messages off process-wide
(``CTexGen.SetMessages(False)``) when it loads pytexgen, errors included, so every input
TexGen would reject is checked here first.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import trimesh

from xrayraster.core.errors import WeaveError
from xrayraster.core.validate import show
from xrayraster.weave import Section, UnitCell
from xrayraster.weave.manifold_mesh import to_manifold
from xrayraster.weave.sections import (
    ellipse_area,
    lenticular_area,
    power_ellipse_area,
    rounded_rectangle_area,
)

__all__ = ["TexGenResult", "texgen_available", "texgen_layer_to_layer", "texgen_power", "yarn_overlap"]

_core = None           # pytexgen.Core once loaded
_import_error = None   # reason string if the import failed


def _init():
    global _core, _import_error
    if _core is not None or _import_error is not None:
        return
    try:
        import pytexgen.Core as core
    except (ImportError, OSError) as exc:  # not installed, or a wheel without a loadable compiled Core
        _import_error = f"pytexgen not importable ({type(exc).__name__}: {exc}); pip install pytexgen"
        return
    core.TexGenSingleton.GetInstance().SetMessages(False)
    _core = core


def texgen_available() -> str | None:
    """None if TexGen (``pip install pytexgen``) imports, else the reason."""
    _init()
    return _import_error


@dataclass(frozen=True)
class TexGenResult:
    """TexGen's layer-to-layer sample: timings (s), one mesh per yarn in our frame (mm), checks.

    ``build_seconds``: the textile (pattern, binder shaping); ``mesh_seconds``: TexGen's surface
    meshing, clipping and capping (its slave nodes are built lazily in there);
    ``convert_seconds``: reading the meshes out into numpy (Python-side SWIG iteration, ~1 µs a
    number, so kept apart from TexGen's own time).
    ``meshes`` lists wefts first (by column, bottom layer first), then the warps (binders and
    stuffers, by column, bottom first), ``kinds`` names each (``weft``, ``binder``, ``stuffer``).
    ``watertight_fraction`` is the share of meshes trimesh finds watertight; ``refused`` counts
    the meshes manifold3d refuses (left out of ``interpenetration_mm3``, see :func:`yarn_overlap`).
    """

    build_seconds: float
    mesh_seconds: float
    convert_seconds: float
    meshes: tuple[trimesh.Trimesh, ...]
    kinds: tuple[str, ...]
    centrelines: tuple[np.ndarray, ...]  # per yarn as ``kinds``: (k, 3) points (mm, our frame) of TexGen's path
    watertight_fraction: float
    refused: int
    interpenetration_mm3: float

    @property
    def seconds(self) -> float:
        """TexGen's own time: textile build plus meshing (the read-out excluded)."""
        return self.build_seconds + self.mesh_seconds

    @property
    def triangles(self) -> int:
        return sum(len(m.faces) for m in self.meshes)


_AREA = {  # exact area (mm²) of each of our section shapes
    "ellipse": lambda s, w, h: ellipse_area(w, h),
    "lenticular": lambda s, w, h: lenticular_area(w, h),
    "power_ellipse": lambda s, w, h: power_ellipse_area(w, h, s.exponent),
    "rounded_rectangle": lambda s, w, h: rounded_rectangle_area(w, h, s.corner),
}


def texgen_power(section: Section, width: float, height: float) -> float:
    """TexGen's power-ellipse power p with the area of our ``section`` (``width`` × ``height`` mm).

    TexGen's section x = a·cos t, z = b·sign(sin t)·|sin t|^p has the area
    2ab·√π·Γ(p/2 + 1)/Γ(p/2 + 3/2): 4ab at p = 0 (the rectangle), πab at p = 1, falling to 0 as p
    grows; it is matched to the exact area of our smooth section.
    """
    a, b = width / 2, height / 2
    target = _AREA[section.shape](section, width, height) / (a * b)
    if not 0 < target < 4:
        raise WeaveError(f"{section.shape} section of {width} x {height} mm has no TexGen power ellipse of its "
                         "area (it would need to fill more than its bounding rectangle)")

    def area(p):
        return 2 * math.sqrt(math.pi) * math.exp(math.lgamma(p / 2 + 1) - math.lgamma(p / 2 + 1.5))

    lo, hi = 0.0, 1.0
    while area(hi) > target:
        lo, hi = hi, 2 * hi
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if area(mid) > target else (lo, mid)
    return (lo + hi) / 2


def _binder_stacks(cell: UnitCell) -> tuple[int, tuple[tuple[int, ...], ...]]:
    """(L, top gap of each position's binder stack per weft column), or WeaveError if TexGen cannot."""
    n = cell.weft_layers
    if (cell.warp_ratio, cell.binder_ratio) != (1, 1):
        raise WeaveError(f"warp_ratio = {cell.warp_ratio}, binder_ratio = {cell.binder_ratio}: the TexGen peer maps "
                         "alternating binder and stuffer columns only (both ratios 1)")
    if cell.stuffers not in (0, n - 1):
        raise WeaveError(f"stuffers = {cell.stuffers}: TexGen's layer-to-layer warps fill every inner gap, so the "
                         f"TexGen peer takes stuffers = 0 or weft_layers - 1 = {n - 1}")
    members = [[b for b, p in enumerate(cell.binder_position) if p == pos] for pos in range(cell.warp_positions)]
    counts = {len(m) for m in members}
    if len(counts) != 1 or 0 in counts:
        raise WeaveError(f"binder_position: TexGen's layer-to-layer puts the same number of binders in every warp "
                         f"position, got {[len(m) for m in members]} per position; give each position as many")
    stack = counts.pop()
    if stack > n:
        raise WeaveError(f"binders: {stack} per warp position fill all {n + 1} gaps; TexGen's layer-to-layer moves "
                         f"at most weft_layers = {n} per position")
    tops = []
    for pos, binders in enumerate(members):
        order = sorted(binders, key=lambda b: cell.binder_path[b][0])
        row = []
        for j in range(cell.weft_per_layer):
            gaps = [cell.binder_path[b][j] for b in order]
            if gaps != list(range(gaps[0], gaps[0] + stack)):
                raise WeaveError(f"binder_path: at weft column {j} the binders {order} of warp position {pos} lie in "
                                 f"gaps {gaps}; TexGen's layer-to-layer moves them as one stack of consecutive gaps "
                                 "in a fixed order")
            row.append(gaps[-1])
        tops.append(tuple(row))
    return stack, tuple(tops)


def _trimesh(mesh, lift: float) -> trimesh.Trimesh:
    """A TexGen triangle CMesh as a trimesh in our frame: TexGen (x, y, z) -> (y, x, z + lift), winding reversed."""
    xyz = np.array([(p.y, p.x, p.z + lift) for p in mesh.GetNodes()], dtype=np.float64).reshape(-1, 3)
    faces = np.array(mesh.GetIndices(_core.CMesh.TRI), dtype=np.int64).reshape(-1, 3)[:, ::-1]
    return trimesh.Trimesh(vertices=xyz, faces=np.ascontiguousarray(faces), process=False)


def texgen_layer_to_layer(cell: UnitCell, cells=(1, 1), resolution: int = 24) -> TexGenResult:
    """Build and mesh ``cell`` tiled ``cells = (nx, ny)`` with TexGen's CTextileLayerToLayer.

    ``resolution``: TexGen's points per yarn cross-section (the spacing along each yarn follows).
    The mapping and what differs from ``xrayraster.weave.Sample`` are in the module docstring.
    """
    if not isinstance(cell, UnitCell):
        raise WeaveError(f"cell must be a UnitCell, got {show(cell)}")
    if (isinstance(cells, (str, bytes)) or not hasattr(cells, "__len__") or len(cells) != 2
            or any(isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1 for c in cells)):
        raise WeaveError(f"cells must be (nx, ny), two counts of unit cells >= 1, got {show(cells)}")
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or resolution < 4:
        raise WeaveError(f"resolution must be an integer >= 4 (TexGen's points per yarn cross-section), "
                         f"got {show(resolution)}")
    stack, tops = _binder_stacks(cell)
    warp_power = texgen_power(cell.warp_section, cell.warp_width, cell.warp_height)
    weft_power = texgen_power(cell.weft_section, cell.weft_width, cell.weft_height)
    reason = texgen_available()
    if reason is not None:
        raise RuntimeError(f"TexGen unavailable: {reason}")
    core = _core
    nx, ny = (int(c) for c in cells)
    n, w, cols = cell.weft_layers, cell.weft_per_layer, cell.warp_columns
    step = cols // cell.warp_positions  # 2 with stuffer columns between the binder positions

    start = time.perf_counter()
    textile = core.CTextileLayerToLayer(cols * nx, w * ny, cell.warp_spacing, cell.weft_spacing,
                                        cell.warp_height, cell.weft_height, stack)
    textile.SetBinderPattern(core.BoolVector([i % step == 0 for i in range(cols * nx)]))
    textile.SetupLayers(n - 1, n, stack)
    textile.SetXYarnWidths(cell.warp_width)
    textile.SetYYarnWidths(cell.weft_width)
    textile.SetWarpYarnPower(warp_power)
    textile.SetBinderYarnPower(warp_power)
    textile.SetWeftYarnPower(weft_power)
    textile.SetResolution(int(resolution))
    for cx in range(nx):
        for pos, row in enumerate(tops):
            for column in range(w * ny):
                textile.SetBinderPosition(column, cx * cols + pos * step, n - row[column % w])
    yarns = [(y, "weft") for j in range(w * ny) for y in textile.GetYYarns(j)]  # GetYYarns builds the textile
    for i in range(cols * nx):
        kind = "binder" if textile.IsBinderYarn(i) else "stuffer"
        yarns += [(y, kind) for y in textile.GetXYarns(i)]
    built = time.perf_counter()

    sx, sy, sz = cell.size
    domain = core.CDomainPlanes(core.XYZ(0.0, 0.0, -cell.margin_z), core.XYZ(ny * sy, nx * sx, sz - cell.margin_z))
    surfaces = _surfaces(yarns, domain)
    meshed = time.perf_counter()
    meshes = [_trimesh(surface, cell.margin_z) for surface in surfaces]
    converted = time.perf_counter()

    volume, refused = yarn_overlap(meshes)
    return TexGenResult(build_seconds=built - start, mesh_seconds=meshed - built, convert_seconds=converted - meshed,
                        meshes=tuple(meshes),
                        kinds=tuple(kind for _, kind in yarns),
                        centrelines=tuple(_centreline(yarn, cell.margin_z) for yarn, _ in yarns),
                        watertight_fraction=float(np.mean([m.is_watertight for m in meshes])),
                        refused=refused, interpenetration_mm3=volume)


def texgen_weave_2d(cell: UnitCell, resolution: int = 24) -> TexGenResult:
    """One ply of a 2D weave ``cell`` (plain, twill, satin or a pattern) with TexGen's CTextileWeave2D.

    TexGen's X yarns (along its x) are our warps, its Y yarns our wefts; X yarn ``i`` lies at
    TexGen y = i · spacing and crossing ``j`` at x = j · spacing, z from 0 (the ply's bottom), so
    TexGen (x, y, z) is our (y + s/2, x + s/2, z + margin_z). TexGen puts every X yarn over at
    first; ``SwapPosition(j, i)`` sends warp ``i`` under weft ``j`` where our pattern has a 0. No
    refinement (``bRefine`` off, the yarns' sections stay as given), in-plane tangents (TexGen's
    default), ellipse sections of our widths and heights (TexGen's 2D weave draws ellipses), the
    domain our yarn box. One ply and equal spacings only (CTextileWeave2D has one spacing)."""
    if cell.plies != 1 or cell.warp_spacing != cell.weft_spacing:
        raise WeaveError("TexGen's 2D weave is one ply with one yarn spacing: use plies = 1 and equal spacings")
    if cell.warp_section.shape != "ellipse" or cell.weft_section.shape != "ellipse":
        raise WeaveError("TexGen's 2D weave draws ellipses: give the cell ellipse sections")
    reason = texgen_available()
    if reason is not None:
        raise RuntimeError(f"TexGen unavailable: {reason}")
    core, s = _core, cell.warp_spacing
    warps, wefts = cell.warp_positions, cell.weft_per_layer
    start = time.perf_counter()
    textile = core.CTextileWeave2D(warps, wefts, s, cell.ply_pitch, False, True)
    textile.SetXYarnWidths(cell.warp_width)
    textile.SetYYarnWidths(cell.weft_width)
    textile.SetXYarnHeights(cell.warp_height)
    textile.SetYYarnHeights(cell.weft_height)
    textile.SetResolution(int(resolution))
    for i, row in enumerate(cell.pattern):
        for j, over in enumerate(row):
            if not over:
                textile.SwapPosition(j, i)
    yarns = [(y, "weft") for j in range(wefts) for y in textile.GetYYarns(j)]
    yarns += [(y, "warp") for i in range(warps) for y in textile.GetXYarns(i)]
    built = time.perf_counter()
    sx, sy, sz = cell.size
    domain = core.CDomainPlanes(core.XYZ(-s / 2, -s / 2, -cell.margin_z), core.XYZ(sy - s / 2, sx - s / 2, sz - cell.margin_z))
    surfaces = _surfaces(yarns, domain)
    meshed = time.perf_counter()
    shift = np.array([s / 2, s / 2, cell.margin_z])
    meshes = [_trimesh(surface, 0.0).apply_translation(shift) for surface in surfaces]
    converted = time.perf_counter()
    volume, refused = yarn_overlap(meshes)
    return TexGenResult(build_seconds=built - start, mesh_seconds=meshed - built, convert_seconds=converted - meshed,
                        meshes=tuple(meshes), kinds=tuple(kind for _, kind in yarns),
                        centrelines=tuple(_centreline(yarn, 0.0) + shift for yarn, _ in yarns),
                        watertight_fraction=float(np.mean([m.is_watertight for m in meshes])),
                        refused=refused, interpenetration_mm3=volume)


def _surfaces(yarns, domain) -> list:
    """Each of ``yarns``' (TexGen yarn, kind) surfaces clipped to ``domain`` and capped there, in triangles."""
    surfaces = []
    for yarn, _ in yarns:
        surface = _core.CMesh()
        yarn.AddSurfaceToMesh(surface, domain, True, True)
        surface.ConvertQuadstoTriangles()
        surfaces.append(surface)
    return surfaces


def _centreline(yarn, lift: float) -> np.ndarray:
    """A TexGen yarn's slave nodes (its interpolated path, at the resolution it meshes with) as
    (k, 3) points in our frame: TexGen (x, y, z) is our (y, x, z − ``lift``)."""
    points = [node.GetPosition() for node in yarn.GetSlaveNodes(_core.CYarn.LINE)]
    return np.array([(p.y, p.x, p.z + lift) for p in points])


def yarn_overlap(meshes) -> tuple[float, int]:
    """(volume in mm³ shared by pairs of meshes, number of meshes manifold3d refuses).

    Each mesh is read as xrayraster.weave.sample reads a yarn (manifold3d Mesh64); pairs whose
    bounding boxes overlap are intersected and the intersection volumes summed. Meshes manifold3d
    refuses (not closed, not manifold) are counted and left out.
    """
    solids, boxes = [], []
    for mesh in meshes:
        try:
            solids.append(to_manifold(mesh))
        except WeaveError:
            continue
        boxes.append(mesh.bounds)
    refused = len(meshes) - len(solids)
    if not solids:
        return 0.0, refused
    lo, hi = np.array(boxes)[:, 0], np.array(boxes)[:, 1]
    touch = np.all((lo[:, None, :] < hi[None, :, :]) & (lo[None, :, :] < hi[:, None, :]), axis=2)
    i, j = np.nonzero(np.triu(touch, k=1))
    return float(sum((solids[a] ^ solids[b]).volume() for a, b in zip(i, j))), refused


def _demo(resolution: int = 24) -> None:
    from xrayraster.weave import Sample

    cell = UnitCell()
    print(f"default UnitCell, TexGen resolution {resolution} points per section; ours points_per_section 24, "
          "samples_per_mm 4")
    for n in (1, 4):
        r = texgen_layer_to_layer(cell, (n, n), resolution)
        start = time.perf_counter()
        ours = Sample(cell, cells=(n, n)).meshes()
        seconds = time.perf_counter() - start
        print(f"{n}x{n}: TexGen {r.seconds:.2f} s (build {r.build_seconds:.2f}, mesh {r.mesh_seconds:.2f}; "
              f"read-out {r.convert_seconds:.2f}), "
              f"{r.triangles} triangles, {len(r.meshes)} yarns, watertight {r.watertight_fraction:.1%}, "
              f"manifold3d refuses {r.refused}, interpenetration {r.interpenetration_mm3:.3f} mm3 | "
              f"ours {seconds:.2f} s, {sum(len(m.faces) for _, m in ours)} triangles, {len(ours)} yarns")


if __name__ == "__main__":
    _demo()
