"""Classical segmentations and Dice scores, the baselines scripts/train_segmentation.py scores the
network beside (docs/ml.md): smoothing then multi-Otsu thresholds or a Gaussian mixture, their
classes matched to labels by the order of their means; voxel confusion matrices and the Dice of
each label. SciPy, scikit-image and scikit-learn (the ml extra) are imported on first use."""

from __future__ import annotations

from typing import Iterable

import numpy as np


def baseline(name: str, smooth: str, order: list[int]):
    """A classical segmentation: ``smooth`` ("median 3³" or "Gaussian σ 1") then ``name``
    ("multi-Otsu" or "Gaussian mixture"), its classes matched to ``order`` by their means."""
    from scipy import ndimage

    def segment(volume: np.ndarray) -> np.ndarray:
        v = ndimage.median_filter(volume, size=3) if smooth.startswith("median") else ndimage.gaussian_filter(volume, 1.0)
        k = len(order)
        if name == "multi-Otsu":
            from skimage.filters import threshold_multiotsu

            clusters = np.digitize(v, threshold_multiotsu(v, classes=k))  # already in the order of the means
        else:
            from sklearn.mixture import GaussianMixture

            sample = np.random.default_rng(0).choice(v.ravel(), size=min(v.size, 200_000), replace=False)
            mixture = GaussianMixture(k, random_state=0).fit(sample[:, None])
            rank = np.argsort(np.argsort(mixture.means_.ravel()))
            clusters = rank[mixture.predict(v.reshape(-1, 1))].reshape(v.shape)
        return np.asarray(order, np.uint8)[clusters]

    return segment


def confusion(truth: np.ndarray, predicted: np.ndarray, k: int) -> np.ndarray:
    """Voxels by (true label, predicted label)."""
    return np.bincount((truth.astype(np.int64) * k + np.minimum(predicted, k - 1)).ravel(), minlength=k * k).reshape(k, k)


def dice_from_confusion(m: np.ndarray, labels: Iterable[int]) -> dict:
    """Dice of each of ``labels`` from a confusion matrix (true label by row, predicted by column)."""
    return {c: 2 * float(m[c, c]) / max(float(m[c, :].sum() + m[:, c].sum()), 1.0) for c in labels}
