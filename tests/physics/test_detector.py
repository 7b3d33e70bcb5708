"""Detector model: efficiency, per-photon weights, point spread, read-out noise, validation."""

from __future__ import annotations

import numpy as np
import pytest

from xrayraster.physics.detector import Detector
from xrayraster.physics.beer_lambert import PhysicsError


class Slab:
    """A stand-in material with a known μ(E) = 2 mm⁻¹ · (20 keV / E)³."""

    def attenuation(self, energies_kev):
        return 2.0 * (20.0 / np.asarray(energies_kev)) ** 3


def test_efficiency_and_weights():
    e = np.array([20.0, 40.0, 80.0])
    plain = Detector()
    np.testing.assert_array_equal(plain.efficiency(e), 1.0)
    np.testing.assert_array_equal(plain.weights(e), e)
    scint = Detector(scintillator=Slab(), scintillator_mm=0.5)
    eta = 1 - np.exp(-2.0 * (20.0 / e) ** 3 * 0.5)
    np.testing.assert_allclose(scint.efficiency(e), eta, rtol=1e-14)
    np.testing.assert_allclose(scint.weights(e), e * eta, rtol=1e-14)
    np.testing.assert_allclose(Detector("counting", Slab(), 0.5).weights(e), eta, rtol=1e-14)


def test_gaussian_blur_of_a_point_is_the_sampled_gaussian():
    image = np.zeros((41, 41))
    image[20, 20] = 1.0
    sigma = 1.7
    out = Detector(blur_sigma_px=sigma).blur(image)
    x = np.arange(-20, 21)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    g[np.abs(x) > np.ceil(4 * sigma)] = 0
    want = np.outer(g, g) / g.sum() ** 2
    np.testing.assert_allclose(out, want, atol=1e-15)
    assert out.sum() == pytest.approx(1.0)


def test_user_psf_is_a_convolution_not_a_correlation():
    image = np.zeros((7, 7))
    image[3, 3] = 1.0
    psf = np.zeros((3, 3))
    psf[1, 2] = 3.0  # all light goes one pixel to the right (+column)
    out = Detector(psf=psf).blur(image)
    assert out[3, 4] == pytest.approx(1.0) and out.sum() == pytest.approx(1.0)


def test_read_out_adds_dark_and_electronic_noise():
    flat = np.full((300, 400), 50.0)
    det = Detector(dark=10.0, electronic_noise=2.0)
    np.testing.assert_array_equal(det.read_out(flat, None), 60.0)
    noisy = det.read_out(flat, np.random.default_rng(3))
    n = noisy.size
    assert abs(noisy.mean() - 60.0) <= 5 * 2.0 / np.sqrt(n)
    assert abs(noisy.std() - 2.0) <= 5 * 2.0 / np.sqrt(2 * n)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"mode": "spectral"}, "mode must be"),
        ({"blur_sigma_px": -1}, "blur_sigma_px must be"),
        ({"electronic_noise": float("nan")}, "electronic_noise must be"),
        ({"scintillator": Slab()}, "both scintillator"),
        ({"scintillator_mm": 0.3}, "both scintillator"),
        ({"psf": np.ones((2, 2))}, "odd size"),
        ({"psf": -np.ones((3, 3))}, "non-negative"),
        ({"psf": np.ones((3, 3)), "blur_sigma_px": 1.0}, "not both"),
    ],
)
def test_bad_detectors_are_refused(kwargs, match):
    with pytest.raises(PhysicsError, match=match):
        Detector(**kwargs)
