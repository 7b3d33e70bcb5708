"""The spectral table against the full sum over energy bins, written here in float64 NumPy."""

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.physics import beer_lambert
from xrayraster.physics.radiograph import attenuation_table
from xrayraster.physics.spectral_table import moment_weights, spectral_table

SPECTRUM = xr.Spectrum.from_tube(kvp=40.0, anode="W", filters={"Al": 2.0}, mas=1.25)
ENERGIES, PHOTONS = SPECTRUM.energies[SPECTRUM.fluence > 0], SPECTRUM.fluence[SPECTRUM.fluence > 0]
RESIN = xr.Material.from_mass_fractions({"C": 0.404, "H": 0.481, "Cl": 0.019, "O": 0.096}, density=1.08)
CARBON_A, CARBON_B = (xr.Material.from_formula("C", density=d) for d in (1.72, 1.82))
LONGEST_MM = 30.0


def _sums(lengths, mu, photons, efficiency, energies):
    """(E·η·N, E²·η·N, η·N) · exp(−μ·L) summed over bins, pixel by pixel: (pixels, 3)."""
    out = np.zeros((lengths.shape[1], 3))
    for b, e in enumerate(energies):
        n = photons[b] * efficiency[b] * np.exp(-(mu[:, b] @ lengths))
        out += np.stack([e * n, e * e * n, n], axis=1)
    return out


def _random_lengths(channels, pixels, seed=0):
    # Path lengths anywhere in the box, including 0 (air) and the longest chord.
    lengths = np.random.default_rng(seed).random((channels, pixels)) * LONGEST_MM
    lengths[:, :3] = np.transpose([[0.0] * channels, [LONGEST_MM] * channels, [0.0] * (channels - 1) + [LONGEST_MM]])
    return lengths


def test_two_densities_of_one_element_reduce_to_a_two_dimensional_table_within_tolerance():
    mu = attenuation_table([RESIN, CARBON_A, CARBON_B], ENERGIES)
    efficiency = np.linspace(1.0, 0.6, len(ENERGIES))  # any per-bin weights
    table = spectral_table(mu, moment_weights(PHOTONS, efficiency, ENERGIES), LONGEST_MM, tolerance=1e-5)
    assert len(table.shape) == 2  # resin and carbon: μ has rank 2, whatever the three densities
    assert 0 < table.error <= 1e-5
    lengths = _random_lengths(3, 20_000)
    got, inside = table.moments(lengths)
    want = _sums(lengths, mu, PHOTONS, efficiency, ENERGIES)
    assert inside.all()
    assert np.abs(got / want - 1).max() <= 1e-5


def test_a_tighter_tolerance_takes_a_finer_grid_and_meets_it():
    mu = attenuation_table([RESIN, CARBON_A], ENERGIES)
    q = moment_weights(PHOTONS, np.ones(len(ENERGIES)), ENERGIES)
    coarse, fine = (spectral_table(mu, q, LONGEST_MM, tolerance=t) for t in (1e-3, 1e-6))
    assert coarse.shape[0] < fine.shape[0]
    lengths = _random_lengths(2, 5000, seed=1)
    want = _sums(lengths, mu, PHOTONS, np.ones(len(ENERGIES)), ENERGIES)
    for table, tolerance in ((coarse, 1e-3), (fine, 1e-6)):
        assert np.abs(table.moments(lengths)[0] / want - 1).max() <= tolerance


def test_lengths_beyond_the_grid_are_flagged():
    mu = attenuation_table([RESIN, CARBON_A], ENERGIES)
    table = spectral_table(mu, moment_weights(PHOTONS, np.ones(len(ENERGIES)), ENERGIES), LONGEST_MM)
    lengths = np.array([[1.0, 3 * LONGEST_MM, -5.0], [1.0, 0.0, 0.0]])
    assert table.moments(lengths)[1].tolist() == [True, False, False]


def test_a_table_too_large_for_the_tolerance_is_refused():
    # Three unrelated materials (rank 3) at a 1e-9 tolerance would need > MAX_POINTS points.
    mu = attenuation_table([RESIN, xr.Material.from_formula("Al", density=2.7),
                            xr.Material.from_formula("CaCO3", density=2.71)], ENERGIES)
    assert spectral_table(mu, moment_weights(PHOTONS, np.ones(len(ENERGIES)), ENERGIES), LONGEST_MM, 1e-9) is None


@pytest.mark.parametrize("counting", [False, True])
def test_noisy_signal_from_the_table_has_the_exact_mean_and_variance(counting):
    """Many pixels with one path length: the sample mean and variance of the signal drawn through
    the table match Σ w·n and Σ w²·n (w = E for an integrating detector, 1 for counting)."""
    mu = attenuation_table([RESIN, CARBON_A], ENERGIES)
    efficiency = np.ones(len(ENERGIES))
    table = spectral_table(mu, moment_weights(PHOTONS, efficiency, ENERGIES), LONGEST_MM)
    lengths = np.broadcast_to(np.array([6.0, 3.0])[:, None, None], (2, 200, 500)).astype(np.float32)
    factor = 0.05  # photons per bin: PHOTONS × factor (a few 10⁴ in all)
    signal = beer_lambert.sampled_signal(lengths, mu, PHOTONS, efficiency, ENERGIES, factor, counting,
                                         np.random.default_rng(3), table=table)
    n = PHOTONS * factor * np.exp(-(mu.T @ np.array([6.0, 3.0])))
    w = np.ones_like(ENERGIES) if counting else ENERGIES
    mean, variance = (w * n).sum(), (w * w * n).sum()
    assert abs(signal.mean() / mean - 1) < 4 * np.sqrt(variance / signal.size) / mean
    assert abs(signal.var() / variance - 1) < 0.02  # 10⁵ draws: the variance's relative error is ~0.5 %


def test_pixels_expecting_few_photons_are_drawn_bin_by_bin_as_without_a_table():
    """Below EXACT_BELOW_PHOTONS the table path draws the same per-bin Poisson sums as the exact
    path: with one seed, both give the same bytes in those pixels."""
    mu = attenuation_table([RESIN, CARBON_A], ENERGIES)
    efficiency = np.ones(len(ENERGIES))
    table = spectral_table(mu, moment_weights(PHOTONS, efficiency, ENERGIES), LONGEST_MM)
    lengths = np.zeros((2, 4, 64), np.float32)
    lengths[0] = 25.0  # a thick path: few photons everywhere
    factor = 1e-5
    a, b = (beer_lambert.sampled_signal(lengths, mu, PHOTONS, efficiency, ENERGIES, factor, False,
                                        np.random.default_rng(7), table=t) for t in (None, table))
    expected = (PHOTONS * factor * np.exp(-mu[0] * 25.0)).sum()
    assert expected < beer_lambert.EXACT_BELOW_PHOTONS
    np.testing.assert_array_equal(a, b)


def test_a_renderer_with_the_table_draws_what_the_exact_sum_draws(gl):
    """Two slabs (resin, carbon) seen by a small detector, noise on, one seed: every pixel expects
    well over EXACT_BELOW_PHOTONS photons, so both paths draw the same normal deviates, and the
    line integrals differ only by the table's error (≤ 1e-5 of the signal: ≤ ~1e-5 in −ln)."""
    import trimesh

    scene = xr.Scene()
    scene.add(trimesh.creation.box((8.0, 8.0, 3.0)), RESIN, name="resin")
    scene.add(trimesh.creation.box((4.0, 4.0, 2.0)), CARBON_A, name="carbon",
              transform=xr.Transform.translation((0.0, 0.0, 3.0)))
    geometry = xr.ConeBeamGeometry(60.0, 140.0, (24, 32), 0.5, xr.full_circle(4))
    with xr.Renderer(geometry, context=gl) as renderer:
        exact, tabled = (renderer.project_all(scene, SPECTRUM, noise=True, seed=5, spectral_table=t) for t in (False, True))
    assert "spectral_table" not in exact.provenance
    assert tabled.provenance["spectral_table"]["error"] <= 1e-5 and len(tabled.provenance["spectral_table"]["grid"]) == 2
    assert np.abs(tabled.data - exact.data).max() <= 2e-5
