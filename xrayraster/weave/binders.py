"""The binders' bends: curvature along each binder's centre line inside the cell, and the tightest
bend, which sets the path-sampling error (:attr:`~xrayraster.weave.Sample.path_sagitta_mm`,
:mod:`xrayraster.weave.tessellation`)."""

from __future__ import annotations

import math

import numpy as np

from .sweep import CubicSpline3

__all__ = ["CURVATURE_SAMPLES", "binder_curvature_along", "smallest_bend_radius_mm"]

#: Points per node interval at which :func:`binder_curvature_along` evaluates the spline's curvature.
CURVATURE_SAMPLES = 64


def binder_curvature_along(yarns, size) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per bending yarn among ``yarns`` (:class:`~xrayraster.weave.Yarn`; the binders, and a 2D
    weave's warps and wefts, which have a node at every crossing): arc length (mm) and curvature
    (1/mm) along its centre line (the C² spline, node plateaus and clamped ends included) at
    :data:`CURVATURE_SAMPLES` points per node interval, kept where the path lies inside the cell
    (``0 ≤ y ≤ size[1]`` along a warp, ``0 ≤ x ≤ size[0]`` along a weft: what the clip keeps); arc
    length from the first point kept."""
    out = []
    for yarn in yarns:
        if yarn.kind != "binder" and len(yarn.nodes) <= 2:  # a straight yarn
            continue
        axis = 0 if yarn.family == "weft" else 1
        spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
        t = np.linspace(0.0, spline.length_parameter, CURVATURE_SAMPLES * (len(spline.knots) - 1) + 1)
        points = spline(t)
        inside = (points[:, axis] >= 0) & (points[:, axis] <= size[axis])  # the yarn runs along its axis: one run
        step = np.linalg.norm(np.diff(points[inside], axis=0), axis=1)
        out.append((np.concatenate([[0.0], np.cumsum(step)]), spline.curvature(t)[inside]))
    return out


def smallest_bend_radius_mm(curves) -> float:
    """The smallest bend radius (mm) over ``curves`` (:func:`binder_curvature_along`); ``inf`` when
    nothing bends."""
    curvature = max(float(kappa.max()) for _, kappa in curves)
    return 1.0 / curvature if curvature > 0 else math.inf
