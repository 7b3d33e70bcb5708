"""The ramp filter's frequency response against numpy.fft and a direct convolution in space.

``ramp_response`` is what the OpenCL kernels multiply each zero-padded row's FFT by. Here that
product, inverted with numpy.fft, must equal the *linear* convolution (``np.convolve``) of the
row with the spatial Kak–Slaney kernel (references/fdk.py, written from Kak & Slaney eq. 3.61
and the window table, sharing no code with the package), in float64, for every window at
cut-off 1 and a lower one. Agreement is ~1e-16 relative (rounding of two FFTs); a window or
kernel term off by 1 % shows up at ~1e-3.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from xrayraster.core.choices import FILTERS
from xrayraster.recon.ramp_filter import padded_length, ramp_response

from references.fdk import WINDOWS, kak_slaney_kernel, ramp_filter_rows, ramp_kernel

TOLERANCE = 1e-12  # relative to the filtered row's largest value


def test_every_filter_the_package_offers_has_a_reference():
    assert set(FILTERS) == set(WINDOWS)


@pytest.mark.parametrize("cutoff", [1.0, 0.55])
@pytest.mark.parametrize("window", WINDOWS)
@pytest.mark.parametrize("cols, pitch", [(64, 0.8), (50, 0.15)])
def test_response_times_padded_fft_equals_direct_convolution(window, cutoff, cols, pitch):
    rng = np.random.default_rng(cols)
    rows = np.concatenate([rng.normal(size=(3, cols)),  # white: every frequency
                           np.ones((1, cols)),  # flat: the DC term
                           (np.abs(np.arange(cols) - cols / 2) < cols / 4)[None].astype(float)])  # a slab's profile
    response = ramp_response(cols, pitch, window, cutoff)
    assert response.shape == (padded_length(cols),) and len(response) >= 2 * cols
    via_fft = np.fft.ifft(np.fft.fft(rows, n=len(response), axis=1) * response, axis=1)
    assert np.abs(via_fft.imag).max() <= 1e-13 * np.abs(via_fft.real).max()  # a real, even response
    direct = ramp_filter_rows(rows, pitch, window, cutoff)
    error = np.abs(via_fft.real[:, :cols] - direct).max() / np.abs(direct).max()
    assert error <= TOLERANCE, f"{window} cut-off {cutoff}: relative error {error:.3g}"


@pytest.mark.parametrize("cols, pitch", [(64, 0.8), (33, 0.05)])
def test_unwindowed_kernel_is_kak_slaney_in_closed_form(cols, pitch):
    """Ram-Lak at cut-off 1 leaves the kernel untouched: h₀ = 1/(4τ), h_k = −1/(π²k²τ) for odd
    k, 0 for even k — written out here once more, term by term."""
    kernel = ramp_kernel(cols, pitch, "ram-lak", 1.0)
    for lag, value in zip(range(-(cols - 1), cols), kernel):
        if lag == 0:
            want = 1 / (4 * pitch)
        elif lag % 2:
            want = -1 / (math.pi**2 * lag**2 * pitch)
        else:
            want = 0.0
        assert value == pytest.approx(want, rel=1e-12, abs=1e-12 / pitch)
    assert np.array_equal(kak_slaney_kernel(np.arange(4), 2.0), [1 / 8, -1 / (2 * math.pi**2), 0, -1 / (18 * math.pi**2)])


def test_flat_row_is_filtered_to_almost_zero_in_its_middle():
    """Kak & Slaney's kernel sums to zero over all lags: a flat row filters, away from its ends,
    to the (positive) sum of the kernel's negative tail beyond the row, bounded analytically."""
    cols, pitch = 512, 0.2
    q = np.fft.ifft(np.fft.fft(np.ones(cols), n=padded_length(cols)) * ramp_response(cols, pitch)).real[:cols]
    middle = q[cols // 4 : 3 * cols // 4]
    # Remaining tail of Σ_k h_k beyond |k| ≥ cols/4: 2/(π²τ)·Σ_{odd k > cols/4} 1/k² ≈ 1/(π²τ·cols/4).
    assert np.abs(middle).max() < 1.1 / (math.pi**2 * pitch * cols / 4)
    assert q[cols // 2] > 0
