"""Samples: ``nx × ny × nz`` unit cells as one box of matrix and continuous yarn meshes.

Axes (mm), as in :mod:`xrayraster.weave.spec`: weft yarns run along **x** and are spaced along
**y**; warp yarns (binders and stuffers) run along **y** and are spaced along **x**; **z** is the
thickness, the bottom cell's weft layer 0 lowest. Cell ``(cx, cy, cz)`` occupies
``[cx·size_x, (cx+1)·size_x] × [cy·size_y, (cy+1)·size_y] × [cz·thickness, (cz+1)·thickness]``,
so the yarns fill ``[0, nx·size_x] × [0, ny·size_y] × [0, nz·thickness]``; the matrix box is that
box grown by ``margin_xy`` in x and y (the cell's ``margin_z`` is already inside its thickness).

Every yarn is one path across the whole sample, not one per cell: a weft is a straight line along
x at its column's y and its layer's z; a binder has a node at every weft column of every cell it
crosses, at the height of its gap there (``gap_z``), so it passes over and under the wefts and the
spline runs on smoothly across cell borders. That "node" is a plateau of four (:data:`PLATEAU`) over
the middle half of the weft, and the binder's path is clamped flat (tangent +y) at both ends, so the
spline does not overshoot the step-shaped gap sequence; a stuffer is a straight line along y in its gap.
Paths start and end one node (a weft spacing, or ``extend`` mm for straight yarns) outside the box,
so the tube's end caps lie outside and the clip to the box (manifold3d, in double precision) leaves
flat, closed cut faces exactly on the box's faces.

With a :class:`~xrayraster.weave.distort.Distortion` (all 0 by default: the regular weave above,
bit for bit), a weft gets a node at every warp column, a stuffer one at every weft column; each
yarn draws its node displacements, waviness and section scale and rotation from its own generator
(``seed`` and its name), a binder's plateau moving as one; and each stacked layer of cells moves by
its own in-plane shift. Yarns of one more period on each side are added where the distortion can
carry them into the box, and clipped yarns under :data:`REMNANT_FRACTION` of a full one are
dropped. Yarns may touch or cut into each other (as TexGen's do); the scene's priorities (warp over
weft over matrix) resolve the shared space.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import trimesh
from tqdm.auto import tqdm

from ..core.choices import EXPORT_PER, MESH_FORMATS, WEAVE_RESOLVE, check_choice
from ..core.errors import WeaveError
from ..core.estimate import plan
from ..core.files import atomic_directory
from ..core.validate import show
from ..scene.materials import Material
from ..scene.scene import Scene
from .binders import binder_curvature_along, smallest_bend_radius_mm
from .distort import Distortion, yarn_rng
from .families import FAMILIES
from .export import (
    GENERATOR,
    REPORT_NAME,
    MeshPart,
    export_report,
    merge_meshes,
    settle,
    write_parts,
    write_report,
)
from .manifold_mesh import from_manifold, to_manifold
from .materials import as_yarn_materials
from .resolve import interpenetration, resolve_boolean
from .size import SAMPLE_DEFAULTS, WeaveJob
from .spec import UnitCell
from .sweep import bend_sagitta_mm, polygon_area
from .voids import Voids, draw_voids
from .yarn_paths import PLATEAU, sample_yarns
from .yarn import LABELS, PRIORITIES, Yarn, section_outline

# LABELS, PRIORITIES, Yarn and section_outline live in .yarn; re-exported here, where users meet them
__all__ = ["LABELS", "PLATEAU", "PRIORITIES", "REMNANT_FRACTION", "Sample", "Yarn", "section_outline"]

#: A clipped yarn smaller than this fraction of a full one (its outline's area times the box's
#: length along it) is dropped: with a layer shift, yarns of the neighbouring periods straddle the
#: box's side faces, and the ones barely inside would leave thin slivers along a face.
REMNANT_FRACTION = 0.1


def _stage(show_it: bool, text: str) -> None:
    """One line of progress on stderr, between the progress bars."""
    if show_it:
        print(f"weave: {text}", file=sys.stderr, flush=True)


def _count(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise WeaveError(f"{name} must be an integer >= 1, got {show(value)}")
    return int(value)


@dataclass(frozen=True)
class Sample:
    """``cells = (nx, ny)`` unit cells side by side and ``layers_of_cells`` stacked.

    ``points_per_section`` is the outline's point count (a multiple of 4, so every shape takes it);
    ``samples_per_mm`` the path samples per mm of yarn on the cell's tightest binder bend, which
    sets the largest chord error (:attr:`path_sagitta_mm`); elsewhere each yarn's samples are spaced
    out to that same error (:func:`~xrayraster.weave.sweep.adaptive_params`). ``extend`` (mm) is how far the regular
    weave's straight yarns reach past the box before the clip (a distorted sample's paths reach at
    least half a node spacing past it). ``distortion`` (:class:`Distortion`, all 0 by default: the
    regular weave, bit for bit) is drawn from ``seed`` (an integer >= 0): the same seed gives the
    same sample. ``voids`` (:class:`~xrayraster.weave.voids.Voids`, none by default) are drawn from
    the same seed.
    """

    cell: UnitCell
    cells: tuple[int, int] = SAMPLE_DEFAULTS["cells"]
    layers_of_cells: int = SAMPLE_DEFAULTS["layers_of_cells"]
    points_per_section: int = SAMPLE_DEFAULTS["points_per_section"]
    samples_per_mm: float = SAMPLE_DEFAULTS["samples_per_mm"]
    extend: float = 0.5
    distortion: Distortion = field(default_factory=Distortion)
    seed: int = 0
    voids: Voids = field(default_factory=Voids)

    def __post_init__(self):
        if not isinstance(self.cell, UnitCell):
            raise WeaveError(f"cell must be a UnitCell, got {show(self.cell)}")
        cells = self.cells
        if isinstance(cells, (str, bytes)) or not hasattr(cells, "__len__") or len(cells) != 2:
            raise WeaveError(f"cells must be (nx, ny), two counts of unit cells, got {show(cells)}")
        object.__setattr__(self, "cells", (_count("cells[0] (nx)", cells[0]), _count("cells[1] (ny)", cells[1])))
        object.__setattr__(self, "layers_of_cells", _count("layers_of_cells", self.layers_of_cells))
        k = self.points_per_section
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 8 or k % 4:
            raise WeaveError(f"points_per_section must be an integer >= 8 and a multiple of 4, got {show(k)}")
        rate = self.samples_per_mm
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (0 < rate < float("inf")):
            raise WeaveError(f"samples_per_mm must be a positive number, got {show(rate)}")
        ext = self.extend
        if isinstance(ext, bool) or not isinstance(ext, (int, float)) or not (0 < ext < float("inf")):
            raise WeaveError(f"extend must be a positive number of mm, got {show(ext)}")
        if not isinstance(self.distortion, Distortion):
            raise WeaveError(f"distortion must be a Distortion, got {show(self.distortion)}")
        if not isinstance(self.voids, Voids):
            raise WeaveError(f"voids must be a Voids, got {show(self.voids)}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise WeaveError(f"seed must be an integer >= 0, got {show(self.seed)}")
        object.__setattr__(self, "seed", int(self.seed))
        plateau = self.plateau
        self.distortion.check(self.cell, plateau_mm=(plateau[-1] - plateau[0]) * self.cell.weft_width / 2)

    # Geometry ---------------------------------------------------------------------------

    @property
    def plateau(self) -> tuple[float, ...]:
        """A binder's nodes over a weft column (:data:`PLATEAU`, or its family's own)."""
        return FAMILIES[self.cell.family].plateau or PLATEAU

    @cached_property
    def path_sagitta_mm(self) -> float:
        """The largest distance (mm) between a yarn's chords and its smooth tube: what ``samples_per_mm``
        gives on the regular cell's tightest binder bend (:func:`~xrayraster.weave.tessellation.path_error_mm`,
        the warp's half-height outside it). Each yarn's samples hold it along their whole path, dense in
        bends and sparse where the yarn runs straight; 0 (uniform samples) for a cell whose binders never bend."""
        radius = smallest_bend_radius_mm(binder_curvature_along(Sample(self.cell).yarns(), self.cell.size))
        return bend_sagitta_mm(radius, 1.0 / self.samples_per_mm, self.cell.warp_height / 2)

    @property
    def yarn_box(self) -> np.ndarray:
        """``(2, 3)`` min/max corners (mm) the yarns are clipped to."""
        sx, sy, sz = self.cell.size
        nx, ny = self.cells
        return np.array([[0.0, 0.0, 0.0], [nx * sx, ny * sy, self.layers_of_cells * sz]])

    @property
    def box(self) -> np.ndarray:
        """``(2, 3)`` min/max corners (mm) of the matrix: the yarn box grown by ``margin_xy`` in x and y."""
        m = self.cell.margin_xy
        return self.yarn_box + np.array([[-m, -m, 0.0], [m, m, 0.0]])

    def yarns(self) -> list[Yarn]:
        """Every yarn's centre-line nodes and outline, wefts first (bottom to top), then warps
        (:func:`~xrayraster.weave.yarn_paths.sample_yarns`).

        With a distortion, the paths carry more nodes (a weft one at every warp column) moved by
        the draws of each yarn's own generator, and the yarns of one more period on each side join
        wherever the distortion can carry them into the box (:meth:`meshes` drops their slivers).
        """
        return sample_yarns(self)

    # Meshes -----------------------------------------------------------------------------

    def matrix_mesh(self) -> trimesh.Trimesh:
        """The matrix: the sample box, a closed outward-oriented box mesh."""
        lo, hi = self.box
        return trimesh.creation.box(bounds=np.array([lo, hi]))

    def meshes(self, progress: bool = False) -> list[tuple[Yarn, trimesh.Trimesh]]:
        """Each yarn swept (``yarn_mesh``) and clipped exactly to the yarn box (manifold3d, float64).

        A clipped yarn under :data:`REMNANT_FRACTION` of a full one (its outline's area times the
        box's length along it) is left out: a sliver of a neighbouring period's yarn along a side face.
        ``progress``: a tqdm bar over the yarns on stderr. A sample whose meshes cannot fit in memory
        is refused first (:mod:`~xrayraster.weave.size`).
        """
        import manifold3d

        plan(WeaveJob(self, export=False), WeaveError)

        lo, hi = self.yarn_box
        clip = manifold3d.Manifold.cube(tuple(hi - lo)).translate(tuple(lo))
        # a distorted path reaches up to 1.5 node spacings past the box: its tube is trimmed there
        # first (the same solid once clipped); the regular weave's stays whole, as it always was
        within = None if self.distortion.is_zero else self.yarn_box
        out = []
        for yarn in tqdm(self.yarns(), desc="yarns", unit="yarn", disable=not progress, leave=False):
            try:
                tube = yarn.mesh(self.samples_per_mm, within, self.path_sagitta_mm)
            except WeaveError as exc:
                hint = "" if self.distortion.is_zero else (
                    f" (distortion seed {self.seed}: lower the {yarn.family}'s node displacement, section scale or "
                    "the waviness, or try another seed)")
                raise WeaveError(f"yarn {yarn.name}: {exc}{hint}") from None
            cut = to_manifold(tube, yarn.name) ^ clip
            length = hi[0] - lo[0] if yarn.family == "weft" else hi[1] - lo[1]
            if cut.volume() >= REMNANT_FRACTION * polygon_area(yarn.outline) * length:
                out.append((yarn, from_manifold(cut)))
        return out

    def parts(self, materials=None, *, per: str = "yarn", resolve: str = "priority", measure: bool = True,
              progress: bool = False, binder_label: bool = False) -> tuple[list[MeshPart], dict]:
        """The sample's objects (:class:`~xrayraster.weave.export.MeshPart`), and facts about its yarns.

        ``materials`` as for :meth:`scene`. ``per="yarn"``: the matrix and one part per yarn;
        ``"family"``: the matrix, the wefts, the warps (each family one mesh, the union of its yarns)
        and one part per tracer yarn (tracers come last, so they win priority ties). ``resolve="boolean"``
        makes every mesh disjoint, higher priority keeping shared space (per yarn
        :func:`~xrayraster.weave.resolve.resolve_boolean`, per family
        :func:`~xrayraster.weave.export.settle`), the matrix the box minus the yarns; ``"priority"``
        leaves the overlaps to the scene's priorities. The dict gives ``yarns``, the yarns in the
        sample by kind (clipped remnants left out), ``tracers`` (their names), and ``interpenetration_mm3``: the volume between
        yarns ``before`` and ``after`` resolving (``after`` None for ``"priority"``); with
        ``measure=False`` that is empty unless the per-yarn boolean measured it anyway (a scan needs none).
        ``binder_label``: the binders labelled as a class of their own (``LABELS["binder"]``, a part of
        their own per family), the stuffers staying warp; their material and priority the warp's.
        The matrix voids (:meth:`void_meshes`) follow the yarns, one part each (``per="yarn"``) or one
        ``void`` part, and the dict's ``voids`` gives their count, volume and share of the box.
        """
        check_choice(per, EXPORT_PER, "per", WeaveError)
        check_choice(resolve, WEAVE_RESOLVE, "resolve", WeaveError)
        plan(WeaveJob(self, resolve, export=False), WeaveError)  # the boolean's pairs hold far more
        family_materials, tracers = self._materials(materials)
        family_materials = {**family_materials, "binder": family_materials["warp"], "void": Material.named("air")}
        if not self.voids.is_zero and resolve == "boolean":
            raise WeaveError("voids with resolve=\"boolean\" are not made: use resolve=\"priority\" (the scene's "
                             "priorities give a void the matrix's space)")
        pieces = self.meshes(progress)
        voids = self.void_meshes(pieces, progress)

        def labelled(yarn) -> str:  # the family a yarn is labelled as
            return "binder" if binder_label and yarn.kind == "binder" else yarn.family

        matrix = self.matrix_mesh()
        if per == "yarn" and resolve == "boolean":
            _stage(progress, "resolving every yarn pair (boolean)")
            resolved = resolve_boolean(pieces, self.box, measure_after=False)  # excess is exact and cheap
            matrix = resolved.matrix
            objects = [(yarn.name, labelled(yarn), mesh) for yarn, mesh in resolved.pieces]
            overlap = {"before": resolved.before.volume, "after": max(resolved.excess, 0.0),
                       "dropped_yarns": list(resolved.dropped)}
        else:
            _stage(progress and measure, "measuring the interpenetration of the yarns")
            overlap = {"before": interpenetration(pieces).volume, "after": None} if measure else {}
            objects = [(yarn.name, labelled(yarn), mesh) for yarn, mesh in pieces
                       if per == "yarn" or yarn.name in tracers]
            if per == "family":
                _stage(progress, "merging each family's yarns")
                groups = ("weft", "warp", "binder") if binder_label else ("weft", "warp")
                merged = [(f, [m for y, m in pieces if labelled(y) == f and y.name not in tracers]) for f in groups]
                objects = [(f, f, merge_meshes(meshes)) for f, meshes in merged if meshes] + objects
            if voids:
                objects += ([("void", "void", merge_meshes(voids))] if per == "family"
                            else [(f"void_{k}", "void", mesh) for k, mesh in enumerate(voids)])
            if resolve == "boolean":  # a few parts: settled here, without touching shells inside a family
                objects, matrix, after = settle(objects, PRIORITIES, self.box)
                overlap.update({"after": after} if measure else {})
        parts = [MeshPart("matrix", "matrix", family_materials["matrix"], LABELS["matrix"], PRIORITIES["matrix"],
                          matrix)]
        for name, family, mesh in objects:
            material, label = tracers.get(name, (family_materials[family], None))
            parts.append(MeshPart(name, family, material, LABELS[family] if label is None else label,
                              PRIORITIES[family], mesh))
        kinds = [yarn.kind for yarn, _ in pieces]
        listed = ("weft", "warp") if FAMILIES[self.cell.family].plies else ("weft", "binder", "stuffer")
        yarns = {kind: kinds.count(kind) for kind in listed}
        facts = {"yarns": {**yarns, "total": len(kinds)}, "tracers": sorted(tracers), "interpenetration_mm3": overlap}
        if voids:
            facts["voids"] = {"count": len(voids), "volume_mm3": float(sum(mesh.volume for mesh in voids)),
                              "volume_fraction": float(sum(mesh.volume for mesh in voids) / np.prod(np.diff(self.box, axis=0)))}
        return parts, facts

    def void_meshes(self, pieces, progress: bool = False) -> list[trimesh.Trimesh]:
        """The sample's matrix voids (:mod:`~xrayraster.weave.voids`), drawn from its seed inside the
        matrix box, avoiding ``pieces`` (:meth:`meshes`) unless their placement is ``"anywhere"``;
        ``"between_yarns"`` centres them between the outermost margins (``margin_z`` above the bottom,
        below the top)."""
        if self.voids.is_zero:
            return []
        _stage(progress, "drawing the matrix voids")
        centres = self.box.copy()
        if self.voids.placement == "between_yarns":
            centres[:, :2] = self.yarn_box[:, :2]
            centres[:, 2] += (self.cell.margin_z, -self.cell.margin_z)
        try:
            return draw_voids(self.voids, self.box, centres, pieces, yarn_rng(self.seed, "voids"))
        except WeaveError as exc:
            raise WeaveError(f"{exc} (seed {self.seed})") from None

    def scene(self, materials=None, *, resolve: str = "priority", per: str = "yarn", transform=None,
              progress: bool = False, binder_label: bool = False) -> Scene:
        """An ``xr.Scene``: the matrix box (label 1, priority 0), wefts (2, 1) and warps (3, 2), and
        the matrix voids (5, 0.5: air) where :attr:`voids` draws any.

        ``materials``: a :class:`~xrayraster.weave.materials.YarnMaterials`, None for its defaults
        (epoxy, and carbon-fibre bundles at fibre volume fraction 0.6), or a dict of its
        ``matrix``/``weft``/``warp`` fields. A tracer yarn takes its own material and keeps its
        family's priority, and its family's label unless the tracer gives one. ``resolve`` and ``per``
        as for :meth:`parts` (scanning needs no boolean: the priorities settle shared space exactly);
        ``transform`` (an ``xr.Transform``) places every object in the scanner frame; ``binder_label``:
        the binders as a class of their own (label 4, :meth:`parts`).
        """
        scene = Scene()
        for part in self.parts(materials, per=per, resolve=resolve, measure=False, progress=progress,
                               binder_label=binder_label)[0]:
            scene.add(part.mesh, part.material, label=part.label, priority=part.priority, name=part.name,
                      transform=transform)
        return scene

    def export(self, directory, *, materials=None, per: str = "family", fmt: str = "stl",
               resolve: str = "priority", progress: bool = False, overwrite: bool = False) -> dict:
        """Write the meshes (one ``<part>.<fmt>`` file per :meth:`parts` entry, ``fmt`` "stl" or
        "ply") and ``report.json`` into ``directory``; returns the report (:meth:`exported`).

        The directory is built beside ``directory`` and moved into place whole
        (:func:`~xrayraster.core.files.atomic_directory`; ``report.json`` records the names written):
        an existing ``directory`` is replaced only if it holds nothing but an earlier export, else
        :class:`~xrayraster.ConfigError` before any work; ``overwrite=True`` then replaces the earlier
        export's files and keeps every other entry.
        """
        with atomic_directory(directory, marker=REPORT_NAME, generator=GENERATOR, overwrite=overwrite) as tmp:
            parts, report = self.exported(materials, per=per, fmt=fmt, resolve=resolve, progress=progress)
            _stage(progress, f"writing {len(parts)} mesh files")
            write_parts(parts, tmp, fmt)
            write_report(report, tmp)
        return report

    def exported(self, materials=None, *, per: str = "family", fmt: str = "stl", resolve: str = "priority",
                 progress: bool = False) -> tuple[list[MeshPart], dict]:
        """What :meth:`export` writes, in memory: the parts (one mesh file each) and the report
        (:func:`~xrayraster.weave.export.export_report`, with the seconds it took)."""
        check_choice(fmt, MESH_FORMATS, "format", WeaveError)
        start = time.perf_counter()
        parts, facts = self.parts(materials, per=per, resolve=resolve, progress=progress)
        _stage(progress, "measuring the families' volumes")
        settings = {"cell": self.cell.to_dict(), "cells": list(self.cells), "layers_of_cells": self.layers_of_cells,
                    "points_per_section": self.points_per_section, "samples_per_mm": self.samples_per_mm,
                    "seed": self.seed, "distortion": self.distortion.to_dict(),
                    **({} if self.voids.is_zero else {"voids": self.voids.to_dict()})}
        report = export_report(parts, facts, settings, self.box, resolve=resolve, per=per, fmt=fmt)
        report["seconds"] = round(time.perf_counter() - start, 3)
        return parts, report

    def _materials(self, materials) -> tuple[dict, dict]:
        """(family → Material, tracer yarn → (Material, label or None)), tracer names checked."""
        chosen = as_yarn_materials(materials)
        tracers = chosen.tracer_materials()
        names = [yarn.name for yarn in self.yarns()]
        missing = sorted(set(tracers) - set(names))
        if missing:
            raise WeaveError(f"tracers: no yarn named {', '.join(map(repr, missing))} in this sample; name one "
                             f"as Sample.yarns() does, e.g. {names[0]!r} or {names[-1]!r}")
        return chosen.resolve(), tracers
