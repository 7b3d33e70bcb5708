"""The detector: how absorbed photons become a signal, and the blur and electronic noise it adds."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.choices import DETECTOR_MODES, check_choice
from ..core.errors import PhysicsError

# A Gaussian blur whose standard deviation is below this many pixels is skipped, at no cost
# (docs/realism.md, "Options too small to show"). Both blurs' kernels are exactly [0, 1, 0] in
# float64 there (the weight one pixel away underflows to 0: exp(−1/(2σ²)) below σ ≈ 0.026 px for the
# sampled kernel, 1 − erf below σ ≈ 0.059 px for the pixel-averaged one), so skipping changes no
# bit of the noise-free signal. On a detector that integrates over its pixels, such a blur would
# change a pixel by at most √(2/π)·σ of the contrast around it per axis (:func:`blur_change_bound`):
# 0.8 % at the threshold, where a pixel sampled at its centre already places an edge only to
# within the pixel (up to half the contrast).
NEGLIGIBLE_BLUR_PX = 0.01


def negligible_blur(sigma_px: float) -> bool:
    """Whether a Gaussian blur of standard deviation ``sigma_px`` (pixels) is skipped: 0, or below
    :data:`NEGLIGIBLE_BLUR_PX`."""
    return sigma_px < NEGLIGIBLE_BLUR_PX


def blur_change_bound(sigma_rows_px: float, sigma_cols_px: float) -> float:
    """The most a Gaussian blur of these standard deviations (pixels) can change a pixel of an image
    integrated over its pixels, as a share of the image's range: √(2/π)·(σ_rows + σ_cols).

    Along one axis, the blur moves a share ∫₀^∞ Φ(−t/σ) dt = σ/√(2π) of a pixel's content across
    each of its two edges, out and in: at most 2·σ/√(2π) of the range (a one-pixel line; a step
    edge gets half). A separable blur's two passes add (docs/realism.md derives it).
    """
    return math.sqrt(2 / math.pi) * (sigma_rows_px + sigma_cols_px)


@dataclass(frozen=True)
class Detector:
    """A flat-panel detector.

    * ``mode``: ``"integrating"`` (signal = energy deposited, keV: Σ E·η·n) or ``"counting"``
      (signal = photons counted: Σ η·n).
    * ``scintillator`` (a :class:`~xrayraster.Material`) and ``scintillator_mm``: absorption
      efficiency η(E) = 1 − exp(−μ(E)·thickness). Without one, η = 1 (every photon counts).
    * ``blur_sigma_px``: Gaussian point-spread (standard deviation, pixels), applied to the
      detected signal (after quantum noise, as scintillator light spreads), or ``psf``: a
      user-supplied odd-sized 2-D kernel (normalised to sum 1). Not both.
    * ``electronic_noise``: standard deviation of additive Gaussian read noise, signal units.
    * ``dark``: mean dark signal (offset), signal units; dark fields average to it.
    """

    mode: str = "integrating"
    scintillator: object | None = None
    scintillator_mm: float = 0.0
    blur_sigma_px: float = 0.0
    psf: tuple | None = None
    electronic_noise: float = 0.0
    dark: float = 0.0

    def __post_init__(self):
        check_choice(self.mode, DETECTOR_MODES, "detector mode", PhysicsError)
        for name in ("scintillator_mm", "blur_sigma_px", "electronic_noise", "dark"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise PhysicsError(f"detector {name} must be a finite number >= 0, got {value!r}")
        if (self.scintillator is None) != (self.scintillator_mm == 0):
            raise PhysicsError("detector: give both scintillator (a Material) and scintillator_mm > 0, or neither")
        if self.psf is not None:
            kernel = np.asarray(self.psf, dtype=np.float64)
            if kernel.ndim != 2 or kernel.shape[0] % 2 == 0 or kernel.shape[1] % 2 == 0:
                raise PhysicsError(f"detector psf must be a 2-D kernel of odd size, got shape {kernel.shape}")
            if not np.all(np.isfinite(kernel)) or np.any(kernel < 0) or kernel.sum() <= 0:
                raise PhysicsError("detector psf must be finite, non-negative and not all zero")
            if self.blur_sigma_px:
                raise PhysicsError("detector: give blur_sigma_px or psf, not both")
            object.__setattr__(self, "psf", tuple(map(tuple, kernel / kernel.sum())))

    @property
    def counting(self) -> bool:
        return self.mode == "counting"

    def efficiency(self, energies_kev) -> np.ndarray:
        """Absorption efficiency η(E) of the scintillator (1 without one)."""
        energies = np.asarray(energies_kev, dtype=np.float64)
        if self.scintillator is None:
            return np.ones_like(energies)
        return -np.expm1(-self.scintillator.attenuation(energies) * self.scintillator_mm)

    def weights(self, energies_kev) -> np.ndarray:
        """Expected signal per incident photon of each energy: E·η (integrating) or η (counting)."""
        energies = np.asarray(energies_kev, dtype=np.float64)
        eta = self.efficiency(energies)
        return eta if self.counting else energies * eta

    @property
    def blur_skipped(self) -> bool:
        """Whether ``blur_sigma_px`` is given but too small to show (:data:`NEGLIGIBLE_BLUR_PX`): not applied."""
        return 0 < self.blur_sigma_px and negligible_blur(self.blur_sigma_px)

    def blur(self, image: np.ndarray) -> np.ndarray:
        """The point-spread applied to ``image`` (edges extended); ``image`` itself without blur, with
        a negligible ``blur_sigma_px`` (:data:`NEGLIGIBLE_BLUR_PX`) or with a ``psf`` of one centre weight."""
        if self.psf is not None:
            kernel = np.asarray(self.psf)
            if np.count_nonzero(kernel) == 1 and kernel[kernel.shape[0] // 2, kernel.shape[1] // 2]:
                return image  # the centre's weight alone, 1 once normalised: an identity
            return _convolve2d(image, kernel)
        if negligible_blur(self.blur_sigma_px):
            return image
        return gaussian_blur(image, self.blur_sigma_px, self.blur_sigma_px)

    def read_out(self, signal: np.ndarray, rng, *, gain=None, frames: int = 1) -> np.ndarray:
        """Blur, per-pixel ``gain`` (a map, or None for 1), dark offset and (with ``rng``) electronic
        noise: what the panel reports. ``frames``: ``signal`` is the mean of that many exposures,
        whose read noises average to a standard deviation of ``electronic_noise / sqrt(frames)``."""
        out = self.blur(signal)
        if gain is not None:
            out = out * gain
        if self.dark:  # adding 0 would change no value, only cost a pass over the image
            out = out + self.dark
        if rng is not None and self.electronic_noise > 0:
            out = out + rng.normal(0.0, self.electronic_noise / np.sqrt(frames), out.shape)
        return out


def gaussian_blur(image: np.ndarray, sigma_rows_px: float, sigma_cols_px: float, *, pixel_averaged: bool = False
                  ) -> np.ndarray:
    """``image`` convolved with a Gaussian of these standard deviations (pixels; 0: none along that
    axis), edges extended; ``image`` itself when both are 0. The kernel spans ±4σ and sums to 1: the
    Gaussian sampled at whole pixels, or with ``pixel_averaged`` its mean over each pixel's width
    (differences of its CDF), which blurs an image of pixel-wide steps exactly at any σ, also below
    a pixel, where the sampled kernel is coarse."""
    out = image
    for sigma, axis in ((sigma_cols_px, 1), (sigma_rows_px, 0)):  # separable
        if sigma == 0:
            continue
        radius = max(1, int(np.ceil(4 * sigma)))
        x = np.arange(-radius, radius + 1)
        if pixel_averaged:
            cdf = np.array([math.erf(edge / (sigma * math.sqrt(2))) for edge in np.append(x - 0.5, radius + 0.5)])
            g = np.diff(cdf)
        else:
            g = np.exp(-0.5 * (x / sigma) ** 2)
        g /= g.sum()
        out = _convolve2d(out, g[None, :] if axis == 1 else g[:, None])
    return out


def _convolve2d(image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Direct 2-D convolution with a small kernel, edges extended."""
    kernel = kernel[::-1, ::-1]
    ky, kx = kernel.shape
    padded = np.pad(image, ((ky // 2, ky // 2), (kx // 2, kx // 2)), mode="edge")
    out = np.zeros(image.shape)
    rows, cols = image.shape
    for i in range(ky):
        for j in range(kx):
            if kernel[i, j]:
                out += kernel[i, j] * padded[i : i + rows, j : j + cols]
    return out
