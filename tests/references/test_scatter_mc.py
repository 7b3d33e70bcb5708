"""The Monte-Carlo scatter reference (references/scatter_mc.py) against what can be computed
without it: the primary through a cylinder from its chords, and the scatter behind a slab too thin
for a photon to scatter twice from a deterministic single-scatter integral over the slab."""

import math

import numpy as np
import pytest

from references.scatter_mc import ELECTRON_REST_KEV, Setup, primary_image, simulate

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


def _single_scatter(setup: Setup, energy: float, pixels: np.ndarray) -> np.ndarray:
    """Scatter energy per source photon (into 4π) reaching each pixel (centre, pixel's solid angle)
    behind ``setup``'s slab: the slab cut in cells, each scattering the primary fluence reaching it
    into the pixel by ρ · dσ/dΩ (Compton at the Compton energy, Rayleigh at the primary's), both
    attenuated by half the slab (it is thin)."""
    theta = np.linspace(1e-4, math.pi, 4000)

    def table(dcs):
        values = np.full(len(theta), np.nan)
        for k, t in enumerate(theta):
            try:
                values[k] = dcs("H2O", energy, float(t))
            except ValueError:  # beyond xraylib's tables at the smallest angles: the nearest value
                pass
        bad = np.isnan(values)
        values[bad] = np.interp(np.flatnonzero(bad), np.flatnonzero(~bad), values[~bad])
        return values

    compton, rayleigh = table(xraylib.DCS_Compt_CP), table(xraylib.DCS_Rayl_CP)
    mu = xraylib.CS_Total_CP("H2O", energy) * setup.density / 10
    n, layers = 241, 4
    xs = np.linspace(-setup.width_mm / 2, setup.width_mm / 2, n)
    zs = np.linspace(-setup.height_mm / 2, setup.height_mm / 2, n)
    ys = -setup.thickness_mm / 2 + (np.arange(layers) + 0.5) * setup.thickness_mm / layers
    cell = (xs[1] - xs[0]) * (zs[1] - zs[0]) * setup.thickness_mm / layers  # mm³ (edges: half weight below)
    y, x, z = np.meshgrid(ys, xs, zs, indexing="ij")
    q = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    edge = ((np.abs(q[:, 0]) == xs[-1]).astype(float) + (np.abs(q[:, 2]) == zs[-1])) * 0.5
    share = 1.0 - edge + edge * edge / 2  # trapezoid weights in x and z
    source = np.array([0.0, -setup.source_to_origin, 0.0])
    incoming = q - source
    r_in = np.linalg.norm(incoming, axis=1)
    fluence = np.exp(-mu * setup.thickness_mm / 2) / (4 * math.pi * r_in**2)  # photons per mm² at q
    out = []
    for p in pixels:
        outgoing = p - q
        r_out = np.linalg.norm(outgoing, axis=1)
        cos = np.clip(np.einsum("ij,ij->i", incoming / r_in[:, None], outgoing / r_out[:, None]), -1.0, 1.0)
        angle = np.arccos(cos)
        solid = setup.pixel_mm**2 * outgoing[:, 1] / r_out**3
        e_compton = energy / (1 + energy / ELECTRON_REST_KEV * (1 - cos))
        per_sr = setup.density / 10 * (np.interp(angle, theta, compton) * e_compton
                                       + np.interp(angle, theta, rayleigh) * energy)  # keV per mm per sr
        out.append(np.sum(fluence * per_sr * solid * share * np.exp(-mu * setup.thickness_mm / 2)) * cell)
    return np.array(out)


def test_the_scatter_behind_a_thin_slab_is_the_single_scatter_integral():
    """A 1 mm water slab (0.5 % of photons scatter, so almost never twice) at 30 keV, 8 mm pixels:
    the Monte Carlo's scatter in the 4 × 4 middle pixels against the integral, within 6 % (their
    photons give a statistical error of about 2 %; measured 2.7 % apart at this seed)."""
    setup = Setup((30.0,), (1.0,), shape="slab", thickness_mm=1.0, width_mm=80.0, height_mm=80.0, rows=6, cols=6,
                  pixel_mm=8.0)
    result = simulate(setup, 12_000_000, seed=1, batch=500_000)
    y = setup.source_to_detector - setup.source_to_origin
    middle = np.array([[x, y, z] for z in (-12.0, -4.0, 4.0, 12.0) for x in (-12.0, -4.0, 4.0, 12.0)])
    want = _single_scatter(setup, 30.0, middle)
    got = result.scatter[1:5, 1:5].ravel()
    print("Monte Carlo", got.sum(), "integral", want.sum(), "photons", result.scattered_hits)
    assert abs(got.sum() / want.sum() - 1) < 0.06
