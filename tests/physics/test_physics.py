"""Spectral Beer–Lambert, noise and normalisation against float64 references and Poisson statistics."""

from __future__ import annotations

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.physics import beer_lambert as physics

ENERGIES = np.arange(15.0, 80.0, 1.0)  # keV
PHOTONS = np.exp(-0.5 * ((ENERGIES - 40.0) / 12.0) ** 2) * 1e3  # photons per mm² at 1 m per bin


def mu_like(scale: float) -> np.ndarray:
    """A photoelectric-plus-scatter shape, mm⁻¹: falls steeply with energy, like real materials."""
    return scale * (0.02 + 8000.0 / ENERGIES**3)


def reference_signal(lengths, mu, photons, weights, factor):
    """Pixel-by-pixel, bin-by-bin float64 sum: the definition, written out."""
    c, rows, cols = lengths.shape
    out = np.zeros((rows, cols))
    for i in range(rows):
        for j in range(cols):
            for b in range(len(photons)):
                out[i, j] += weights[b] * photons[b] * factor[i, j] * np.exp(-sum(mu[k, b] * float(lengths[k, i, j]) for k in range(c)))
    return out


def test_monochromatic_line_integral_is_mu_times_length():
    rng = np.random.default_rng(1)
    lengths = rng.uniform(0, 30, (2, 40, 50)).astype(np.float32)
    mu = np.array([[0.05], [0.3]])
    factor = np.ones((40, 50))
    signal = physics.expected_signal(lengths, mu, [1e4], [30.0], factor)
    flat = physics.expected_signal(np.zeros_like(lengths), mu, [1e4], [30.0], factor)
    got = physics.normalise(signal, flat, 0.0, floor=1e-300).line_integral
    want = np.tensordot(mu[:, 0], lengths.astype(np.float64), axes=1)
    assert np.abs(got - want).max() <= 1e-6 * want.max()


@pytest.mark.parametrize("channels", [1, 3])
def test_polychromatic_transmission_equals_the_float64_definition(channels):
    rng = np.random.default_rng(channels)
    lengths = rng.uniform(0, 8, (channels, 12, 9)).astype(np.float32)
    mu = np.stack([mu_like(s) for s in (1.0, 2.7, 0.4)[:channels]])
    factor = rng.uniform(0.5, 1.0, (12, 9))
    weights = ENERGIES * 0.8
    got = physics.expected_signal(lengths, mu, PHOTONS, weights, factor)
    want = reference_signal(lengths, mu, PHOTONS, weights, factor)
    np.testing.assert_allclose(got, want, rtol=1e-10)
    flat = physics.expected_signal(np.zeros_like(lengths), mu, PHOTONS, weights, factor)
    want_t = want / reference_signal(np.zeros_like(lengths), mu, PHOTONS, weights, factor)
    np.testing.assert_allclose(physics.normalise(got, flat, 0.0, 1e-300).transmission, want_t, rtol=1e-5)


def test_pixels_that_miss_every_object_are_the_open_beam_bit_for_bit():
    """Rays through nothing skip the spectral sum: their signal is the flat the radiograph divides
    by, to the last bit (line integral exactly 0), and the crossed pixels still equal the definition."""
    rng = np.random.default_rng(4)
    lengths = rng.uniform(0, 8, (2, 12, 9)).astype(np.float32)
    lengths[:, :, :4] = 0.0  # air
    lengths[0, 0, 0] = 1e-30  # a graze: crossed, however little
    mu = np.stack([mu_like(1.0), mu_like(2.7)])
    factor = rng.uniform(0.5, 1.0, (12, 9))
    weights = ENERGIES * 0.8
    got = physics.expected_signal(lengths, mu, PHOTONS, weights, factor, threads=2)
    open_beam = (PHOTONS * weights).sum() * factor  # the flat as radiograph._exact_flat makes it
    air = ~lengths.any(axis=0)
    assert np.array_equal(got[air], open_beam[air]) and air.sum() == 12 * 4 - 1
    np.testing.assert_allclose(got[~air], reference_signal(lengths, mu, PHOTONS, weights, factor)[~air], rtol=1e-10)
    assert np.all(physics.normalise(got, open_beam, 0.0, 1e-300).line_integral[air] == 0.0)


def test_photon_factor_follows_inverse_square_and_obliquity():
    geom = xr.ConeBeamGeometry(500.0, 1000.0, (5, 7), 40.0, [0.3])
    factor = physics.pixel_photon_factor(geom, 0)
    area = 40.0**2
    # Centre pixel: on the axis, 1 m from the source.
    assert factor[2, 3] == pytest.approx(area, rel=1e-12)
    # Corner pixel: offsets (2, 3) pixels: distance r, cos = 1000 / r.
    r = np.sqrt(1000.0**2 + (2 * 40.0) ** 2 + (3 * 40.0) ** 2)
    assert factor[0, 0] == pytest.approx(area * (1000.0 / r) * (1000.0 / r) ** 2, rel=1e-12)
    parallel = physics.pixel_photon_factor(xr.ParallelBeamGeometry((3, 4), 0.5, [1.0]), 0)
    np.testing.assert_allclose(parallel, 0.25)


@pytest.mark.parametrize("counting, scale", [(True, 0.05), (False, 0.05), (False, 20.0)])
def test_noise_mean_and_variance_match_poisson(counting, scale):
    """10⁵ pixels with the same expected photons: sample mean and variance against the exact
    compound-Poisson moments, within 5 standard errors computed from n. Scale 0.05: ~100
    photons per pixel (drawn bin by bin); 20: ~40 000 (the moment-exact Gaussian)."""
    n = 100_000
    lengths = np.full((1, 250, 400), 3.0, np.float32)
    mu = mu_like(1.0)[None]
    photons = PHOTONS * scale
    efficiency = np.linspace(0.9, 0.6, len(ENERGIES))
    detected = photons * efficiency * np.exp(-mu[0] * 3.0)  # per bin, per pixel
    w = np.ones_like(ENERGIES) if counting else ENERGIES
    mean, var = (w * detected).sum(), (w**2 * detected).sum()
    fourth = (w**4 * detected).sum() + 3 * var**2  # 4th central moment of a compound Poisson sum
    exact = detected.sum() < physics.EXACT_BELOW_PHOTONS
    assert exact == (scale < 1) or counting
    sample = physics.sampled_signal(lengths, mu, photons, efficiency, ENERGIES, 1.0, counting, np.random.default_rng(7))
    assert sample.size == n
    assert abs(sample.mean() - mean) <= 5 * np.sqrt(var / n)
    assert abs(sample.var(ddof=1) - var) <= 5 * np.sqrt((fourth - var**2) / n)
    if counting or exact:  # whole photons (of whole-keV energies here)
        assert np.all(sample == np.round(sample))


def test_same_seed_same_bytes_and_different_seeds_differ():
    lengths = np.random.default_rng(0).uniform(0, 5, (2, 30, 30)).astype(np.float32)
    mu = np.stack([mu_like(1.0), mu_like(2.0)])
    args = (lengths, mu, PHOTONS, np.ones_like(ENERGIES), ENERGIES, 1.0, False)
    a = physics.sampled_signal(*args, np.random.default_rng(42))
    b = physics.sampled_signal(*args, np.random.default_rng(42))
    c = physics.sampled_signal(*args, np.random.default_rng(43))
    assert a.tobytes() == b.tobytes() and a.tobytes() != c.tobytes()


def test_beam_hardening_effective_mu_falls_with_thickness():
    """A step wedge: μ_eff = −ln(T)/t falls with t, exactly as the float64 definition says."""
    steps = np.array([0.5, 1, 2, 4, 8, 16, 32.0])
    lengths = steps[None, None, :].astype(np.float32)
    mu = mu_like(1.0)[None]
    w = ENERGIES
    signal = physics.expected_signal(lengths, mu, PHOTONS, w, np.ones((1, len(steps))))
    flat = (PHOTONS * w).sum()
    mu_eff = -np.log(signal[0] / flat) / steps
    want = np.array([-np.log((PHOTONS * w * np.exp(-mu[0] * t)).sum() / flat) / t for t in steps])
    np.testing.assert_allclose(mu_eff, want, rtol=1e-10)
    assert np.all(np.diff(mu_eff) < 0)
    assert mu_eff[0] / mu_eff[-1] > 1.5  # visibly harder


def test_starved_pixels_are_clamped_and_counted():
    raw = np.array([[5.0, 0.0, -2.0, 1.0]])
    out = physics.normalise(raw, np.full((1, 4), 10.0), 1.0, floor=0.5)
    assert out.starved == 3  # 0, -2 and 1 are all at or below the dark level 1
    np.testing.assert_allclose(out.transmission, [[4 / 9, 0.5 / 9, 0.5 / 9, 0.5 / 9]])
    assert np.all(np.isfinite(out.line_integral))


def test_bad_shapes_and_flat_are_refused():
    with pytest.raises(physics.PhysicsError, match="mu must be"):
        physics.expected_signal(np.zeros((2, 3, 3)), np.zeros((1, 4)), np.ones(4), np.ones(4), 1.0)
    with pytest.raises(physics.PhysicsError, match="photons must have one value per energy bin"):
        physics.expected_signal(np.zeros((1, 3, 3)), np.zeros((1, 4)), np.ones(3), np.ones(4), 1.0)
    with pytest.raises(physics.PhysicsError, match="flat field is not above the dark"):
        physics.normalise(np.ones((2, 2)), np.ones((2, 2)), 1.0, 0.5)


def test_threads_is_the_pool_size_and_changes_no_byte(monkeypatch):
    """threads=1 runs without a pool (a Dask worker's share), threads=3 asks a pool for 3 workers,
    and both give the bytes of the default (every core), with and without noise."""
    rng = np.random.default_rng(5)
    lengths = rng.uniform(0, 30, (2, 300, 40))
    mu = np.stack([mu_like(0.05), mu_like(0.02)])
    factor = np.full((300, 40), 2.0)
    sizes = []
    pool = physics.ThreadPoolExecutor

    def recording(workers):
        sizes.append(workers)
        return pool(workers)

    def signals(threads):
        expected = physics.expected_signal(lengths, mu, PHOTONS, ENERGIES, factor, threads)
        noisy = physics.sampled_signal(lengths, mu, PHOTONS, np.ones_like(ENERGIES), ENERGIES, factor, False,
                                       np.random.default_rng(9), threads)
        return expected.tobytes() + noisy.tobytes()

    monkeypatch.setattr(physics, "ThreadPoolExecutor", recording)
    assert len(physics._row_blocks(len(ENERGIES), 300, 40)) >= 3  # enough blocks for 3 workers
    default = signals(None)
    sizes.clear()
    assert signals(1) == default and sizes == []
    assert signals(3) == default and sizes == [3, 3]
    with pytest.raises(xr.PhysicsError, match="threads must be a positive integer"):
        physics.expected_signal(lengths, mu, PHOTONS, ENERGIES, factor, 0)
    with pytest.raises(xr.PhysicsError, match="threads must be a positive integer"):
        xr.Renderer(xr.ParallelBeamGeometry(4, 1.0, [0.0]), threads=-2)
