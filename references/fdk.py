"""FDK / FBP in plain float64 NumPy: the reference the OpenCL kernels are checked against.

Same algorithm as :mod:`xrayraster.recon.fdk` (the per-view arrays of :mod:`xrayraster.recon.fdk_weights`
and the response of :mod:`xrayraster.recon.ramp_filter`), written the obvious way: weight, filter
each padded row by FFT, backproject every voxel with bilinear interpolation (zero outside the
detector). Slow; for small cases only. Returns mm⁻¹.
"""

from __future__ import annotations

import numpy as np

from xrayraster.recon.fdk_weights import cosine_weights, fdk_views
from xrayraster.recon.ramp_filter import ramp_response


def filtered_projections(projections, geometry, volume, window="ram-lak", cutoff=1.0, scan="auto"):
    """(views, rows, cols) float64 weighted, ramp-filtered projections, and the FDKViews."""
    views = fdk_views(geometry, volume, scan)
    rows, cols = views.detector_shape
    response = ramp_response(cols, views.pixel_pitch, window, cutoff)
    out = np.empty((len(projections), rows, cols))
    for i, p in enumerate(np.asarray(projections, np.float64)):
        weighted = p * cosine_weights(views, i) * views.redundancy[i][None, :]
        spectrum = np.fft.fft(weighted, n=len(response), axis=1) * response
        out[i] = np.fft.ifft(spectrum, axis=1).real[:, :cols]
    return out, views


def backproject(filtered, views, volume) -> np.ndarray:
    """Σ_views scale/w² · bilinear(q, row, col) at every voxel centre, float64 (z, y, x)."""
    nz, ny, nx = volume.shape
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    index = np.stack([i, j, k, np.ones_like(i)], axis=-1).astype(np.float64)  # (z, y, x, 4)
    rows, cols = views.detector_shape
    out = np.zeros(volume.shape)
    for q, m, scale in zip(filtered, views.matrices, views.scale):
        h = index @ m.T
        w = h[..., 2]
        out += scale / w**2 * bilinear(q, h[..., 1] / w, h[..., 0] / w)
    return out


def bilinear(image: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Bilinear interpolation between pixel centres (integer indices), zero outside the image."""
    padded = np.pad(image, 1)  # a ring of zeros: neighbours outside the detector count as 0
    r = row + 1.0
    c = col + 1.0
    inside = (r >= 0) & (r <= padded.shape[0] - 1) & (c >= 0) & (c <= padded.shape[1] - 1)
    r = np.where(inside, r, 0.0)
    c = np.where(inside, c, 0.0)
    r0 = np.minimum(np.floor(r).astype(int), padded.shape[0] - 2)
    c0 = np.minimum(np.floor(c).astype(int), padded.shape[1] - 2)
    fr, fc = r - r0, c - c0
    value = ((1 - fr) * (1 - fc) * padded[r0, c0] + (1 - fr) * fc * padded[r0, c0 + 1]
             + fr * (1 - fc) * padded[r0 + 1, c0] + fr * fc * padded[r0 + 1, c0 + 1])
    return np.where(inside, value, 0.0)


def fdk_reference(projections, geometry, volume, window="ram-lak", cutoff=1.0, scan="auto") -> np.ndarray:
    """The reconstruction, float64 (z, y, x), mm⁻¹."""
    filtered, views = filtered_projections(projections, geometry, volume, window, cutoff, scan)
    return backproject(filtered, views, volume)
