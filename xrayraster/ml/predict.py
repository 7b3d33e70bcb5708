"""Whole-volume segmentation from a patch model: :func:`predict_volume` slides a window over the volume
and blends the overlapping patches' class scores.

The windows are MONAI's (``sliding_window_inference``): along each axis a step of
``int(patch × (1 − overlap))`` voxels (at least 1) from 0, the last window moved back to end at the
volume's edge; a volume smaller than the patch is padded with 0 (air). Blending weighs each
window's scores by a Gaussian about its centre (σ = patch / 8, as MONAI's and nnU-Net's default:
a patch's edges, which see less context, count less), or uniformly (``blend="uniform"``, MONAI's
``"constant"``), and divides by the summed weights.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ConfigError
from .patches import Percentiles, intensity_bounds, patch_shape

BLENDS = ("gaussian", "uniform")


def predict_volume(model, volume, patch_size=64, *, overlap: float = 0.5, normalize=None, blend: str = "gaussian",
                   batch_size: int = 1, index_block: int = 4, scores: bool = False) -> np.ndarray:
    """Labels (uint8, (z, y, x)) of ``volume`` (float cm⁻¹, (z, y, x)) by ``model``, or the blended
    class ``scores`` (float32, (classes, z, y, x)) when ``scores=True``.

    ``model`` maps a batch (N, 1, z, y, x) of normalised patches to class scores (N, classes, z, y, x):
    a ``torch.nn.Module`` (run without gradients on its parameters' device, in eval mode) or any
    function of NumPy arrays. ``normalize`` and ``index_block``: as the model's
    :class:`~.patches.PatchDataset` (its percentiles taken on the same voxels)."""
    if blend not in BLENDS:
        raise ConfigError(f"blend must be one of {', '.join(BLENDS)}, got {blend!r}")
    if not 0.0 <= overlap < 1.0:
        raise ConfigError(f"overlap must be in [0, 1), got {overlap!r}")
    volume = np.asarray(volume, dtype=np.float32)
    if volume.ndim != 3:
        raise ConfigError(f"volume must be 3-D (z, y, x), got shape {volume.shape}")
    size = patch_shape(patch_size)
    normalize = normalize or Percentiles()
    padded = np.pad(normalize.scaled(volume, intensity_bounds(normalize, volume, index_block)),
                    [(0, max(p - n, 0)) for p, n in zip(size, volume.shape)])
    run = _as_function(model)
    weight = _weights(size, blend)
    starts = [(z, y, x) for z in _starts(padded.shape[0], size[0], overlap)
              for y in _starts(padded.shape[1], size[1], overlap) for x in _starts(padded.shape[2], size[2], overlap)]
    total, weights = None, np.zeros(padded.shape, np.float32)
    for first in range(0, len(starts), batch_size):
        batch = starts[first:first + batch_size]
        windows = [tuple(slice(b, b + p) for b, p in zip(start, size)) for start in batch]
        out = np.asarray(run(np.stack([padded[w][None] for w in windows])), dtype=np.float32)
        if total is None:
            total = np.zeros((out.shape[1], *padded.shape), np.float32)
        for w, o in zip(windows, out):
            total[(slice(None), *w)] += o * weight
            weights[w] += weight
    blended = (total / weights)[(slice(None), *(slice(0, n) for n in volume.shape))]
    return blended if scores else np.argmax(blended, axis=0).astype(np.uint8)


def _starts(length: int, patch: int, overlap: float) -> list[int]:
    step = max(int(patch * (1.0 - overlap)), 1)
    count = -(-(length - patch) // step) + 1
    return [min(i * step, length - patch) for i in range(count)]


def _weights(size, blend: str) -> np.ndarray:
    if blend == "uniform":
        return np.ones(size, np.float32)
    axes = [np.exp(-0.5 * ((np.arange(p) - (p - 1) / 2) / (p / 8)) ** 2) for p in size]
    weight = axes[0][:, None, None] * axes[1][None, :, None] * axes[2][None, None, :]
    weight /= weight.max()
    return np.maximum(weight, weight[weight > 0].min()).astype(np.float32)  # no zero weight at a corner


def _as_function(model):
    if not hasattr(model, "parameters"):
        return model
    import torch

    device = next(iter(model.parameters()), torch.zeros(0)).device
    model.eval()

    def run(batch: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return model(torch.from_numpy(batch).to(device)).float().cpu().numpy()

    return run
