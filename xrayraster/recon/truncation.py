"""Truncation correction for FDK: rows of objects wider than the field of view (region-of-interest
scans), extrapolated smoothly past the detector's edges before the ramp filter.

Why: the ramp filter is not local. A row cut off where the object still attenuates (a composite
panel wider than the beam) is filtered as if the object ended in a step at the detector edge; the
step's response runs across the whole field of view as a bright rim, a bias and cupping (a
homogeneous cylinder 1.5× wider than the field of view comes out +0.37 of its μ too high inside
it, docs/reconstruction.md). Filling in a plausible continuation of the row before filtering
removes most of that; the filtered row is still used only on the detector.

The method, per row end, adapts to what the row shows (measured in docs/reconstruction.md):

* **Arc** (water-cylinder extrapolation, Hsieh et al., Med. Phys. 31 (2004) 2385): a round object
  of uniform μ gives, along a row, (q/cos γ)² = 4μ²w²(ρ² − (ℓ − e)²), a parabola in ℓ, the
  distance of the pixel's ray from the rotation axis (γ its fan angle, w the redundancy weight;
  ℓ = R sin γ, the ray's lateral distance, for cone beams; for parallel beams the ray's own
  distance, and cos γ = 1). The parabola is fitted by least squares to the :data:`FIT_PIXELS`
  outermost pixels and followed past the edge to where it closes. Used when it closes within
  the padding: the object visibly rounds off.
* **Mirror** otherwise (a slab, a panel: no curvature to follow): the row continues as its point
  mirror about the edge pixel, which keeps the edge value and slope (Ohnesorge et al., Med.
  Phys. 27 (2000) 39, eq. 3, as RTK's truncation correction), rolled off to zero over W columns:

      q(−j) = w(j) · max(0, 2·q(0) − q(j)),   w(j) = cos²(π/2 · j / (W + 1)),   j = 1 … W

  (and likewise past the last column). W is how far the object reaches past that edge in that
  view when its reach about the axis is known (``object_radius_mm``; ``xrayraster scan`` knows
  its sample's), else ``truncation_width`` × the detector width.

The padding (columns extrapolated at most on each side) is the object's farthest reach past an
edge when known, else ``truncation_width`` × the detector width. The filtered row is still used
only on the detector.

When (``truncation="auto"``, the default): a row end is truncated when the mean of its
:data:`EDGE_PIXELS` outermost line integrals, times the redundancy weight at that edge relative
to the view's largest (0 at a displaced detector's short edge, which the weights already roll
off; 1 for a centred full scan), is above :data:`THRESHOLD` and above :data:`RELATIVE_THRESHOLD`
of the row's largest line integral (so the decision does not depend on how the views are
batched). ``True`` corrects every row end, ``False`` none. The share of row ends corrected is
reported in the reconstruction's provenance.
"""

from __future__ import annotations

import numpy as np

from ..core.choices import is_switch
from ..core.errors import ReconstructionError
from .fdk_weights import FDKViews

EDGE_PIXELS = 4  # outermost pixels averaged to decide whether a row end is truncated (noise)
THRESHOLD = 0.02  # line integral (−ln of a 98 % transmission) at the edge that counts as an object
RELATIVE_THRESHOLD = 0.02  # ... and as a share of the row's largest line integral
DEFAULT_WIDTH = 0.5  # padding on each side, a share of the detector width, where the reach is unknown
FIT_PIXELS = 12  # outermost pixels of a row end the arc is fitted to (fewer on narrower detectors)
MAX_WIDTH = 4.0  # padding at most, detector widths
LEFT, RIGHT = 1, 2  # bits of a row's flags: extrapolate before column 0 / after the last column


def check_truncation(truncation, width) -> None:
    """Refuse an unknown ``truncation`` or a padding ``width`` outside (0, 4]."""
    if not is_switch(truncation):
        raise ReconstructionError(f"truncation must be 'auto', True or False, got {truncation!r}")
    if isinstance(width, bool) or not isinstance(width, (int, float)) or not 0 < width <= 4:
        raise ReconstructionError(
            f"truncation_width must be a share of the detector width in (0, 4] (0.25: a quarter on each side), "
            f"got {width!r}")


def padding_columns(cols: int, width: float) -> int:
    """Columns extrapolated past each edge: ``width`` × the detector's columns, at least 1."""
    return max(1, round(width * cols))


def padding(views: FDKViews, truncation, width: float, reach_mm: float | None) -> tuple[int, np.ndarray]:
    """Columns extrapolated at most past each edge, and (views, 2) the mirrors' roll-off widths:
    from an object's known reach (:func:`reach_padding`), else ``width`` × the detector width for both."""
    count, cols = len(views.scale), views.detector_shape[1]
    if truncation is False:
        return 0, np.zeros((count, 2), int)
    if reach_mm is None:
        pad = padding_columns(cols, width)
        return pad, np.full((count, 2), pad)
    return reach_padding(views.vectors, views.toward_axis, views.detector_shape, views.beam == "cone", reach_mm,
                         round(MAX_WIDTH * cols))


def lateral_positions(vectors: np.ndarray, toward_axis: np.ndarray, rows: np.ndarray, shape: tuple[int, int],
                      columns: np.ndarray, cone: bool) -> tuple[np.ndarray, np.ndarray]:
    """(n, len(columns)) float64 each, for n views (``vectors`` (n, 12): source (cone) or ray
    direction (parallel), detector centre, pixel steps; ``toward_axis`` (n, 3)) and a row of each
    (``rows`` (n,), fractional allowed) on a detector of ``shape``: ℓ, the horizontal distance (mm,
    signed: its sign does not matter to the fits) of each pixel's ray from the rotation axis (z), and cos γ, its
    fan angle's cosine (1 for parallel beams), at pixel ``columns`` (also past the edges)."""
    # Pixel (row, c) sits at base + c·u: every quantity below is a polynomial in c with per-view
    # coefficients, so no (views, columns, 3) array is made.
    src, d, u, v = (vectors[:, 3 * k : 3 * k + 2] for k in range(4))  # horizontal parts (z does not matter)
    c = (np.asarray(columns, float) - 0.5 * (shape[1] - 1))[None, :]
    base = d + (np.asarray(rows, float) - 0.5 * (shape[0] - 1))[:, None] * v
    cross = lambda a, b: (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])[:, None]  # noqa: E731
    dot = lambda a, b: (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])[:, None]  # noqa: E731
    if cone:
        h, s_hat = base - src, toward_axis[:, :2]  # h + c·u: from the source to the pixel
        norm = np.sqrt(dot(h, h) + c * (2 * dot(h, u) + c * dot(u, u)))
        radius = np.hypot(src[:, 0], src[:, 1])[:, None]
        lateral = radius * (cross(s_hat, h) + c * cross(s_hat, u)) / norm
        cos = (dot(s_hat, h) + c * dot(s_hat, u)) / norm
    else:
        ray = src / np.hypot(src[:, 0], src[:, 1])[:, None]  # the ray's direction
        lateral, cos = cross(ray, base) + c * cross(ray, u), np.ones((len(base), c.shape[1]))
    return lateral, cos


def reach_padding(vectors: np.ndarray, toward_axis: np.ndarray, shape: tuple[int, int], cone: bool,
                  reach_mm: float, most: int) -> tuple[int, np.ndarray]:
    """For an object that reaches ``reach_mm`` from the axis: the padding (columns past an edge,
    at most ``most``) that holds every column whose line through the detector's centre still
    passes within that reach, with a tenth and two columns to spare (an arc that closes there is
    seen to close), and (views, 2) the mirrors' widths: the object's reach past the left and the
    right edge in columns of the edge's own spacing (the fan's magnification at the edge; the
    tangent columns overstate a flat object's extent as the fan widens)."""
    rows, cols = shape
    j = np.arange(1, most + 1)
    columns = np.concatenate([[0, 1, cols - 2, cols - 1], -j, cols - 1 + j])
    middle = np.full(len(vectors), 0.5 * (rows - 1))
    lateral = np.abs(lateral_positions(vectors, toward_axis, middle, (rows, cols), columns, cone)[0])
    beyond = lateral[:, 4:].reshape(-1, 2, most) >= reach_mm
    tangent = np.where(beyond.any(axis=2), np.argmax(beyond, axis=2), most)
    pad = int(min(most, np.ceil(1.1 * tangent.max()) + 2))
    edge, step = lateral[:, [0, 3]], np.abs(lateral[:, [0, 3]] - lateral[:, [1, 2]])
    widths = np.clip(np.round((reach_mm - edge) / np.maximum(step, 1e-12)), 1, pad).astype(int)
    return pad, widths


def row_extensions(q: np.ndarray, ends: np.ndarray, vectors: np.ndarray, toward_axis: np.ndarray, cone: bool,
                   pad: int, width: np.ndarray) -> np.ndarray:
    """(views, rows, 2, pad) float32: the pre-weighted values at columns 1 … ``pad`` past the left
    (index 0) and the right (1) end of each row flagged in ``ends``, zeros elsewhere: the arc
    where the fitted one closes within ``pad``, else the mirror rolled off over ``width``
    columns ((views, 2), at most ``pad``). ``q`` (views, rows, cols) the pre-weighted rows."""
    views, rows, cols = q.shape
    out = np.zeros((views, rows, 2, pad), np.float32)
    k = min(FIT_PIXELS, cols)
    j = np.arange(1, pad + 1)
    sides = ((LEFT, np.arange(k), -j, np.minimum(j, cols - 1)),
             (RIGHT, cols - 1 - np.arange(k), cols - 1 + j, np.maximum(cols - 1 - j, 0)))
    for side, (flag, inner, past, mirrored) in enumerate(sides):
        view, row = np.nonzero(ends & flag)
        if not len(view):
            continue
        lateral, cos = lateral_positions(vectors[view], toward_axis[view], row, (rows, cols),
                                         np.concatenate([inner, past]), cone)
        rowq = q[view, row]
        edge = rowq[:, inner]  # (m, k): from the edge inwards
        # The parabola in ℓ about the edge pixel, ℓ scaled by the fitted span (conditioning).
        span = np.maximum(np.abs(lateral[:, k - 1 : k] - lateral[:, :1]), 1e-9)
        x = (lateral - lateral[:, :1]) / span
        fitted = x[:, :k]
        powers = np.stack([np.ones_like(fitted), fitted, fitted * fitted], axis=2)
        coeffs = _least_squares(powers, (edge / cos[:, :k]) ** 2)
        value = coeffs[:, :1] + coeffs[:, 1:2] * x[:, k:] + coeffs[:, 2:3] * x[:, k:] ** 2
        closed = np.maximum.accumulate(value <= 0, axis=1)  # past the first column where it closes
        arc = closed[:, -1] & (k >= 3)  # the arc closes within the padding: the row rounds off
        rounded = cos[arc, k:] * np.sqrt(np.maximum(value[arc], 0.0))
        out[view[arc], row[arc], side] = np.where(closed[arc], 0.0, rounded)
        mirror = ~arc
        widths, which = np.unique(width[view[mirror], side], return_inverse=True)
        rolls = np.where(j <= widths[:, None], np.cos(0.5 * np.pi * j / (widths[:, None] + 1)) ** 2, 0.0)
        out[view[mirror], row[mirror], side] = rolls[which] * np.maximum(
            0.0, 2.0 * edge[mirror, :1] - rowq[mirror][:, mirrored])
    return out


def _least_squares(powers: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(m, 3) coefficients minimising |powers · c − y| for each of m rows (normal equations, float64)."""
    gram = np.einsum("mki,mkj->mij", powers, powers)
    rhs = np.einsum("mki,mk->mi", powers, y)
    return np.linalg.solve(gram + 1e-12 * np.eye(3), rhs[..., None])[..., 0]


def truncated_row_ends(lineint: np.ndarray, edge_weights: np.ndarray, truncation) -> np.ndarray:
    """(views, rows) uint8 flags (:data:`LEFT`, :data:`RIGHT`) of the row ends to extrapolate.

    ``lineint`` (views, rows, cols) line integrals; ``edge_weights`` (views, 2) the redundancy
    weights of the first and the last column relative to each view's largest; ``truncation`` as
    in the module docstring."""
    views, rows, _ = lineint.shape
    if truncation is False:
        return np.zeros((views, rows), np.uint8)
    if truncation is True:
        return np.full((views, rows), LEFT | RIGHT, np.uint8)
    limit = np.maximum(THRESHOLD, RELATIVE_THRESHOLD * lineint.max(axis=2))
    left = lineint[:, :, :EDGE_PIXELS].mean(axis=2) * edge_weights[:, :1] > limit
    right = lineint[:, :, -EDGE_PIXELS:].mean(axis=2) * edge_weights[:, 1:] > limit
    return (left * LEFT + right * RIGHT).astype(np.uint8)
