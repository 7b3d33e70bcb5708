"""Rotation-minimising frames along a sampled path: the double-reflection method of Wang, Jüttler,
Zheng and Liu, "Computation of rotation minimizing frames", ACM Trans. Graph. 27(1), 2008
(:func:`rotation_minimising_frames`; the yarn mesher, :mod:`xrayraster.weave.sweep`, carries the
cross-sections in them).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import WeaveError

__all__ = ["rotation_minimising_frames"]


def rotation_minimising_frames(points, tangents, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Frames ``(n, 3, 3)`` along a sampled path: rows ``[T, U, V]`` per sample, right-handed.

    T is the unit tangent, V the section's height axis, U = V × T its width axis (so U × V = T
    and an outline counter-clockwise in (u, v) is counter-clockwise seen from ahead). The first V
    is ``up`` made perpendicular to the first tangent (``up=None`` picks any perpendicular); the
    rest follow by the double-reflection method, which has no twist beyond the path's own
    (zero twist on a planar path) and is fourth-order accurate in the sample spacing.
    """
    x = np.asarray(points, dtype=np.float64)
    t = np.asarray(tangents, dtype=np.float64)
    t = t / np.linalg.norm(t, axis=1)[:, None]
    n = len(x)
    if up is None:
        helper = np.eye(3)[int(np.argmin(np.abs(t[0])))]
        r = helper - np.dot(helper, t[0]) * t[0]
    else:
        up_vec = np.asarray(up, dtype=np.float64).reshape(3)
        r = up_vec - np.dot(up_vec, t[0]) * t[0]
        if np.linalg.norm(r) <= 1e-9 * max(np.linalg.norm(up_vec), 1e-300):
            raise WeaveError(f"up {tuple(up_vec)} is parallel to the path's first tangent {tuple(t[0])}; "
                             "choose an up vector across the yarn's start")
    r = r / np.linalg.norm(r)
    # Step i reflects in the plane normal to v1 (the chord), then in the one normal to v2 (the
    # reflected tangent's miss): a fixed linear map M_i, whatever r is, so the normals are
    # M_{i-1}…M_0 r, their prefix products (a zero chord or miss reflects nothing).
    v1 = np.diff(x, axis=0)
    first = _reflections(v1)
    t_l = np.einsum("nij,nj->ni", first, t[:-1])
    maps = _reflections(t[1:] - t_l) @ first
    normals = np.concatenate([r[None], _prefix_products(maps) @ r])
    normals -= np.einsum("ij,ij->i", normals, t)[:, None] * t  # rounding drift only (about 1e-16 a step)
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    frames = np.empty((n, 3, 3))
    frames[:, 0] = t
    frames[:, 2] = normals
    frames[:, 1] = np.cross(normals, t)
    return frames


def _reflections(v: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` Householder reflections I − 2 v vᵀ / vᵀv in the planes normal to ``v`` ``(n, 3)``;
    the identity where v is zero."""
    c = np.einsum("ij,ij->i", v, v)
    scale = np.divide(2.0, c, out=np.zeros_like(c), where=c > 0)
    return np.eye(3) - scale[:, None, None] * v[:, :, None] * v[:, None, :]


def _prefix_products(maps: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)``: entry k is maps[k] @ maps[k − 1] @ … @ maps[0] (a doubling scan: log2 n
    vectorised steps instead of n small ones)."""
    out = maps.copy()
    step = 1
    while step < len(out):
        out[step:] = out[step:] @ out[:-step]
        step *= 2
    return out
