"""Radiographs end to end: real attenuation data (xraylib) and tube spectra (SpekPy) against
float64 references written out here, and through the renderer against analytic chords."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from references.chords import box_chord, cone_rays

import xrayraster as xr
from xrayraster.physics import beer_lambert as physics
from xrayraster.physics.radiograph import radiograph

AL = xr.Material.element("Al")
CSI = xr.Material.from_formula("CsI", 4.51)
WEDGE_MM = np.linspace(0.0, 60.0, 61)


@pytest.fixture(scope="module")
def tube():
    return xr.Spectrum.from_tube(80, filters={"Al": 2.0}, mas=10)


def wedge_reference(spectrum, detector, material, thickness):
    """Transmission through each thickness with every bin, float64, the definition written out."""
    e, n = spectrum.energies, spectrum.fluence
    w, mu = detector.weights(e), material.attenuation(e)
    return np.array([(n * w * np.exp(-mu * t)).sum() for t in thickness]) / (n * w).sum()


def test_polychromatic_transmission_with_dropped_bins_matches_all_bins(tube):
    detector = xr.Detector(scintillator=CSI, scintillator_mm=0.5)
    got = radiograph(WEDGE_MM[None, None, :].astype(np.float32), [AL], tube, detector, 1.0, output="transmission")
    assert got.bins < len(tube.energies) and got.dropped <= 1e-6  # some bins really were dropped
    want = wedge_reference(tube, detector, AL, WEDGE_MM)
    assert np.abs(got.image[0] / want - 1).max() <= 1e-5


def test_beam_hardening_in_an_aluminium_step_wedge(tube):
    detector = xr.Detector(scintillator=CSI, scintillator_mm=0.5)
    steps = WEDGE_MM[1:]
    got = radiograph(steps[None, None, :].astype(np.float32), [AL], tube, detector, 1.0, output="lineint")
    mu_eff = got.image[0] / steps
    want = -np.log(wedge_reference(tube, detector, AL, steps)) / steps
    np.testing.assert_allclose(mu_eff, want, rtol=1e-5)
    assert np.all(np.diff(mu_eff) < 0)  # harder with every step
    assert mu_eff[0] > 1.5 * mu_eff[-1]
    # Between the softest and hardest bins' μ: a polychromatic average, not a single energy.
    mu_bins = AL.attenuation(tube.energies[tube.fluence > 0])
    assert mu_bins.min() < mu_eff[-1] < mu_eff[0] < mu_bins.max()


def test_monochromatic_cube_line_integral_is_mu_times_chord(gl):
    water = xr.Material.from_formula("H2O", 1.0)
    scene = xr.Scene()
    scene.add(trimesh.creation.box((10.0, 10.0, 10.0)), water)
    geom = xr.ConeBeamGeometry(100.0, 200.0, (64, 64), 0.5, [0.3])
    with xr.Renderer(geom, context=gl) as r:
        got = r.project(scene, xr.Spectrum.monochromatic(40.0, 1e6), output="lineint")
    mu = water.attenuation(40.0)
    want = mu * box_chord(*cone_rays(100.0, 200.0, (64, 64), 0.5, 0.3), np.zeros(3), np.eye(3), (5, 5, 5))
    assert got.bins == 1 and got.starved == 0
    # Path lengths are good to ~1e-5 mm; the rest is float32 rounding of the line integral.
    assert np.abs(got.image - want).max() <= mu * 2e-5 + 1e-6 * want.max()


def test_noise_is_seeded_per_view_and_flat_follows_inverse_square(gl):
    scene = xr.Scene()
    scene.add(trimesh.creation.box((4.0, 4.0, 4.0)), AL)
    geom = xr.ConeBeamGeometry(100.0, 300.0, (32, 48), 2.0, xr.full_circle(2))
    spectrum = xr.Spectrum.monochromatic(30.0, 1e3)
    with xr.Renderer(geom, context=gl) as r:
        a = r.project(scene, spectrum, 0, output="raw", noise=True, seed=5).image
        assert r.project(scene, spectrum, 0, output="raw", noise=True, seed=5).image.tobytes() == a.tobytes()
        assert r.project(scene, spectrum, 0, output="raw", noise=True, seed=6).image.tobytes() != a.tobytes()
        clean = r.project(scene, spectrum, 1, output="raw").image
        with pytest.raises(xr.RenderError, match="seed"):
            r.project(scene, spectrum, 0, noise=True)
    # Open-beam corner vs centre: photons ∝ cos(θ)/r², signal = 30 keV per photon.
    factor = physics.pixel_photon_factor(geom, 1)
    assert clean[0, 0] == pytest.approx(30.0 * 1e3 * factor[0, 0], rel=1e-6)
    r_corner = np.sqrt(300.0**2 + (15.5 * 2.0) ** 2 + (23.5 * 2.0) ** 2)
    assert factor[0, 0] == pytest.approx(4.0 * (300.0 / r_corner) * (1000.0 / r_corner) ** 2, rel=1e-12)


def test_photon_starvation_is_clamped_and_reported(gl):
    lead = xr.Material.element("Pb")
    scene = xr.Scene()
    scene.add(trimesh.creation.box((20.0, 20.0, 20.0)), lead)
    geom = xr.ConeBeamGeometry(100.0, 200.0, (16, 16), 0.5, [0.0])
    with xr.Renderer(geom, context=gl) as r:
        out = r.project(scene, xr.Spectrum.monochromatic(60.0, 10.0), output="lineint", noise=True, seed=1)
    assert out.starved == 16 * 16 and np.all(np.isfinite(out.image))


def test_plain_material_names_cannot_be_projected(gl):
    scene = xr.Scene()
    scene.add(trimesh.creation.box((4.0, 4.0, 4.0)), "aluminium")
    geom = xr.ConeBeamGeometry(100.0, 200.0, (8, 8), 0.5, [0.0])
    with xr.Renderer(geom, context=gl) as r, pytest.raises(xr.PhysicsError, match="'aluminium' has no attenuation data"):
        r.project(scene, xr.Spectrum.monochromatic(60.0, 10.0))
