"""Spectrum: SpekPy units and conversion, inverse square, trimming, file I/O, errors.

References are independent of the code under test: SpekPy is called directly here with its own
documented units ([photons cm⁻² keV⁻¹] at z cm for the Spek's mAs), and trimming is re-checked by
summing the dropped contributions from scratch.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

spekpy = pytest.importorskip("spekpy")

from xrayraster import Spectrum, SpectrumError
from xrayraster.physics.spectrum import REFERENCE_DISTANCE_MM

# Two tube set-ups, each made once per module (a SpekPy spectrum costs ~0.2–0.6 s).
TUBES = {
    "40kVp_W_2mmAl_mas10": {"kvp": 40.0, "anode": "W", "anode_angle_deg": 12.0, "filters": {"Al": 2.0}, "mas": 10.0, "bin_kev": 0.5},
    "120kVp_W_1mmCu_mas2": {"kvp": 120.0, "anode": "W", "anode_angle_deg": 12.0, "filters": {"Cu": 1.0, "Al": 0.5}, "mas": 2.0, "bin_kev": 1.0},
}


def _spekpy_reference(p):
    """SpekPy directly: the Spek object and its (k, [photons cm⁻² keV⁻¹]) at its default z."""
    s = spekpy.Spek(kvp=p["kvp"], th=p["anode_angle_deg"], targ=p["anode"], dk=p["bin_kev"], mas=p["mas"])
    for material, t in p["filters"].items():
        s.filter(material, t)  # thickness in mm (SpekPy DataTables.get_mu_t: "[mm]")
    return s


@pytest.fixture(scope="module", params=sorted(TUBES))
def tube(request):
    p = TUBES[request.param]
    return p, Spectrum.from_tube(**p), _spekpy_reference(p)


def test_from_tube_matches_spekpy_after_unit_conversion(tube):
    p, ours, ref = tube
    assert ref.state.spectrum_parameters.z == 100.0  # SpekPy's default distance is 100 cm = our 1 m
    k, per_kev_per_cm2 = ref.get_spectrum()  # mid-bin keV, photons cm⁻² keV⁻¹ at 100 cm, for mas
    expected = per_kev_per_cm2 * p["bin_kev"] / 100.0  # × keV per bin, ÷ 100 mm² per cm²
    np.testing.assert_allclose(ours.energies, k, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours.fluence, expected, rtol=1e-12, atol=0)
    assert ours.fluence.dtype == np.float64 and ours.energies.dtype == np.float64
    # A second SpekPy route: its integrated fluence [photons cm⁻²] ÷ 100.
    assert ours.total == pytest.approx(ref.get_flu() / 100.0, rel=1e-9)
    assert f"{p['kvp']:g} kVp" in ours.description and "mAs" in ours.description


def test_from_tube_distance_option_is_inverse_square(tube):
    """SpekPy at z = 50 cm equals our 1 m spectrum taken to 500 mm (1 mm² pixel, normal incidence)."""
    p, ours, ref = tube
    _, at_50cm = ref.get_spectrum(z=50.0)
    expected = at_50cm * p["bin_kev"] / 100.0
    np.testing.assert_allclose(ours.photons_per_pixel(500.0, 1.0), expected, rtol=1e-12, atol=0)


def test_from_tube_scales_linearly_with_mas():
    p = dict(TUBES["40kVp_W_2mmAl_mas10"])
    ten = Spectrum.from_tube(**p)
    p["mas"] = 2.5
    quarter = Spectrum.from_tube(**p)
    assert ten.total == pytest.approx(4.0 * quarter.total, rel=1e-12)
    np.testing.assert_allclose(ten.fluence, 4.0 * quarter.fluence, rtol=1e-12)
    np.testing.assert_array_equal(ten.energies, quarter.energies)


def test_a_tube_seen_again_reuses_its_model_and_gives_a_new_speks_spectrum_bit_for_bit():
    """The same tube at another mAs (as a dataset drawing the exposure makes it): the SpekPy model
    is reused, and the spectrum equals a new Spek's made with that mAs, bit for bit."""
    from xrayraster.physics.spectrum import _tube_model

    p = dict(TUBES["120kVp_W_1mmCu_mas2"])
    Spectrum.from_tube(**p)
    hits = _tube_model.cache_info().hits
    for mas in (0.37, 2.0, 11.5):
        p["mas"] = mas
        ours = Spectrum.from_tube(**p)
        k, per_kev_per_cm2 = _spekpy_reference(p).get_spectrum()
        np.testing.assert_array_equal(ours.fluence, np.asarray(per_kev_per_cm2) * p["bin_kev"] / 100.0)
        np.testing.assert_array_equal(ours.energies, k)
        assert f"{mas:g} mAs" in ours.description
    assert _tube_model.cache_info().hits == hits + 3


def test_photons_per_pixel_inverse_square_area_obliquity():
    spec = Spectrum.from_arrays([20.0, 30.0, 40.0], [1.0e3, 3.7e3, 0.9e3])
    at_1m = spec.photons_per_pixel(1000.0, 1.0)
    np.testing.assert_array_equal(at_1m, spec.fluence)
    np.testing.assert_array_equal(spec.photons_per_pixel(500.0, 1.0), 4.0 * at_1m)  # exactly
    np.testing.assert_array_equal(spec.photons_per_pixel(2000.0, 1.0), 0.25 * at_1m)
    np.testing.assert_allclose(spec.photons_per_pixel(1000.0, 0.0723**2), 0.0723**2 * at_1m, rtol=1e-15)
    np.testing.assert_allclose(spec.photons_per_pixel(1000.0, 1.0, cos_obliquity=0.5), 0.5 * at_1m, rtol=1e-15)
    # Broadcast: bins first, then the pixel grid.
    d = np.array([[500.0, 1000.0], [2000.0, 1000.0]])
    cos = np.array([1.0, 0.8])
    grid = spec.photons_per_pixel(d, 0.01, cos)
    assert grid.shape == (3, 2, 2)
    for r in range(2):
        for c in range(2):
            np.testing.assert_allclose(grid[:, r, c], spec.fluence * (1000.0 / d[r, c]) ** 2 * 0.01 * cos[c], rtol=1e-14)
    for bad in ({"distance_mm": 0.0}, {"distance_mm": -5.0}, {"pixel_area_mm2": 0.0}, {"cos_obliquity": 1.5}):
        args = {"distance_mm": 1000.0, "pixel_area_mm2": 1.0, "cos_obliquity": 1.0} | bad
        with pytest.raises(SpectrumError, match=next(iter(bad))):
            spec.photons_per_pixel(**args)
    assert REFERENCE_DISTANCE_MM == 1000.0


def _check_trim(spec: Spectrum, out: Spectrum, tol: float, weights=None):
    """Independent check: dropped bins' contribution ≤ tol·total, smallest dropped first, greedy."""
    e = spec.energies
    w = e if weights is None else np.asarray(weights, dtype=float)
    contrib = {float(ei): float(ni * wi) for ei, ni, wi in zip(e, spec.fluence, w)}
    kept = [float(x) for x in out.energies]
    assert kept == sorted(kept) and set(kept) <= set(contrib)  # order kept, no new bins
    for ei, ni in zip(out.energies, out.fluence):  # photon counts unchanged
        assert ni == spec.fluence[list(e).index(ei)]
    dropped = [c for ei, c in contrib.items() if ei not in set(kept)]
    total = math.fsum(contrib.values())
    if len(kept) > 1:
        assert math.fsum(dropped) <= tol * total * (1 + 1e-12)
        # Greedy and maximal: the smallest kept bin would push the dropped sum over the budget.
        smallest_kept = min(contrib[k] for k in kept)
        assert all(c <= smallest_kept for c in dropped)
        assert math.fsum(dropped) + smallest_kept > tol * total
    assert all(contrib[k] > 0 for k in kept)  # zero contributions never kept (one-bin case too)
    return dropped, total


def test_trimmed_drops_at_most_tolerance_of_energy_weighted_signal(tube):
    _, spec, _ = tube
    for tol in (1e-6, 1e-4, 1e-2, 0.2):
        out = spec.trimmed(tol)
        dropped, total = _check_trim(spec, out, tol)
        keep, fraction = spec.trim_mask(tol)
        assert keep.sum() == len(out)
        assert fraction == pytest.approx(math.fsum(dropped) / total, rel=1e-9, abs=1e-300)
        assert "trimmed" in out.description
    assert len(spec.trimmed(1e-2)) < len(spec.trimmed(1e-6)) <= len(spec)


def test_trimmed_zero_tolerance_keeps_every_nonzero_bin_and_drops_zero_bins():
    spec = Spectrum.from_arrays([10.0, 11.0, 12.0, 13.0, 14.0], [0.0, 5.0, 0.0, 1e-300, 2.0])
    out = spec.trimmed(0.0)
    assert out.energies_kev == (11.0, 13.0, 14.0)
    assert out.photons == (5.0, 1e-300, 2.0)
    keep, fraction = spec.trim_mask(0.0)
    assert keep.tolist() == [False, True, False, True, True] and fraction == 0.0


def test_trimmed_rule_on_a_hand_computed_example():
    # Energy-weighted contributions: 10·1=10, 20·0.25=5, 30·10=300, 40·0.05=2, 50·4=200 → total 517.
    spec = Spectrum.from_arrays([10.0, 20.0, 30.0, 40.0, 50.0], [1.0, 0.25, 10.0, 0.05, 4.0])
    assert spec.trimmed(1.5 / 517).energies_kev == (10.0, 20.0, 30.0, 40.0, 50.0)  # 2 > 1.5: drop none
    assert spec.trimmed(2.5 / 517).energies_kev == (10.0, 20.0, 30.0, 50.0)  # drop 2
    assert spec.trimmed(7.5 / 517).energies_kev == (10.0, 30.0, 50.0)  # drop 2 + 5
    assert spec.trimmed(16.5 / 517).energies_kev == (10.0, 30.0, 50.0)  # 2 + 5 + 10 = 17 > 16.5: keep the 10
    assert spec.trimmed(17.5 / 517).energies_kev == (30.0, 50.0)  # drop 2 + 5 + 10
    assert spec.trim_mask(17.5 / 517)[1] == pytest.approx(17 / 517, rel=1e-15)
    assert spec.trimmed(0.99).energies_kev == (30.0,)  # at least one bin: the largest
    assert spec.trimmed(5.0).energies_kev == (30.0,)
    # Photon-counting weights (1 per photon): contributions are the photon counts themselves.
    weights = np.ones(5)
    out = spec.trimmed(0.3 / 15.3, weights=weights)
    _check_trim(spec, out, 0.3 / 15.3, weights)
    assert out.energies_kev == (10.0, 30.0, 50.0)  # drops 0.05 and 0.25
    with pytest.raises(SpectrumError, match="weights"):
        spec.trimmed(1e-3, weights=np.ones(4))
    with pytest.raises(SpectrumError, match="weights"):
        spec.trimmed(1e-3, weights=np.zeros(5))
    with pytest.raises(SpectrumError, match="tolerance"):
        spec.trimmed(-1e-3)


def test_monochromatic_from_arrays_and_file_round_trip(tmp_path):
    mono = Spectrum.monochromatic(59.5, 1.0e6)
    assert mono.energies_kev == (59.5,) and mono.photons == (1.0e6,) and mono.total == 1.0e6
    assert len(mono) == 1 and mono.trimmed(0.5) == mono

    spec = Spectrum.from_arrays(np.array([15.25, 20.0, 33.3333333333333]), [1.0 / 3.0, 0.0, 7.123456789e5])
    assert isinstance(spec.energies_kev, tuple) and isinstance(spec.photons[0], float)
    hash(spec)  # immutable value
    path = spec.to_file(tmp_path / "spec.txt")
    back = Spectrum.from_file(path)
    assert back == spec  # exact: repr() floats
    assert back.energies_kev == spec.energies_kev and back.photons == spec.photons

    # Hand-written file: comments, blank lines, comma and whitespace separators, trailing comments.
    text = "# energy_keV photons\n\n10, 100\n  20\t250   # peak\n30 ,  5e1\n# end\n"
    (tmp_path / "hand.csv").write_text(text)
    hand = Spectrum.from_file(tmp_path / "hand.csv")
    assert hand.energies_kev == (10.0, 20.0, 30.0) and hand.photons == (100.0, 250.0, 50.0)
    assert hand == Spectrum.from_arrays([10, 20, 30], [100, 250, 50])  # description not compared


@pytest.mark.parametrize(
    "energies, photons, match",
    [
        ([10.0, 20.0], [1.0, -1.0], "negative"),
        ([10.0, 10.0], [1.0, 1.0], "strictly increasing"),
        ([20.0, 10.0], [1.0, 1.0], "strictly increasing"),
        ([10.0, 20.0], [1.0, float("nan")], "not finite"),
        ([10.0, float("nan")], [1.0, 1.0], "not finite"),
        ([0.0, 20.0], [1.0, 1.0], "> 0"),
        ([], [], "empty"),
        ([10.0, 20.0], [0.0, 0.0], "all zero"),
        ([10.0, 20.0], [1.0], "one photon count per energy bin"),
    ],
)
def test_invalid_arrays(energies, photons, match):
    with pytest.raises(SpectrumError, match=match):
        Spectrum.from_arrays(energies, photons)


def test_monochromatic_errors():
    with pytest.raises(SpectrumError, match="photons_per_mm2_at_1m"):
        Spectrum.monochromatic(30.0, 0.0)
    with pytest.raises(SpectrumError, match="energy_kev"):
        Spectrum.monochromatic(float("nan"), 1.0)


@pytest.mark.parametrize(
    "content, match",
    [
        ("10 1\n20 2 3\n", "line 2: expected 2 columns"),
        ("# header\n10 1\n\n20 abc\n", "line 4: not two numbers"),
        ("10 1\n20 -2\n", "line 2: photons must be ≥ 0"),
        ("10 1\n10 2\n", "line 2: energies must be strictly increasing"),
        ("10 1\nnan 2\n", "line 2: values must be finite"),
        ("# nothing\n\n", "no data lines"),
        ("10 0\n20 0\n", "all zero"),
    ],
)
def test_bad_files(tmp_path, content, match):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    with pytest.raises(SpectrumError, match=match):
        Spectrum.from_file(path)


def test_missing_file(tmp_path):
    with pytest.raises(SpectrumError, match="absent.txt: no such file"):
        Spectrum.from_file(tmp_path / "absent.txt")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"kvp": 40, "anode": "Xx"}, "anode"),
        ({"kvp": 40, "anode": "w"}, "anode"),  # SpekPy names are case-sensitive
        ({"kvp": 600}, "kvp"),  # W: 10–500 kV
        ({"kvp": 5}, "kvp"),
        ({"kvp": 80, "anode": "Mo"}, "kvp"),  # Mo: 10–50 kV
        ({"kvp": float("nan")}, "kvp"),
        ({"kvp": 1e308}, "kvp"),  # finite, but kvp / bin_kev is not: refused before the bins are counted
        ({"kvp": -5}, "kvp"),
        ({"kvp": 40, "filters": {"Al": -1.0}}, r"filters\['Al'\]"),
        ({"kvp": 40, "mas": 0.0}, "mas"),
        ({"kvp": 40, "bin_kev": 0.0}, "bin_kev"),
        ({"kvp": 40, "anode_angle_deg": 95.0}, "anode_angle_deg"),
        ({"kvp": 40, "filters": [("Al", 1.0)]}, "filters"),
    ],
)
def test_from_tube_errors_before_or_from_spekpy(kwargs, match):
    with pytest.raises(SpectrumError, match=match):
        Spectrum.from_tube(**kwargs)


def test_from_tube_unknown_filter_material():
    with pytest.raises(SpectrumError, match="filters: 'Unobtainium' is not a SpekPy material"):
        Spectrum.from_tube(kvp=30, filters={"Unobtainium": 1.0})
