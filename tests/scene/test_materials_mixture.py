"""Material.mixture: ideal mixtures by volume or mass, checked against the physics they must obey."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from xrayraster import Material
from xrayraster.core.errors import MaterialError

ENERGIES_KEV = np.array([8.0, 20.0, 35.0, 60.0, 100.0, 150.0, 500.0])
# Material rounds mass fractions to 12 significant digits: up to 5e-12 relative per element.
RTOL = 5e-12
CARBON = Material.named("carbon_fibre")   # C, 1.76 g/cm³
EPOXY = Material.named("epoxy")           # C21H24O4, 1.16 g/cm³
GLASS = Material.named("e_glass")         # oxides, 2.54 g/cm³


def test_volume_mixture_attenuates_as_the_volume_weighted_sum_of_its_parts():
    """A ray through a volume mixture meets each part over its volume fraction of the path."""
    parts = [(CARBON, 0.5), (EPOXY, 0.3), (GLASS, 0.2)]
    mix = Material.mixture(parts)
    expected = sum(f * m.attenuation_per_mm(ENERGIES_KEV) for m, f in parts)
    np.testing.assert_allclose(mix.attenuation_per_mm(ENERGIES_KEV), expected, rtol=RTOL, atol=0)


def test_mass_mixture_has_the_mass_weighted_mass_attenuation():
    parts = [(CARBON, 0.25), (GLASS, 0.75)]
    mix = Material.mixture(parts, by="mass")
    expected = sum(m * mat.mass_attenuation(ENERGIES_KEV) for mat, m in parts)
    np.testing.assert_allclose(mix.mass_attenuation(ENERGIES_KEV), expected, rtol=RTOL, atol=0)


def test_densities_by_hand():
    assert Material.mixture([(CARBON, 0.6), (EPOXY, 0.4)]).density == pytest.approx(0.6 * 1.76 + 0.4 * 1.16,
                                                                                    rel=1e-15)
    # 1 g of a 50/50 mass mix takes 0.5/1.76 + 0.5/1.16 cm³
    by_mass = Material.mixture([(CARBON, 0.5), (EPOXY, 0.5)], by="mass")
    assert by_mass.density == pytest.approx(1 / (0.5 / 1.76 + 0.5 / 1.16), rel=1e-15)


def test_composition_by_hand():
    # 1 cm³ of half carbon (2 g/cm³) and half water (1 g/cm³) holds 1 g of C and 0.5 g of water
    carbon = Material.element("C", 2.0)
    water = Material.from_formula("H2O", 1.0)
    mix = Material.mixture([(carbon, 0.5), (water, 0.5)])
    w_h = water.mass_fractions["H"]
    assert mix.density == 1.5
    assert mix.mass_fractions["C"] == pytest.approx(1.0 / 1.5, rel=1e-11)
    assert mix.mass_fractions["H"] == pytest.approx(0.5 * w_h / 1.5, rel=1e-11)
    assert mix.mass_fractions["O"] == pytest.approx(0.5 * (1 - w_h) / 1.5, rel=1e-11)


def test_volume_and_mass_fractions_describe_the_same_mixture():
    f = 0.6
    rho = f * CARBON.density + (1 - f) * EPOXY.density
    m = f * CARBON.density / rho
    by_volume = Material.mixture([(CARBON, f), (EPOXY, 1 - f)])
    by_mass = Material.mixture([(CARBON, m), (EPOXY, 1 - m)], by="mass")
    assert by_mass.density == pytest.approx(by_volume.density, rel=1e-14)
    for (z1, w1), (z2, w2) in zip(by_volume.composition, by_mass.composition, strict=True):
        assert z1 == z2 and w1 == pytest.approx(w2, rel=1e-11)


@pytest.mark.parametrize("by", ["volume", "mass"])
def test_a_material_mixed_with_itself_is_that_material(by):
    mix = Material.mixture([(GLASS, 0.3), (GLASS, 0.7)], by=by)
    assert mix.composition == GLASS.composition
    assert mix.density == pytest.approx(GLASS.density, rel=1e-15)


def test_a_zero_fraction_adds_nothing():
    mix = Material.mixture([(CARBON, 1.0), (GLASS, 0.0)])
    assert mix.composition == CARBON.composition and mix.density == pytest.approx(CARBON.density, rel=1e-15)


def test_names():
    assert Material.mixture([(CARBON, 0.6), (EPOXY, 0.4)]).name == "0.6 carbon_fibre + 0.4 epoxy (by volume)"
    assert Material.mixture([(CARBON, 0.5), (EPOXY, 0.5)], by="mass").name == \
        "0.5 carbon_fibre + 0.5 epoxy (by mass)"
    assert Material.mixture([(CARBON, 1.0)], name="tow").name == "tow"


def test_fractions_slightly_off_are_normalised_with_a_warning():
    with pytest.warns(UserWarning, match="parts: volume fractions sum to 1.001"):
        mix = Material.mixture([(CARBON, 0.6), (EPOXY, 0.401)])
    assert mix.density == pytest.approx((0.6 * 1.76 + 0.401 * 1.16) / 1.001, rel=1e-14)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # within 1e-6: silent
        Material.mixture([(CARBON, 0.6), (EPOXY, 0.4000005)])


@pytest.mark.parametrize("parts, by, match", [
    ([(CARBON, 0.6), (EPOXY, 0.3)], "volume", r"parts: volume fractions sum to 0\.9, not 1"),
    ([(CARBON, 60), (EPOXY, 40)], "mass", r"parts: mass fractions sum to 100, not 1"),
    ([(CARBON, 1.2), (EPOXY, -0.2)], "volume", r"parts\[1\]: volume fraction of epoxy must be finite and >= 0"),
    ([(CARBON, math.nan), (EPOXY, 1.0)], "volume", r"parts\[0\].*finite"),
    ([(CARBON, "a lot"), (EPOXY, 0.4)], "volume", r"parts\[0\].*must be a number"),
    ([], "volume", r"parts: no materials given"),
    ([("carbon_fibre", 1.0)], "volume", r"parts\[0\]: expected a Material"),
    ([CARBON], "volume", r"parts: expected \(Material, fraction\) pairs"),
    ([(CARBON, 1.0)], "weight", r"by: expected 'volume' or 'mass'"),
])
def test_bad_parts_name_the_field(parts, by, match):
    with pytest.raises(MaterialError, match=match):
        Material.mixture(parts, by=by)
