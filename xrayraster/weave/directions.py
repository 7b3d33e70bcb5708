"""The yarn direction at every yarn voxel: the unit tangent of the yarn's centre line where it
passes nearest the voxel's centre, a label a network can learn fibre orientation from.

Each yarn's centre line is its path's spline (:func:`~xrayraster.weave.centrelines.centreline`, the
one its tube is swept along), evaluated every :data:`STEP_VOXELS` of a voxel and placed as the
sample is (``transform``); each voxel of the yarn (from the instance label volume, so the yarn that
owns the voxel under the priorities) takes the tangent at the nearest of those points (a k-d tree).
The tangent's sign follows the path: +x along a weft, +y along a warp, as the regular weave's
nodes run.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core.transform import Transform
from ..core.volume import VolumeGeometry
from .centrelines import centreline
from .yarn import Yarn

__all__ = ["STEP_VOXELS", "direction_field"]

#: Centre-line points per voxel edge: the nearest point's tangent is then that of the closest point
#: on the curve to within a turn of the path over a quarter voxel.
STEP_VOXELS = 0.25


def direction_field(instances: np.ndarray, grid: VolumeGeometry, yarns: dict[int, Yarn],
                    transform: Transform) -> np.ndarray:
    """``(3, z, y, x)`` float16: the (x, y, z) components of the unit direction of the yarn that owns
    each voxel (``instances``: the instance ids on ``grid``; ``yarns``: id → its yarn), 0 outside
    the yarns. ``transform`` places the yarns' nodes (mm) in the grid's frame."""
    out = np.zeros((3, *instances.shape), np.float16)
    flat = instances.ravel()
    order = np.argsort(flat, kind="stable")
    ends = np.cumsum(np.bincount(flat, minlength=max(yarns, default=0) + 1))
    axes = [grid.axis_centres(a) for a in range(3)]  # z, y, x
    step = STEP_VOXELS * min(grid.voxel_size)
    for label, yarn in yarns.items():
        voxels = order[ends[label - 1]:ends[label]]
        if voxels.size == 0:
            continue
        points, tangents = centreline(yarn, transform, step)
        k, j, i = np.unravel_index(voxels, instances.shape)
        centres = np.column_stack([axes[2][i], axes[1][j], axes[0][k]])  # x, y, z
        nearest = cKDTree(points).query(centres)[1]
        for c in range(3):
            out[c].ravel()[voxels] = tangents[nearest, c]
    return out
