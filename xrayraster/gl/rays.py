"""Per-view ray coefficients for the shaders, computed in float64 relative to a reference point.

Float32 on the GPU loses ~1e-7 of whatever magnitude it holds. A source 10 m away would cost
~1e-3 mm in every distance measured from the source, so nothing here is measured from the
source: each pixel's ray is described by a point ``Q`` near the scene (on the plane through the
reference ``ref`` that faces the source) and a direction, and vertices are stored relative to
``ref``. Error then scales with the scene size, not with the source distance.

For pixel offsets ``(c', r')`` from the detector centre (in pixels):

* ray origin ``Q − ref = (N0 + c'·Nu + r'·Nv) / (m0 + c'·mu + r'·mv)``
* ray direction ``∝ D0 + c'·Du + r'·Dv``
* pixel of a point X: ``h = P · (X − ref, 1)``, ``c' = h0/h2``, ``r' = h1/h2``; ``h2 > 0`` in
  front of the source (cone beam) and ``h2 = 1`` for a parallel beam.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.geometry import VectorGeometry


@dataclass(frozen=True)
class ViewRays:
    """Shader inputs for one view (all float64; the renderer casts to float32)."""

    origin_num: np.ndarray  # (3, 3): rows N0, Nu, Nv
    origin_den: np.ndarray  # (3,): m0, mu, mv
    direction: np.ndarray  # (3, 3): rows D0, Du, Dv
    world_to_pixel: np.ndarray  # (3, 4)


def view_rays(vec: VectorGeometry, view: int, ref) -> ViewRays:
    """Ray coefficients of ``view`` with positions relative to ``ref`` (mm, float64)."""
    ref = np.asarray(ref, dtype=np.float64)
    s, d, u, v = np.split(vec.array[view], 4)
    if vec.beam == "cone":
        return _cone(s, d, u, v, ref)
    return _parallel(s, d, u, v, ref)


def _cone(src, d, u, v, ref) -> ViewRays:
    to_ref = ref - src
    g = np.linalg.norm(to_ref)
    if g == 0:
        raise ValueError("the reference point coincides with the source")
    n0 = to_ref / g
    a = (src - ref) / g  # scaled by 1/g so the coefficients stay O(detector size)
    d0 = d - src
    direction = np.stack([d0, u, v])
    den = direction @ n0
    num = a[None, :] * den[:, None] + direction
    den = den / g
    basis = np.column_stack([u, v, d0])
    inv = np.linalg.inv(basis)
    w2p = np.column_stack([inv, inv @ to_ref])
    return ViewRays(num, den, direction, w2p)


def _parallel(ray, d, u, v, ref) -> ViewRays:
    r = ray / np.linalg.norm(ray)
    perp = np.eye(3) - np.outer(r, r)
    num = np.stack([perp @ (d - ref), perp @ u, perp @ v])
    basis = np.column_stack([u, v, r])
    inv = np.linalg.inv(basis)
    w2p = np.zeros((3, 4))
    w2p[:2, :3] = inv[:2]
    w2p[:2, 3] = -(inv @ (d - ref))[:2]
    w2p[2, 3] = 1.0
    return ViewRays(num, np.array([1.0, 0.0, 0.0]), np.stack([r, np.zeros(3), np.zeros(3)]), w2p)
