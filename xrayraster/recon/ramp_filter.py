"""The ramp filter of filtered backprojection, as a frequency response for zero-padded FFTs.

The response is the FFT of the band-limited discrete ramp kernel (Kak & Slaney, "Principles of
Computerized Tomographic Imaging", eq. 3.61): ``h[0] = 1/(4τ)``, ``h[k] = −1/(π² k² τ)`` for
odd k, 0 for even k ≠ 0, τ the pixel pitch (mm), including the τ of the convolution sum, so a
filtered row is ``q = p ⊛ h`` in mm⁻¹ for line integrals p. Sampling the kernel in space rather
than |f| in frequency keeps the DC term right (no offset in flat regions).

Rows are zero-padded to ``n ≥ 2·cols`` (a power of two), so the circular convolution of the
FFT equals the linear one for every output pixel. Windows multiply the response; ``ω`` is the
frequency as a fraction of Nyquist and ``c`` the cut-off (0 < c ≤ 1, zero above it):

=============  ==============================
``ram-lak``    1
``shepp-logan``  sin(πω/2c) / (πω/2c)
``cosine``     cos(πω/2c)
``hamming``    0.54 + 0.46·cos(πω/c)
``hann``       0.5 + 0.5·cos(πω/c)
=============  ==============================
"""

from __future__ import annotations

import math

import numpy as np

from ..core.choices import FILTERS, check_choice
from ..core.errors import GeometryError


def padded_length(cols: int) -> int:
    """FFT length for a row of ``cols`` pixels: the smallest power of two ≥ 2·cols (≥ 64)."""
    return max(64, 1 << (2 * int(cols) - 1).bit_length())


def ramp_response(cols: int, pitch_mm: float, window: str = "ram-lak", cutoff: float = 1.0) -> np.ndarray:
    """Real, even frequency response (length :func:`padded_length`) of the windowed ramp."""
    check_choice(window, FILTERS, "filter", GeometryError)
    cutoff = float(cutoff)
    if not (math.isfinite(cutoff) and 0.0 < cutoff <= 1.0):
        raise GeometryError(f"cutoff must be in (0, 1] (a fraction of the Nyquist frequency), got {cutoff!r}")
    n = padded_length(cols)
    k = np.arange(n)
    k = np.where(k < n // 2, k, k - n).astype(np.float64)  # circular lags
    h = np.zeros(n)
    h[0] = 1.0 / (4.0 * pitch_mm)
    odd = (k % 2) != 0
    h[odd] = -1.0 / (math.pi**2 * k[odd] ** 2 * pitch_mm)
    response = np.fft.fft(h).real
    omega = np.abs(np.fft.fftfreq(n)) / 0.5 / cutoff  # frequency / (cut-off · Nyquist)
    if window == "shepp-logan":
        response *= np.sinc(omega / 2)
    elif window == "cosine":
        response *= np.cos(0.5 * math.pi * omega)
    elif window == "hamming":
        response *= 0.54 + 0.46 * np.cos(math.pi * omega)
    elif window == "hann":
        response *= 0.5 + 0.5 * np.cos(math.pi * omega)
    response[omega > 1.0] = 0.0
    return response
