"""The yarn paths of a 2D weave's plies (:mod:`~xrayraster.weave.families`: plain, twill, satin).

In ply ``k`` (mid-plane ``z_k``, shifted in-plane by ``k · ply_shift_mm`` and, distorted, by its
cells' layer shift), warp ``i`` runs along y with a node at every weft crossing ``j``: at
``z_k + weft_height / 2`` where the pattern has the warp over the weft, ``z_k − weft_height / 2``
where under; weft ``j`` runs along x with a node at every warp crossing, ``z_k ∓ warp_height / 2``
the other way round. So at a crossing the two yarns stack face to face, filling the ply's
thickness. Between two crossings the path follows TexGen's 2D weave (its in-plane tangents): level
at each crossing, ``z`` a smoothstep ``3t² − 2t³`` from one crossing's height to the next, so a
yarn that floats over several crossings stays at one height. The sample's C² spline runs through
:data:`NODES_PER_CROSSING` nodes a crossing on that curve: for a plain weave it keeps to the curve
within 0.5 % of the yarn's swing (its speed along the yarn is the chord length's, not the axis's),
and over a twill's or satin's floats within 2 % of the float's height, where one node a crossing
rose 37.5 % above it (tests/weave/test_weave_families.py).

Paths reach one crossing past the box on each side (clamped level there), and every yarn whose
tube can reach the box is listed, so a shifted ply's yarns that straddle a side face are there to
be clipped.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from .spec import UnitCell

__all__ = ["NODES_PER_CROSSING", "ply_paths"]

#: Nodes of a path per crossing: the crossing's, then points a quarter, a half and three quarters
#: of the way to the next one (measured above).
NODES_PER_CROSSING = 4

#: A warp's and a weft's clamped end tangents: level, along the yarn.
WARP_ENDS = ((0.0, 1.0, 0.0), (0.0, 1.0, 0.0))
WEFT_ENDS = ((1.0, 0.0, 0.0), (1.0, 0.0, 0.0))


def ply_paths(cell: UnitCell, cells: tuple[int, int], layers_of_cells: int, shifts: list[tuple[float, float]],
              reaches: Callable[[float, int, str], bool]) -> Iterator[tuple[str, str, np.ndarray, tuple]]:
    """``(name, family, nodes, end tangents)`` of every yarn of the sample, wefts first then warps,
    each ply bottom to top. ``shifts``: each layer of cells' in-plane shift (mm); ``reaches(centre,
    axis, family)``: whether a yarn whose centre line lies at ``centre`` (mm, along ``axis``) can reach
    the box."""
    nx, ny = cells
    sx, sy, sz = cell.size
    warps, wefts = cell.warp_positions, cell.weft_per_layer
    pattern = np.array(cell.pattern, bool)  # [warp, weft]: the warp over the weft
    plies = [(cz, k, cz * sz + cell.ply_z(k), np.asarray(shift) + k * np.asarray(cell.ply_shift_mm))
             for cz, shift in enumerate(shifts) for k in range(cell.plies)]
    out = {"weft": [], "warp": []}
    for cz, k, z, (dx, dy) in plies:
        warp_x = _centres(cell.warp_spacing, dx, nx * sx)
        weft_y = _centres(cell.weft_spacing, dy, ny * sy)
        xs, ys = (warp_x + 0.5) * cell.warp_spacing + dx, (weft_y + 0.5) * cell.weft_spacing + dy
        for j, y in zip(weft_y, ys):
            if reaches(y, 1, "weft"):
                over = pattern[warp_x % warps, j % wefts]  # the warps over this weft: it runs under them
                along, zs = level_path(xs, z + np.where(over, -0.5, 0.5) * cell.warp_height)
                out["weft"].append((f"weft_c{cz}_p{k}_y{j}", "weft",
                                    np.column_stack([along, np.full(len(along), y), zs]), WEFT_ENDS))
        for i, x in zip(warp_x, xs):
            if reaches(x, 0, "warp"):
                along, zs = level_path(ys, z + np.where(pattern[i % warps, weft_y % wefts], 0.5, -0.5) * cell.weft_height)
                out["warp"].append((f"warp_c{cz}_p{k}_x{i}", "warp",
                                    np.column_stack([np.full(len(along), x), along, zs]), WARP_ENDS))
    yield from out["weft"]
    yield from out["warp"]


def level_path(crossings: np.ndarray, heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions along a yarn and heights (mm) of its nodes: :data:`NODES_PER_CROSSING` a crossing on
    the smoothstep between the ``heights`` at the ``crossings`` (positions along it), the last crossing's
    node closing the path."""
    t = np.arange(NODES_PER_CROSSING) / NODES_PER_CROSSING
    step = t * t * (3 - 2 * t)
    along = (crossings[:-1, None] + t * np.diff(crossings)[:, None]).ravel()
    zs = (heights[:-1, None] + step * np.diff(heights)[:, None]).ravel()
    return np.append(along, crossings[-1]), np.append(zs, heights[-1])


def _centres(spacing: float, shift: float, length: float) -> np.ndarray:
    """Indices ``i`` of the yarn centres ``(i + 0.5) · spacing + shift`` from the last before 0 to the
    first past ``length``: nodes one crossing past the box, yarns a spacing past each face."""
    first = int(np.floor(-shift / spacing - 0.5)) - 1
    last = int(np.ceil((length - shift) / spacing - 0.5)) + 1
    return np.arange(first, last + 1)
