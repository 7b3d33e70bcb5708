"""Truncation correction for FDK: rows of objects wider than the field of view (region-of-interest
scans), extrapolated smoothly past the detector's edges before the ramp filter.

Why: the ramp filter is not local. A row cut off where the object still attenuates (a composite
panel wider than the beam) is filtered as if the object ended in a step at the detector edge; the
step's response runs across the whole field of view as a bright rim, a bias and cupping (a
homogeneous cylinder 1.5× wider than the field of view comes out +0.37 of its μ too high inside
it, docs/reconstruction.md). Filling in a plausible continuation of the row before filtering
removes most of that; the filtered row is still used only on the detector.

The method (Ohnesorge et al., Med. Phys. 27 (2000) 39, eq. 3, as RTK's truncation correction):
past each truncated edge the row continues as its point mirror about the edge pixel, which keeps
the edge value and slope, rolled off to zero over ``pad`` columns:

    q(−j) = w(j) · max(0, 2·q(0) − q(j)),   w(j) = cos²(π/2 · j / (pad + 1)),   j = 1 … pad

(and likewise past the last column), q being the pre-weighted row (cosine and redundancy weights
applied). The clamp keeps the continuation a non-negative line integral. Its size is bounded by
2·q(0), so a row end in air gets (almost) nothing even when corrected.

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

EDGE_PIXELS = 4  # outermost pixels averaged to decide whether a row end is truncated (noise)
THRESHOLD = 0.02  # line integral (−ln of a 98 % transmission) at the edge that counts as an object
RELATIVE_THRESHOLD = 0.02  # ... and as a share of the row's largest line integral
DEFAULT_WIDTH = 0.5  # padding on each side as a share of the detector width (measured, docs/reconstruction.md)
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
