"""A yarn's centre line, the spline its tube is swept along, as points: for the direction labels
(:mod:`~xrayraster.weave.directions`) and the centre lines a scan writes beside its labels."""

from __future__ import annotations

import numpy as np

from ..core.transform import Transform
from .sweep import CubicSpline3
from .yarn import Yarn

__all__ = ["centreline", "centreline_table"]


def centreline(yarn: Yarn, transform: Transform, step_mm: float, box=None) -> tuple[np.ndarray, np.ndarray]:
    """``(points, unit tangents)``, each ``(k, 3)`` mm, of ``yarn``'s centre line every ``step_mm`` or
    closer, placed by ``transform``; with ``box`` (``(2, 3)`` min/max corners in the yarn's own frame)
    only the points inside it, as the clipped tube keeps them."""
    spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
    t = np.linspace(0.0, spline.length_parameter, max(2, int(np.ceil(spline.length_parameter / step_mm)) + 1))
    points, tangents = spline(t), spline(t, derivative=1)
    if box is not None:
        inside = np.all((points >= box[0]) & (points <= box[1]), axis=1)
        points, tangents = points[inside], tangents[inside]
    tangents = tangents @ transform.array[:3, :3].T
    return transform.apply(points), tangents / np.linalg.norm(tangents, axis=1, keepdims=True)


def centreline_table(sample, transform: Transform, step_mm: float) -> dict:
    """Every yarn of ``sample`` (:meth:`~xrayraster.weave.Sample.yarns`, the clipped-away remnants
    too where their line enters the box) as a polyline inside the yarn box, placed by ``transform``:
    ``{"units": "mm", "step_mm": …, "yarns": [{"name", "family", "kind", "points": [[x, y, z], …]}]}``,
    JSON-ready; a yarn whose line stays outside the box is left out."""
    yarns = []
    for yarn in sample.yarns():
        points, _ = centreline(yarn, transform, step_mm, sample.yarn_box)
        if len(points) >= 2:
            yarns.append({"name": yarn.name, "family": yarn.family, "kind": yarn.kind,
                          "points": np.round(points, 6).tolist()})
    return {"units": "mm", "frame": "scanner", "step_mm": step_mm, "yarns": yarns}
