"""The Monte-Carlo scatter reference (references/scatter_mc.py) against what can be computed
without it: the primary through a cylinder from its chords, and the scatter behind a slab too thin
for a photon to scatter twice from a deterministic single-scatter integral over the slab."""

import math

import numpy as np
import pytest

from references.scatter_mc import Setup, primary_image, simulate, single_scatter

xraylib = pytest.importorskip("xraylib")


def test_the_primary_is_beer_lambert_along_each_chord():
    """The middle row of an odd number of rows lies in the plane z = 0, where a ray at distance b
    from the cylinder's axis crosses it along 2 √(R² − b²)."""
    energies, weights = (20.0, 30.0, 40.0), (1.0, 2.0, 1.0)
    setup = Setup(energies, weights, rows=5, cols=40, pixel_mm=2.0, diameter_mm=30.0)
    source = np.array([0.0, -setup.source_to_origin])
    x = (np.arange(setup.cols) - (setup.cols - 1) / 2) * setup.pixel_mm
    to = np.column_stack([x, np.full(setup.cols, setup.source_to_detector - setup.source_to_origin)]) - source
    distance = np.linalg.norm(to, axis=1)
    d = to / distance[:, None]
    b = np.abs(source[0] * d[:, 1] - source[1] * d[:, 0])  # |source × d|: the ray's distance from the axis
    chord = 2 * np.sqrt(np.maximum((setup.diameter_mm / 2) ** 2 - b**2, 0.0))
    mu = np.array([xraylib.CS_Total_CP("H2O", e) / 10 for e in energies])  # 1/mm at 1 g/cm³
    w = np.array(weights) / sum(weights)
    want = (w * np.array(energies) * np.exp(-np.outer(chord, mu))).sum(axis=1)
    want *= setup.pixel_mm**2 * d[:, 1] / distance**2 / (4 * math.pi)
    np.testing.assert_allclose(primary_image(setup)[2], want, rtol=1e-9)
    assert chord.max() > 29.0 and chord.min() == 0.0  # through the middle and past the sides


def test_the_scatter_behind_a_thin_slab_is_the_single_scatter_integral():
    """A 1 mm water slab (0.5 % of photons scatter, so almost never twice) at 30 keV, 8 mm pixels:
    the Monte Carlo's scatter in the 4 × 4 middle pixels against the integral, within 6 % (their
    photons give a statistical error of about 2 %; measured 2.7 % apart at this seed)."""
    setup = Setup((30.0,), (1.0,), shape="slab", thickness_mm=1.0, width_mm=80.0, height_mm=80.0, rows=6, cols=6,
                  pixel_mm=8.0)
    result = simulate(setup, 12_000_000, seed=1, batch=500_000)
    y = setup.source_to_detector - setup.source_to_origin
    middle = np.array([[x, y, z] for z in (-12.0, -4.0, 4.0, 12.0) for x in (-12.0, -4.0, 4.0, 12.0)])
    want = single_scatter(setup, 30.0, middle)
    got = result.scatter[1:5, 1:5].ravel()
    print("Monte Carlo", got.sum(), "integral", want.sum(), "photons", result.scattered_hits)
    assert abs(got.sum() / want.sum() - 1) < 0.06
