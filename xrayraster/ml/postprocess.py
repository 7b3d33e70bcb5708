"""Post-processing of a segmentation: :func:`largest_component` keeps the specimen, the largest
connected body of non-background voxels, and sets every other body to background.

A woven specimen is one body: matrix binds every yarn. Whatever a network labels as material apart
from it (a mount or holder below a gap of air, a loose fragment, a speck of noise) is not the
specimen. This is nnU-Net's "keep the largest foreground component" and MONAI's
``KeepLargestConnectedComponent(independent=False)``; it cannot help where a mount touches the
specimen, as the two are then one body.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..core.errors import ConfigError


def largest_component(labels, background: int = 0, connectivity: int | None = None) -> np.ndarray:
    """``labels`` (any integer array) with every voxel outside its largest connected body of
    non-``background`` voxels set to ``background``; ties keep the body met first in C order.

    ``connectivity``: the most axes along which two neighbours may differ (1: faces only; the
    default, ``labels.ndim``: faces, edges and corners, 26 neighbours in 3-D), as in MONAI and
    scikit-image."""
    labels = np.asarray(labels)
    connectivity = labels.ndim if connectivity is None else connectivity
    if not 1 <= connectivity <= max(labels.ndim, 1):
        raise ConfigError(f"connectivity must be 1 to {labels.ndim} for a {labels.ndim}-D array, got {connectivity!r}")
    bodies, count = ndimage.label(labels != background, ndimage.generate_binary_structure(labels.ndim, connectivity))
    if count <= 1:
        return labels.copy()
    sizes = np.bincount(bodies.ravel())
    sizes[0] = 0
    return np.where(bodies == np.argmax(sizes), labels, np.asarray(background, labels.dtype))
