"""Every view's per-pixel photon factor (:func:`~xrayraster.physics.beer_lambert.pixel_photon_factor`),
computed once for all the views whose detector sits alike relative to the source.

A view's factor (area · cos(incidence) · (1 m / distance)² per pixel) depends on its source and
detector only through their relative pose: for a cone beam the seven dot products of the detector
vectors u, v and the source-to-detector vector h (u·u, v·v, u·v, u·h, v·h, h·h and (u×v)·h), for
a parallel beam those of u, v and the ray direction. Every view of a circular scan, the detector
turning with the source, has the same ones up to the rounding of its rotated vectors, so its
factor is computed once a scan instead of once a view (1.1 ms of a 512² view's 10 ms of physics,
measured on 2 cores). Views are grouped by these invariants rounded to :data:`KEY_DIGITS`
significant digits; each group takes the factor of its first view, so the bytes of a view's factor
do not depend on which views were asked, or in which order.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

from ..core.geometry import as_vector_geometry
from .beer_lambert import pixel_photon_factor

#: Significant digits of the invariants that group views: rotating a detector's vectors rounds them
#: at ~1e-16 of their size, while a real change of pose (a shifted or tilted detector, another
#: distance) moves them by far more than 1e-12.
KEY_DIGITS = 12
#: Factors kept at once (a circular scan needs one; a geometry whose views all differ computes each
#: view's as before, keeping only the last few).
KEPT = 4


class PhotonFactors:
    """``factors(view)``: the read-only per-pixel photon factor of ``view`` of ``geometry``
    (float64, detector shape), computed once for the views that share their relative pose (module
    docstring). Safe to call from several threads."""

    def __init__(self, geometry):
        self.vector_geometry = vec = as_vector_geometry(geometry)
        first: dict[tuple, int] = {}
        self._representative = [first.setdefault(key, view) for view, key in enumerate(_pose_keys(vec))]
        self._kept: OrderedDict[int, np.ndarray] = OrderedDict()
        self._lock = threading.Lock()

    @property
    def distinct(self) -> int:
        """How many distinct relative poses the views have (1 for a circular scan)."""
        return len(set(self._representative))

    def __call__(self, view: int) -> np.ndarray:
        representative = self._representative[view]
        with self._lock:
            if representative in self._kept:
                self._kept.move_to_end(representative)
                return self._kept[representative]
        factor = pixel_photon_factor(self.vector_geometry, representative)
        factor.flags.writeable = False  # shared by every view of its group
        with self._lock:
            self._kept[representative] = factor
            while len(self._kept) > KEPT:
                self._kept.popitem(last=False)
        return factor


def _pose_keys(vec) -> list[tuple]:
    """Per view, what its factor depends on: the lengths of u, v and h (:data:`KEY_DIGITS` significant
    digits) and the cosines between them and of h with the detector's normal (as many decimals: a
    cosine that is 0 up to rounding, such as u·h on a centred detector, rounds to 0 in every view)."""
    s, d, u, v = (vec.array[:, 3 * k : 3 * k + 3] for k in range(4))
    ray = d - s if vec.beam == "cone" else s  # a parallel beam's array holds the ray direction in s
    lengths = [np.linalg.norm(x, axis=1) for x in (u, v, ray)]
    u, v, ray = (x / n[:, None] for x, n in zip((u, v, ray), lengths))
    pairs = ((u, v), (u, ray), (v, ray), (np.cross(u, v), ray))
    cosines = np.round(np.stack([np.einsum("ij,ij->i", a, b) for a, b in pairs], axis=1), KEY_DIGITS)
    if vec.beam != "cone":
        lengths[2] = np.ones_like(lengths[2])  # only the direction of a parallel beam's rays counts
    return [tuple(float(f"{x:.{KEY_DIGITS}g}") for x in row) + tuple(cos + 0.0 for cos in row_cos)
            for row, row_cos in zip(np.stack(lengths, axis=1), cosines.tolist())]
