"""The yarns of a :class:`~xrayraster.weave.sample.Sample`: each one centre line of nodes across the
whole sample and its outline (module docstring of :mod:`~xrayraster.weave.sample`): the regular
weave's, a distorted one's (each yarn moved by its own draws), and a 2D weave's plies."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .distort import layer_shift, yarn_draws, yarn_rng
from .families import FAMILIES
from .plies import NODES_PER_CROSSING, ply_paths
from .yarn import Yarn, section_outline

if TYPE_CHECKING:
    from .sample import Sample

#: Binder nodes per weft column, as offsets along y in units of the weft's half-width from the
#: column's centre, all at the column's gap height: the binder runs flat over/under the middle half
#: of each weft and turns to the next gap between wefts. A single node per column let the C² spline
#: overshoot a step-shaped gap sequence by up to 0.23 mm (default cell); this double pair (a short
#: last interval at each plateau edge keeps the spline from bulging there) brings it to 4e-4 mm
#: (0.13 % of the binder height) with a smallest bend radius of 0.43 mm (default cell).
PLATEAU = (-0.5, -0.45, 0.45, 0.5)

_FLAT = ((0.0, 1.0, 0.0), (0.0, 1.0, 0.0))  # a binder's clamped end tangents: flat, along +y


def _node_columns(count: int, spacing: float, shift: float) -> np.ndarray:
    """Node indices i (node at ``(i + 0.5) · spacing + shift``) from at least half a ``spacing``
    before 0 to half a spacing past ``count · spacing``: the path's ends lie outside the box."""
    return np.arange(math.floor(-1 - shift / spacing), math.ceil(count - shift / spacing) + 1)


def sample_yarns(sample: Sample) -> list[Yarn]:
    """:meth:`Sample.yarns <xrayraster.weave.sample.Sample.yarns>`."""
    if FAMILIES[sample.cell.family].plies:
        return _ply_yarns(sample)
    if sample.distortion.is_zero:
        return _regular_yarns(sample)
    return _distorted_yarns(sample)


def _outlines(sample: Sample) -> tuple[np.ndarray, np.ndarray]:
    c, k = sample.cell, sample.points_per_section
    return (section_outline(c.weft_section, c.weft_width, c.weft_height, k),
            section_outline(c.warp_section, c.warp_width, c.warp_height, k))


def _binder_nodes(sample: Sample, x: float, path, columns: np.ndarray, z0: float) -> np.ndarray:
    """A binder's plateau nodes (see PLATEAU) at ``x`` over weft ``columns`` (counted over all cells),
    at the heights its family gives them (:meth:`~xrayraster.weave.families.Family.node_heights`)."""
    c = sample.cell
    offsets = np.asarray(sample.plateau) * (c.weft_width / 2)
    ys = ((columns + 0.5) * c.weft_spacing)[:, None] + offsets[None, :]
    zs = FAMILIES[c.family].node_heights(path, columns, offsets, c.weft_spacing, c.gap_z)
    return np.column_stack([np.full(ys.size, x), ys.ravel(), zs.ravel() + z0])


def _regular_yarns(sample: Sample) -> list[Yarn]:
    c = sample.cell
    sx, sy, sz = c.size
    nx, ny = sample.cells
    nz = sample.layers_of_cells
    x_end = nx * sx
    weft, warp = _outlines(sample)
    out: list[Yarn] = []
    for cz in range(nz):
        for layer, z in enumerate(c.weft_layer_z):
            for cy in range(ny):
                for j, y in enumerate(c.weft_y):
                    nodes = np.array([[-sample.extend, cy * sy + y, cz * sz + z],
                                      [x_end + sample.extend, cy * sy + y, cz * sz + z]])
                    out.append(Yarn(f"weft_c{cz}_l{layer}_y{cy * c.weft_per_layer + j}", "weft", "weft",
                                    nodes, weft))
    # one periodic weft column past each end of the sample
    columns = np.arange(-1, ny * c.weft_per_layer + 1)
    for cz in range(nz):
        for cx in range(nx):
            for b, (x, path) in enumerate(zip(c.binder_x, c.binder_path)):
                nodes = _binder_nodes(sample, cx * sx + x, path, columns, cz * sz)
                out.append(Yarn(f"binder_c{cz}_x{cx}_b{b}", "warp", "binder", nodes, warp, _FLAT))
            for s, x in enumerate(c.stuffer_x):
                for g in c.stuffer_gaps:
                    z = c.gap_z(g) + cz * sz
                    nodes = np.array([[cx * sx + x, -sample.extend, z], [cx * sx + x, ny * sy + sample.extend, z]])
                    out.append(Yarn(f"stuffer_c{cz}_x{cx}_s{s}_g{g}", "warp", "stuffer", nodes, warp))
    return out


def _distorted_yarns(sample: Sample) -> list[Yarn]:
    c, d = sample.cell, sample.distortion
    sx, _, sz = c.size
    nx, ny = sample.cells
    w = c.weft_per_layer
    nz = sample.layers_of_cells
    weft, warp = _outlines(sample)
    shifts = [layer_shift(d, sample.seed, cz) for cz in range(nz)]
    out: list[Yarn] = []
    for cz, (dx, dy) in enumerate(shifts):
        # a weft node at every warp column crossing, reaching at least half a spacing past both x faces
        xs = (_node_columns(nx * c.warp_columns, c.warp_spacing, dx) + 0.5) * c.warp_spacing + dx
        for layer, z in enumerate(c.weft_layer_z):
            for jy in range(-w, (ny + 1) * w):  # one extra period on each side
                y = (jy + 0.5) * c.weft_spacing + dy
                if _reaches(sample, y, 1, weft, "weft"):
                    nodes = np.column_stack([xs, np.full(len(xs), y), np.full(len(xs), cz * sz + z)])
                    out.append(_distorted(sample, f"weft_c{cz}_l{layer}_y{jy}", "weft", nodes, weft))
    for cz, (dx, dy) in enumerate(shifts):
        columns = _node_columns(ny * w, c.weft_spacing, dy)
        for cx in range(-1, nx + 1):
            for b, (x, path) in enumerate(zip(c.binder_x, c.binder_path)):
                if _reaches(sample, cx * sx + x + dx, 0, warp, "warp"):
                    nodes = _binder_nodes(sample, cx * sx + x, path, columns, cz * sz) + [dx, dy, 0.0]
                    out.append(_distorted(sample, f"binder_c{cz}_x{cx}_b{b}", "binder", nodes, warp, _FLAT))
            for s, x in enumerate(c.stuffer_x):
                if _reaches(sample, cx * sx + x + dx, 0, warp, "warp"):
                    for g in c.stuffer_gaps:
                        nodes = np.column_stack([np.full(len(columns), cx * sx + x + dx),
                                                 (columns + 0.5) * c.weft_spacing + dy,
                                                 np.full(len(columns), cz * sz + c.gap_z(g))])
                        out.append(_distorted(sample, f"stuffer_c{cz}_x{cx}_s{s}_g{g}", "stuffer", nodes, warp))
    return out


def _ply_yarns(sample: Sample) -> list[Yarn]:
    """A 2D weave's warps and wefts (:mod:`~xrayraster.weave.plies`), their nodes moved by the
    distortion's draws and each layer of cells by its shift, as the 3D families' are."""
    d, regular = sample.distortion, sample.distortion.is_zero
    shifts = [(0.0, 0.0) if regular else layer_shift(d, sample.seed, cz) for cz in range(sample.layers_of_cells)]
    outlines = dict(zip(("weft", "warp"), _outlines(sample)))

    def reaches(centre: float, axis: int, family: str) -> bool:
        return _reaches(sample, centre, axis, outlines[family], family)

    return [Yarn(name, family, family, nodes, outlines[family], ends) if regular
            else _distorted_ply(sample, name, family, nodes, outlines[family], ends)
            for name, family, nodes, ends in ply_paths(sample.cell, sample.cells, sample.layers_of_cells, shifts,
                                                       reaches)]


def _distorted_ply(sample: Sample, name: str, family: str, nodes: np.ndarray, outline: np.ndarray, ends) -> Yarn:
    """A 2D weave's yarn ``name`` with its crossings moved by its draws, the nodes between two
    crossings by the draws eased linearly from one to the next."""
    crossings = np.arange(0, len(nodes), NODES_PER_CROSSING)
    axial = nodes[crossings, 0 if family == "weft" else 1]
    move, scale, rotation = yarn_draws(sample.distortion, family, yarn_rng(sample.seed, name), axial)
    every = np.arange(len(nodes))

    def spread(values: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(every, crossings, v) for v in values.reshape(len(crossings), -1).T], axis=1)

    varies = sample.distortion.varies_section(family)
    return Yarn(name, family, family, nodes + spread(move), outline, ends, spread(scale) if varies else None,
                spread(rotation)[:, 0] if varies else None)


def _reaches(sample: Sample, centre: float, axis: int, outline: np.ndarray, family: str) -> bool:
    """Whether a yarn whose regular centre line lies at ``centre`` (mm, along ``axis``) can reach the box."""
    d = sample.distortion
    reach = (float(np.max(np.linalg.norm(outline, axis=1))) * (1 + max(getattr(d, f"{family}_scale")))
             + getattr(d, f"{family}_node_mm")[axis] + d.waviness_mm)
    lo, hi = sample.yarn_box[:, axis]
    return centre + reach > lo and centre - reach < hi


def _distorted(sample: Sample, name: str, kind: str, nodes: np.ndarray, outline: np.ndarray, end_tangents=None) -> Yarn:
    """The yarn ``name`` with its nodes moved by its draws; a binder's plateaus move as one."""
    family = "weft" if kind == "weft" else "warp"
    group = len(PLATEAU) if kind == "binder" else 1
    groups = nodes.reshape(-1, group, 3)
    axial = groups[:, :, 0 if family == "weft" else 1].mean(axis=1)
    move, scale, rotation = yarn_draws(sample.distortion, family, yarn_rng(sample.seed, name), axial)
    varies = sample.distortion.varies_section(family)
    return Yarn(name, family, kind, (groups + move[:, None, :]).reshape(-1, 3), outline, end_tangents,
                np.repeat(scale, group, axis=0) if varies else None,
                np.repeat(rotation, group) if varies else None)
