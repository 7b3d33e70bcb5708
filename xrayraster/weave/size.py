"""A woven sample's size before it is meshed: its triangles, the memory and time they take.

Every yarn's tube has ``2 × points_per_section`` triangles a ring, and its rings come at about
``samples_per_mm`` a mm (dense in the binders' bends, sparse along straight yarns: the adaptive
spacing of :func:`~xrayraster.weave.sweep.adaptive_params`), so the sample has about
``TRIANGLES_PER_RING_MM × 2 · points_per_section · samples_per_mm`` triangles per mm of yarn, and its
yarn length is the cells' (wefts along x, warps along y) times the cells and layers of cells.

Every key that multiplies that count is in :class:`Size`: the yarns of a cell (``weft_per_layer``,
``weft_layers``, ``warp_positions``, ``binders``, ``stuffers``), their lengths (the spacings), the
repeats (``cells``, ``layers_of_cells``) and the mesh (``points_per_section``, ``samples_per_mm``).
A :class:`Size` is known from a ``[weave]`` table's checked values before the cell is built (building
it generates every binder's path, ``binders × weft_per_layer`` gaps), so a file asking for a sample
that cannot fit is refused before any of that work, naming the key that makes it large: the jobs
:class:`WeaveJob` (meshing, exporting) and :class:`BendSearch` go through
:func:`~xrayraster.core.estimate.plan`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..core.estimate import Estimate, Part
from .families import FAMILIES, PLIES, WARP_POSITIONS, WEFT_LAYERS
from .patterns import level_changes
from .spec import UnitCell

#: Triangles per (points of a section × samples per mm × mm of yarn): measured 0.38–0.62 on the
#: default cell (1 × 1 to 3 × 3 cells, 12–24 points, 2–8 samples a mm, with and without distortion).
TRIANGLES_PER_POINT_SAMPLE_MM = 0.5
#: And per share of a 2D pattern's steps where a yarn changes level (:func:`~xrayraster.weave.patterns.level_changes`),
#: whose bends keep its samples dense: measured 1.6–2.0 plain, 1.5–1.7 (2/2 twill), 0.8–0.95 (5-harness
#: satin) in all at 12–24 points and 2–4 samples a mm, 1 × 1 cells of 2 plies.
TRIANGLES_PER_LEVEL_CHANGE = 1.5
#: Bytes a triangle holds: while the sample is meshed for a scene (the tubes, their clipped copies,
#: the scene's; ~360 B from the twin's scan, pipeline/plan.py), while ``xrayraster weave`` exports it
#: with overlaps left to priorities (the interpenetration measured and each family merged: 1.6 KB
#: measured at 6 × 6 cells, 602 k triangles, 1,063 MiB peak), and with ``resolve="boolean"`` (every
#: pair's boolean: ~2.1 KB at 8 × 8 cells, 2,316 MiB, BENCHMARKS.md bench_weave), rounded up.
BYTES_PER_TRIANGLE = {"meshes": 400, "priority": 1600, "boolean": 2500}
#: Seconds a triangle takes to sweep and clip (1.2e-5 to 4.5e-5 measured under load on 1 × 1 to
#: 3 × 3 cells, 7e-6 at 8 × 8), and the factor of a whole ``xrayraster weave`` export on top
#: (6 × 6 cells under load: 46 s, 7.6e-5 a triangle; booleans: 50 s for 8 × 8 cells, bench_weave).
SECONDS_PER_TRIANGLE = 1.5e-5
EXPORT_FACTOR = {"meshes": 1.0, "priority": 5.0, "boolean": 7.0}
#: The search for the binders' tightest bend (a scan file that leaves the mesh knobs to its grid,
#: :func:`~xrayraster.weave.tessellation.resolution_for`) evaluates every binder of one cell at 64
#: points per node (a node per weft column): measured 146 and 136 B and 1.8 and 2.4 µs a point at
#: 2 and 20 thousand weft columns (299 MiB in 3.7 s, 2.8 GiB in 50 s).
BEND_SEARCH_POINTS_PER_NODE = 64
BYTES_PER_BEND_POINT = 150
SECONDS_PER_BEND_POINT = 2.5e-6

#: The keys a sample's size grows with, by the table that holds them.
CELL_KEYS = ("weft_per_layer", "weft_layers", "warp_positions", "binders", "stuffers", "weft_spacing", "warp_spacing")
SAMPLE_KEYS = ("cells", "layers_of_cells", "points_per_section", "samples_per_mm")
#: The keys that lay the cell's warp columns out and set its defaults (not multipliers themselves).
LAYOUT_KEYS = ("family", "warp_ratio", "binder_ratio")
#: :class:`~xrayraster.weave.Sample`'s defaults of :data:`SAMPLE_KEYS`, kept here (Sample takes them
#: from here) so a size is planned without importing the module that meshes.
SAMPLE_DEFAULTS = {"cells": (1, 1), "layers_of_cells": 1, "points_per_section": 24, "samples_per_mm": 4.0}
#: What to change, for the key that makes a sample too large.
_FIXES = {
    "cells": "use fewer cells (or layers_of_cells)",
    "layers_of_cells": "use fewer cells (or layers_of_cells)",
    "weft_per_layer": "use fewer weft yarns (weft_per_layer, weft_layers)",
    "weft_layers": "use fewer weft yarns (weft_per_layer, weft_layers or plies)",
    "warp_positions": "use fewer warp yarns (warp_positions, binders, stuffers)",
    "binders": "use fewer warp yarns (warp_positions, binders, stuffers)",
    "stuffers": "use fewer warp yarns (warp_positions, binders, stuffers)",
    "weft_spacing": "use a smaller cell (weft_spacing, warp_spacing)",
    "warp_spacing": "use a smaller cell (weft_spacing, warp_spacing)",
}
_COARSER = "a coarser mesh (points_per_section, samples_per_mm)"


@dataclass(frozen=True)
class Size:
    """The keys of a ``[weave]`` table (:data:`CELL_KEYS`) and of its ``[weave.sample]``
    (:data:`SAMPLE_KEYS`) that a woven sample's triangles grow with, and the layout of its warp
    columns (:data:`LAYOUT_KEYS`); ``binders`` None: generated, as the family makes them
    (:class:`~xrayraster.weave.UnitCell`)."""

    weft_per_layer: int
    weft_layers: int
    warp_positions: int
    binders: int | None
    stuffers: int
    weft_spacing: float
    warp_spacing: float
    cells: tuple[int, int]
    layers_of_cells: int
    points_per_section: int
    samples_per_mm: float
    family: str = "layer_to_layer"
    warp_ratio: int = 1
    binder_ratio: int = 1
    level_changes: float = 0.0  # a 2D pattern's (patterns.level_changes); 0 in a 3D cell

    @classmethod
    def of(cls, sample) -> "Size":
        """The size of a built :class:`~xrayraster.weave.Sample` (or of a :class:`Size`, as it is)."""
        if isinstance(sample, Size):
            return sample
        cell = sample.cell
        return cls(**{k: getattr(cell, k) for k in (*CELL_KEYS, *LAYOUT_KEYS)},
                   **{k: getattr(sample, k) for k in SAMPLE_KEYS},
                   level_changes=level_changes(cell.pattern) if cell.pattern else 0.0)

    @classmethod
    def planned(cls, cell: dict, sample: dict) -> "Size":
        """The size of the sample that ``UnitCell(**cell)`` and ``Sample(cell, **sample)`` would make,
        without making them: keys left out take those classes' defaults, the family's where it has
        its own (other keys are ignored)."""
        defaults = {**{f.name: f.default for f in dataclasses.fields(UnitCell)}, **SAMPLE_DEFAULTS}
        given = {k: v for k, v in {**defaults, **cell, **sample}.items() if v is not None}
        family = FAMILIES[given["family"]]
        if family.plies:  # a warp per pattern row and a weft per column in each ply, no stuffers
            pattern = family.pattern(given.get("pattern"), given.get("floats"), given.get("harness"))
            given.update(warp_positions=len(pattern), weft_per_layer=len(pattern[0]),
                         weft_layers=given.get("plies", PLIES), stuffers=0, level_changes=level_changes(pattern))
        else:
            n = given.setdefault("weft_layers", WEFT_LAYERS)
            given.setdefault("warp_positions", WARP_POSITIONS)
            given.setdefault("weft_per_layer", family.default_weft_per_layer(n, given.get("binder_step") or 1))
            given.setdefault("stuffers", family.default_stuffers(n))
        given.setdefault("warp_ratio", 1)
        given.setdefault("binder_ratio", 1)
        return cls(**{k: given.get(k) for k in (*CELL_KEYS, *SAMPLE_KEYS, *LAYOUT_KEYS)},
                   level_changes=given.get("level_changes", 0.0))

    @property
    def binder_count(self) -> int:
        return FAMILIES[self.family].binder_count(self.warp_positions, self.weft_layers) if self.binders is None \
            else self.binders

    @property
    def stuffer_columns(self) -> int:
        """``warp_ratio`` after each group of ``binder_ratio`` binder positions, where there are stuffers."""
        return self.warp_positions // self.binder_ratio * self.warp_ratio if self.stuffers else 0

    @property
    def yarns_per_cell(self) -> int:
        """Wefts (a row of ``weft_per_layer`` in each weft layer, a ply's one) and warps (binders, a
        ply's warps, and stuffers)."""
        return self.weft_layers * self.weft_per_layer + self.binder_count + self.stuffer_columns * self.stuffers

    def yarn_length_mm(self) -> float:
        """The yarns' summed length (mm) along their runs: wefts along x, warps along y."""
        columns = self.warp_positions + self.stuffer_columns
        cell_x, cell_y = columns * self.warp_spacing, self.weft_per_layer * self.weft_spacing
        wefts = self.weft_layers * self.weft_per_layer
        warps = self.binder_count + self.stuffer_columns * self.stuffers
        nx, ny = self.cells
        return self.layers_of_cells * nx * ny * (wefts * cell_x + warps * cell_y)

    def triangles(self) -> int:
        """About how many triangles the sample's yarns will have (module docstring)."""
        per = TRIANGLES_PER_POINT_SAMPLE_MM + TRIANGLES_PER_LEVEL_CHANGE * self.level_changes
        return int(per * self.points_per_section * self.samples_per_mm * self.yarn_length_mm())

    def largest_key(self) -> str:
        """The key furthest above its default (by the factor it multiplies the triangles with; the
        first of :data:`SAMPLE_KEYS` then :data:`CELL_KEYS` on a tie): the one to name in a refusal."""
        default = Size.planned({}, {})
        order = ("cells", "layers_of_cells", *CELL_KEYS, "points_per_section", "samples_per_mm")
        return max(order, key=lambda key: _factor(self, key) / _factor(default, key))

    def key_text(self, key: str, tables: bool) -> str:
        """``key = value`` as a file gives it, after its table (``[weave]``, ``[weave.sample]``) if ``tables``
        (a 2D family's weft layers are its ``plies``, its warps its pattern's rows)."""
        if FAMILIES[self.family].plies:
            key = {"weft_layers": "plies", "binders": "warp_positions"}.get(key, key)
        value = getattr(self, key if key != "plies" else "weft_layers") if key != "binders" else self.binder_count
        table = ("[weave.sample] " if key in SAMPLE_KEYS else "[weave] ") if tables else ""
        return f"{table}{key} = {list(value) if key == 'cells' else value}"


def _factor(size: Size, key: str) -> float:
    """How much ``key`` multiplies ``size``'s triangles by (up to a constant)."""
    if key == "cells":
        return size.cells[0] * size.cells[1]
    if key == "binders":  # a 2D family's warps are its pattern's rows in every ply: plies name that
        return size.warp_positions if FAMILIES[size.family].plies else size.binder_count
    if key == "stuffers":
        return 1 + size.stuffers
    return float(getattr(size, key))


def yarn_length_mm(sample) -> float:
    """The sample's (a :class:`~xrayraster.weave.Sample` or a :class:`Size`) yarns' summed length, mm."""
    return Size.of(sample).yarn_length_mm()


def estimated_triangles(sample) -> int:
    """About how many triangles the sample's yarns will have (module docstring), before meshing."""
    return Size.of(sample).triangles()


def mesh_part(sample, bytes_per_triangle: int = BYTES_PER_TRIANGLE["meshes"], tables: bool = False) -> Part:
    """The sample's meshes as a part of a job's memory, named after the key that makes them largest
    (:meth:`Size.largest_key`; after its table when ``tables``, as a file's errors name it)."""
    size = Size.of(sample)
    triangles, key = size.triangles(), size.largest_key()
    fix = f"{_FIXES[key]} or {_COARSER}" if key in _FIXES else f"use {_COARSER} or fewer cells (or layers_of_cells)"
    return Part(f"meshes of ~{triangles:.2g} triangles from {size.yarns_per_cell} yarns a cell",
                triangles * bytes_per_triangle, size.key_text(key, tables), fix)


@dataclass(frozen=True)
class WeaveJob:
    """Meshing a sample (``size``: its :class:`Size`, or a :class:`~xrayraster.weave.Sample`, taken as
    its size) with overlaps left to priorities or resolved by booleans (``resolve``); ``export``: and
    measuring and writing it, as ``xrayraster weave`` does. ``tables``: the key in a refusal after
    its table, as in a file. A :class:`~xrayraster.core.estimate.Planned` job."""

    size: Size
    resolve: str = "priority"
    export: bool = True
    tables: bool = False

    def __post_init__(self):
        object.__setattr__(self, "size", Size.of(self.size))  # a job holds sizes, never a built sample

    def estimate(self) -> Estimate:
        size = self.size
        stage = self.resolve if self.export or self.resolve == "boolean" else "meshes"
        seconds = size.triangles() * SECONDS_PER_TRIANGLE * EXPORT_FACTOR[stage]
        nx, ny = size.cells
        return Estimate(f"woven sample of {nx} × {ny} × {size.layers_of_cells} cells", seconds,
                        (mesh_part(size, BYTES_PER_TRIANGLE[stage], self.tables),))


@dataclass(frozen=True)
class BendSearch:
    """Finding the binders' tightest bend of a sample's cell (``size``: a :class:`Size` or a
    :class:`~xrayraster.weave.Sample`), the search a scan file's grid makes to choose the mesh knobs
    it leaves out: every binder at :data:`BEND_SEARCH_POINTS_PER_NODE` points per weft column (and
    the two ends' nodes). ``tables``: the key in a refusal after its table. A
    :class:`~xrayraster.core.estimate.Planned` job."""

    size: Size
    tables: bool = True

    def __post_init__(self):
        object.__setattr__(self, "size", Size.of(self.size))  # a job holds sizes, never a built sample

    def estimate(self) -> Estimate:
        size = self.size
        points = size.binder_count * (size.weft_per_layer + 2) * BEND_SEARCH_POINTS_PER_NODE
        key = f"{size.key_text('weft_per_layer', self.tables)}, binders = {size.binder_count}"
        part = Part(f"{points:.2g} points along the binders", points * BYTES_PER_BEND_POINT, key,
                    "use fewer weft columns or binders, or give points_per_section and samples_per_mm in "
                    "[weave.sample] (then no bend is searched for)")
        return Estimate("search for the binders' tightest bend", points * SECONDS_PER_BEND_POINT, (part,))
