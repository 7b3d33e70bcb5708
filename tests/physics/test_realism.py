"""Scanner realism (xrayraster.physics.realism, docs/realism.md), each option against an independent
expectation: the focal spot's edge against the erf of a Gaussian penumbra spot·(M − 1) and against
sub-source sampling; the flats' noise against Poisson statistics; the gain map's line-integral
offset against −ln g; the mount against box chords and the labels it must not have; a blur too small
to show skipped, its effect on a pixel-integrating detector (scipy's Gaussian filter) within the stated bound."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import trimesh
from scipy.ndimage import gaussian_filter

import xrayraster as xr
from references.chords import box_chord, cone_rays
from xrayraster.core.errors import ConfigError, PhysicsError
from xrayraster.io.scene_file import load_scene_file
from xrayraster.physics.detector import NEGLIGIBLE_BLUR_PX, blur_change_bound, gaussian_blur
from xrayraster.physics.radiograph import radiograph
from xrayraster.physics.realism import FWHM_PER_SIGMA, Realism
from xrayraster.pipeline import load_scan_file

AL = xr.Material.element("Al")


def phi(x):
    """The standard normal CDF: a unit step convolved with a Gaussian of σ = 1."""
    return 0.5 * (1 + np.vectorize(math.erf)(np.asarray(x) / math.sqrt(2)))


def edge_sigma(x, profile):
    """σ of an erf-shaped rising edge from its 10 % and 90 % crossings (profile normalised 0 → 1)."""
    x10, x90 = np.interp([0.1, 0.9], profile, x)
    return (x90 - x10) / (2 * 1.2815515655446004)  # Φ⁻¹(0.9) = 1.28155...


# ----------------------------------------------------------------------------- focal spot

SOD, SDD, PIXEL, SPOT = 100.0, 300.0, 0.1, 0.4  # mm; magnification 3 at the axis
EDGE_SHAPE = (4, 128)  # an even number of columns: the central ray runs between two pixels
EDGE_X = (np.arange(EDGE_SHAPE[1]) - (EDGE_SHAPE[1] - 1) / 2) * PIXEL  # column centres on the detector, mm
MONO = xr.Spectrum.monochromatic(30.0, 1e6)


def plate(depth_mm: float) -> xr.Scene:
    """A 1 mm aluminium plate facing the source, ``depth_mm`` beyond the axis, its edge on the plane x = 0:
    that plane holds the source, so the edge projects onto the boundary between the central columns."""
    scene = xr.Scene()
    scene.add(trimesh.creation.box((40.0, 1.0, 10.0)), AL, transform=xr.Transform.translation((-20.0, depth_mm, 0.0)))
    return scene


def normalised_edge(image: np.ndarray) -> np.ndarray:
    row = image[EDGE_SHAPE[0] // 2].astype(np.float64)
    return (row - row[0]) / (row[-1] - row[0])


def sub_source_edge(renderer_gl, depth_mm: float) -> np.ndarray:
    """The reference: the plate seen from 161 source points across the spot (Gaussian weights over ±4σ,
    along the detector's columns), the transmissions averaged. Each point renders an unblurred view."""
    s, d, u, v = np.split(xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, [0.0]).to_vec().array[0], 4)
    offsets = np.linspace(-4, 4, 161)
    weights = np.exp(-offsets**2 / 2)
    shift = SPOT / FWHM_PER_SIGMA * u / np.linalg.norm(u)
    sources = xr.VectorGeometry("cone", EDGE_SHAPE, [np.concatenate([s + a * shift, d, u, v]) for a in offsets])
    mu = AL.attenuation(30.0)
    with xr.Renderer(sources, context=renderer_gl) as r:
        transmissions = [np.exp(-mu * r.path_lengths(plate(depth_mm), k)[0]) for k in range(len(offsets))]
    return normalised_edge(np.tensordot(weights / weights.sum(), transmissions, axes=1))


def test_focal_spot_edge_at_the_axis_is_the_erf_of_a_penumbra_spot_times_m_minus_1(gl):
    geometry = xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, [0.0])
    with xr.Renderer(geometry, context=gl) as r:
        sharp = normalised_edge(r.project(plate(0.0), MONO, output="transmission").image)
        blurred = normalised_edge(r.project(plate(0.0), MONO, output="transmission",
                                            realism=Realism(focal_spot_mm=SPOT)).image)
    middle = EDGE_SHAPE[1] // 2
    assert np.all(sharp[:middle] < 1e-3) and np.all(sharp[middle:] > 1 - 1e-3)  # a point source: a step at x = 0
    penumbra_fwhm = SPOT * (SDD / SOD - 1)  # mm on the detector
    sigma = penumbra_fwhm / FWHM_PER_SIGMA
    np.testing.assert_allclose(blurred, phi(EDGE_X / sigma), atol=1e-3)
    assert edge_sigma(EDGE_X, blurred) * FWHM_PER_SIGMA == pytest.approx(penumbra_fwhm, rel=0.01)


@pytest.mark.parametrize("depth_mm", [0.0, 30.0])
def test_focal_blur_model_at_its_plane_equals_sub_source_sampling(gl, depth_mm):
    z = SOD + depth_mm
    geometry = xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, [0.0])
    with xr.Renderer(geometry, context=gl) as r:
        model = normalised_edge(r.project(plate(depth_mm), MONO, output="transmission",
                                          realism=Realism(focal_spot_mm=SPOT, focal_plane_mm=z)).image)
        at_axis = normalised_edge(r.project(plate(depth_mm), MONO, output="transmission",
                                            realism=Realism(focal_spot_mm=SPOT)).image)
    reference = sub_source_edge(gl, depth_mm)
    assert np.abs(model - reference).max() < 0.012  # of the edge's step
    # The penumbra at depth z is spot · (SDD − z) / z (the reference's within 3 %: each of its source
    # points sees a pixel-sharp edge); the model set for the axis keeps the axis's.
    assert edge_sigma(EDGE_X, reference) * FWHM_PER_SIGMA == pytest.approx(SPOT * (SDD - z) / z, rel=0.03)
    assert edge_sigma(EDGE_X, at_axis) * FWHM_PER_SIGMA == pytest.approx(SPOT * (SDD / SOD - 1), rel=0.01)


@pytest.mark.parametrize("counting", [False, True])
def test_focal_spot_noise_has_the_mean_and_variance_of_the_blurred_intensity(counting):
    """Noise drawn after the blur: per pixel the compound Poisson moments Σ w·n and Σ E²·n (integrating)
    or Σ n (counting) of a low-dose spectrum, and no correlation between neighbours."""
    tube = xr.Spectrum([20.0, 30.0, 45.0, 60.0], [1e5, 4e5, 3e5, 5e4])
    factor = 80.0 / tube.total  # 80 photons a pixel: the compound Poisson regime
    detector = xr.Detector("counting" if counting else "integrating")
    lengths = np.zeros((1, 96, 96), np.float32)
    got = radiograph(lengths, [AL], tube, detector, factor, output="raw", noise=True, bin_tolerance=0,
                     rng=np.random.default_rng(4), focal_sigma_px=(2.0, 1.5)).image.astype(np.float64)
    e, n = tube.energies, tube.fluence * factor
    mean, variance = ((n.sum(), n.sum()) if counting else ((e * n).sum(), (e * e * n).sum()))
    assert got.mean() == pytest.approx(mean, rel=0.01)
    assert got.var() == pytest.approx(variance, rel=0.06)
    neighbours = np.corrcoef(got[:, :-1].ravel(), got[:, 1:].ravel())[0, 1]
    assert abs(neighbours) < 0.04


def test_focal_spot_needs_a_cone_beam_and_a_plane_before_the_detector(gl):
    scene = plate(0.0)
    with xr.Renderer(xr.ParallelBeamGeometry(EDGE_SHAPE, PIXEL, [0.0]), context=gl) as r:
        with pytest.raises(PhysicsError, match="cone-beam"):
            r.project(scene, MONO, realism=Realism(focal_spot_mm=0.1))
    with xr.Renderer(xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, [0.0]), context=gl) as r:
        with pytest.raises(PhysicsError, match="between the source and the detector"):
            r.project(scene, MONO, realism=Realism(focal_spot_mm=0.1, focal_plane_mm=SDD))
    with pytest.raises(PhysicsError, match="focal_plane_mm needs focal_spot_mm"):
        Realism(focal_plane_mm=50.0)


# ----------------------------------------------------------------------------- options too small to show


def spot_for(sigma_px: float) -> float:
    """The focal spot (FWHM, mm) whose penumbra at the axis has standard deviation ``sigma_px`` (the
    plate's geometry: square pixels, so both axes)."""
    return sigma_px * PIXEL * FWHM_PER_SIGMA / (SDD / SOD - 1)


def never_called(*args, **kwargs):
    raise AssertionError("a skipped option's work was done")


def skip_records(caplog) -> list[logging.LogRecord]:
    return [rec for rec in caplog.records if rec.name == "xrayraster" and rec.getMessage().startswith("skipped")]


@pytest.mark.parametrize("noise", [False, True])
def test_a_blur_below_the_threshold_is_not_computed_and_the_scan_is_the_one_without_it(gl, monkeypatch, noise):
    """A focal spot and a detector blur of σ just below NEGLIGIBLE_BLUR_PX: neither blur is computed (nor,
    with noise, the spot's own draw from the blurred moments) for the views or the scan's noisy flat, and
    the bytes are those of the scan without them."""
    tube = xr.Spectrum([20.0, 30.0, 45.0], [1e5, 4e5, 3e5])  # several bins: with noise, Beer–Lambert's own draws
    below = 0.999 * NEGLIGIBLE_BLUR_PX
    geometry = xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, xr.full_circle(3))
    with xr.Renderer(geometry, context=gl) as r:
        without = r.project_all(plate(0.0), tube, noise=noise, seed=5, realism=Realism(flat_fields=4), progress=False)
        for name in ("radiograph.gaussian_blur", "detector.gaussian_blur", "radiograph.scaled_poisson"):
            monkeypatch.setattr(f"xrayraster.physics.{name}", never_called)
        skipped = r.project_all(plate(0.0), tube, detector=xr.Detector(blur_sigma_px=below), noise=noise, seed=5,
                                realism=Realism(focal_spot_mm=spot_for(below), flat_fields=4), progress=False)
    assert skipped.data.tobytes() == without.data.tobytes()


def test_options_that_are_exact_no_ops_cost_nothing(gl, monkeypatch):
    """gain_variation = 0, a psf of one centre weight, no dark offset or read noise: no gain map is drawn,
    nothing is convolved, and the bytes are the ideal scanner's."""
    geometry = xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, [0.0])
    with xr.Renderer(geometry, context=gl) as r:
        ideal = [r.project(plate(0.0), MONO, output=out, noise=True, seed=2).image for out in ("raw", "lineint")]
        for name in ("simulate.renderer.gain_map", "physics.detector._convolve2d", "physics.detector.gaussian_blur"):
            monkeypatch.setattr(f"xrayraster.{name}", never_called)
        options = {"detector": xr.Detector(psf=[[0, 0, 0], [0, 3, 0], [0, 0, 0]]), "realism": Realism(gain_variation=0.0)}
        same = [r.project(plate(0.0), MONO, output=out, noise=True, seed=2, **options).image for out in ("raw", "lineint")]
    assert [a.tobytes() for a in same] == [a.tobytes() for a in ideal]


def pixel_means(fine_image: np.ndarray, fine: int) -> np.ndarray:
    """What a detector integrating over pixels ``fine`` samples wide (along each axis) reads of ``fine_image``."""
    shape = [n for size in fine_image.shape for n in (size // fine, fine)]
    return fine_image.reshape(shape).mean(axis=tuple(range(1, 2 * fine_image.ndim, 2)))


def integrated_change(fine_image: np.ndarray, sigma_px, fine: int) -> np.ndarray:
    """The independent reference: how much a Gaussian blur of ``sigma_px`` (per axis, pixels) changes each
    pixel of a pixel-integrating detector, the blur applied anyway in float64 by scipy.ndimage.gaussian_filter
    on an image sampled ``fine`` times per pixel (its discretisation only underestimates the change: ≤ 0.5 %
    at 4 samples per σ, measured against the erf's integral)."""
    blurred = gaussian_filter(fine_image, [s * fine for s in sigma_px], mode="nearest", truncate=8.0)
    return pixel_means(blurred - fine_image, fine)


def upsampled(image: np.ndarray, fine: int) -> np.ndarray:
    for axis in range(image.ndim):
        image = np.repeat(image, fine, axis=axis)
    return image


@pytest.mark.parametrize("sigma_px", [0.999 * NEGLIGIBLE_BLUR_PX, NEGLIGIBLE_BLUR_PX / 10])
def test_a_skipped_blur_changes_no_pixel_by_more_than_the_stated_bound(sigma_px):
    """docs/realism.md: a blur of σ px changes a pixel-integrated image by at most √(2/π)·σ of its range per
    axis. Worst cases, full contrast: a step edge on a pixel boundary gets half of it (σ/√(2π)), a one-pixel
    line all of it, a one-pixel dot blurred along both axes the sum; a random sub-pixel pattern no more.
    The models' own kernels, applied anyway, change nothing at all."""
    fine = 8 * int(np.ceil(0.5 / sigma_px))  # at least 4 samples per σ, a multiple of 8
    step = upsampled(np.repeat([0.0, 1.0], 4), fine)  # 1-D: the blur along one axis
    line = upsampled(np.eye(1, 7, 3)[0], fine)
    one_axis = blur_change_bound(sigma_px, 0.0)
    assert blur_change_bound(sigma_px, 0.0) == pytest.approx(math.sqrt(2 / math.pi) * sigma_px)
    for image, share in ((step, 0.5), (line, 1.0)):
        change = np.abs(integrated_change(image, [sigma_px], fine)).max()
        assert share * 0.99 * one_axis <= change <= share * one_axis
    rng = np.random.default_rng(0)
    pattern = upsampled(rng.integers(0, 2, 8 * 8).astype(np.float64), fine // 8)  # 8 pixels of 8 random cells
    change = np.abs(integrated_change(pattern, [sigma_px], fine)).max()
    assert 0.1 * one_axis < change <= one_axis
    if sigma_px == NEGLIGIBLE_BLUR_PX / 10:
        return  # the 2-D reference at 4 samples per σ: 4 × 10⁸ samples
    dot = upsampled(np.eye(5)[2][:, None] * np.eye(5)[2][None, :], fine)
    change = np.abs(integrated_change(dot, [sigma_px, sigma_px], fine)).max()
    assert 0.97 * blur_change_bound(sigma_px, sigma_px) <= change <= blur_change_bound(sigma_px, sigma_px)
    assert change < 0.016  # the error docs/realism.md states at the threshold: under 1.6 % of the contrast

    # What the simulation would have computed instead: its kernels are exactly [0, 1, 0] in float64.
    edge = np.repeat([[0.0, 1.0]], 4, axis=1).repeat(4, axis=0)
    for averaged in (False, True):
        assert np.array_equal(gaussian_blur(edge, sigma_px, sigma_px, pixel_averaged=averaged), edge)


def test_a_blur_just_above_the_threshold_is_applied(gl, monkeypatch, caplog):
    above = 1.01 * NEGLIGIBLE_BLUR_PX
    calls = []

    def spy(blur):
        def recorded(image, sigma_rows_px, sigma_cols_px, **options):
            calls.append((sigma_rows_px, sigma_cols_px, options.get("pixel_averaged", False)))
            return blur(image, sigma_rows_px, sigma_cols_px, **options)
        return recorded

    for module in ("radiograph", "detector"):
        monkeypatch.setattr(f"xrayraster.physics.{module}.gaussian_blur", spy(gaussian_blur))
    caplog.set_level(logging.INFO, logger="xrayraster")
    geometry = xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, [0.0])
    with xr.Renderer(geometry, context=gl) as r:
        r.project(plate(0.0), MONO, output="raw", detector=xr.Detector(blur_sigma_px=above),
                  realism=Realism(focal_spot_mm=spot_for(above)))
    focal = [c for c in calls if c[2]]
    assert focal and focal[0][:2] == pytest.approx((above, above), rel=1e-9)  # the view's intensity, pixel-averaged
    assert (above, above, False) in calls  # the detector's point spread
    assert not skip_records(caplog)


def test_each_skip_is_logged_once_a_scan_with_its_size_and_the_threshold(gl, caplog):
    caplog.set_level(logging.INFO, logger="xrayraster")
    geometry = xr.ConeBeamGeometry(SOD, SDD, EDGE_SHAPE, PIXEL, xr.full_circle(4))
    options = {"detector": xr.Detector(blur_sigma_px=0.001), "realism": Realism(focal_spot_mm=spot_for(0.005)),
               "progress": False}
    with xr.Renderer(geometry, context=gl) as r:
        r.project_all(plate(0.0), MONO, **options)
        r.project_all(plate(0.0), MONO, **options)  # the same scan again: nothing new to say
        first = [rec.getMessage() for rec in skip_records(caplog)]
        r.retarget(geometry)  # a new scan
        r.project_all(plate(0.0), MONO, **options)
    assert all(rec.levelno == logging.INFO for rec in skip_records(caplog))
    assert len(first) == 2 and len(skip_records(caplog)) == 4
    focal, detector = sorted(first, key=lambda m: "blur_sigma_px" in m)
    assert "focal_spot_mm" in focal and "σ_rows = 0.005 px, σ_cols = 0.005 px" in focal and "0.8 %" in focal
    assert "blur_sigma_px = 0.001" in detector and "0.16 %" in detector
    assert all("below the 0.01 px threshold" in message for message in first)


# ----------------------------------------------------------------------------- flat fields and gain

OPEN = (96, 96)
PHOTONS = 1e4  # per pixel: a parallel beam's 1 mm² pixels collect the fluence as is
READ_NOISE = 30.0  # counts


def open_beam() -> xr.Scene:
    """An object far above the detector's rows: every pixel sees the open beam."""
    scene = xr.Scene()
    scene.add(trimesh.creation.box((1.0, 1.0, 1.0)), AL, transform=xr.Transform.translation((0.0, 0.0, 500.0)))
    return scene


def open_views(gl, realism, *, noise, seed=11, views=3):
    geometry = xr.ParallelBeamGeometry(OPEN, 1.0, xr.full_circle(views))
    detector = xr.Detector("counting", electronic_noise=READ_NOISE)
    with xr.Renderer(geometry, context=gl) as r:
        return r.project_all(open_beam(), xr.Spectrum.monochromatic(30.0, PHOTONS), detector=detector,
                             output="transmission", noise=noise, seed=seed, realism=realism, progress=False)


@pytest.mark.parametrize("frames", [1, 4])
def test_flat_fields_add_their_poisson_variance_and_share_it_between_views(gl, frames):
    """One exposure's relative variance is σ² = (n + e²)/n² (Poisson n, read noise e); a flat averaged
    from N has σ²/N, and normalising by it gives σ²(1 + 1/N), the flat's part common to every view."""
    one = (PHOTONS + READ_NOISE**2) / PHOTONS**2
    noisy = open_views(gl, Realism(flat_fields=frames), noise=True).data.astype(np.float64)
    assert noisy.var(axis=(1, 2)).mean() == pytest.approx(one * (1 + 1 / frames), rel=0.05)
    shared = np.mean([np.cov(noisy[a].ravel(), noisy[b].ravel())[0, 1] for a, b in ((0, 1), (1, 2), (0, 2))])
    assert shared == pytest.approx(one / frames, rel=0.1)
    clean = open_views(gl, Realism(flat_fields=frames), noise=False).data.astype(np.float64)
    assert np.abs(clean - clean[0]).max() < 1e-6  # one flat for the scan
    assert (1 / clean[0]).var() == pytest.approx(one / frames, rel=0.05)
    exact = open_views(gl, Realism(), noise=True).data.astype(np.float64)
    assert exact.var(axis=(1, 2)).mean() == pytest.approx(one, rel=0.05)


def test_flat_fields_are_seeded_apart_from_the_views_and_the_same_for_any_subset_of_views(gl):
    realism = Realism(flat_fields=2)
    full = open_views(gl, realism, noise=True, seed=3)
    geometry = xr.ParallelBeamGeometry(OPEN, 1.0, xr.full_circle(3))
    with xr.Renderer(geometry, context=gl) as r:
        alone = r.project(open_beam(), xr.Spectrum.monochromatic(30.0, PHOTONS),
                          2, detector=xr.Detector("counting", electronic_noise=READ_NOISE), output="transmission",
                          noise=True, seed=3, realism=realism).image
        with pytest.raises(xr.RenderError, match="need a seed"):
            r.project(open_beam(), MONO, realism=realism)
    assert alone.tobytes() == full.data[2].tobytes()
    assert full.provenance["realism"] == realism.to_dict()
    other = open_views(gl, realism, noise=False, seed=4).data
    assert not np.allclose(other[0], open_views(gl, realism, noise=False, seed=3).data[0])


def test_gain_variation_offsets_every_view_by_minus_ln_g(gl):
    """Noise-free: the raw signal over the ideal one is the gain map g (mean 1, relative std σ); the flat
    leaves it in, so each line integral gains −ln g, the same in every view, of std √ln(1 + σ²) ≈ σ."""
    sigma = 0.05
    scene = xr.Scene()
    scene.add(trimesh.creation.box((8.0, 8.0, 8.0)), AL)
    geometry = xr.ConeBeamGeometry(100.0, 200.0, (64, 64), 0.4, xr.full_circle(2))
    realism = Realism(gain_variation=sigma)
    with xr.Renderer(geometry, context=gl) as r:
        raw = [r.project(scene, MONO, v, output="raw", seed=1, realism=realism).image for v in range(2)]
        ideal_raw = [r.project(scene, MONO, v, output="raw").image for v in range(2)]
        line = [r.project(scene, MONO, v, seed=1, realism=realism).image for v in range(2)]
        ideal = [r.project(scene, MONO, v).image for v in range(2)]
    g = raw[0].astype(np.float64) / ideal_raw[0]
    np.testing.assert_allclose(raw[1] / ideal_raw[1], g, rtol=1e-6)  # one map for the scan
    for v in range(2):
        np.testing.assert_allclose(line[v] - ideal[v], -np.log(g), atol=2e-6)
    assert g.mean() == pytest.approx(1.0, abs=3 * sigma / 64)
    assert g.std() == pytest.approx(sigma, rel=0.05)
    assert np.log(g).std() == pytest.approx(math.sqrt(math.log1p(sigma**2)), rel=0.05)
    assert math.sqrt(math.log1p(sigma**2)) == pytest.approx(sigma, rel=1e-3)


# ----------------------------------------------------------------------------- configuration


def scene_text(source: str = "", detector: str = "", beam: str = "cone") -> str:
    geometry = ("source_to_origin = 100.0\nsource_to_detector = 200.0\n" if beam == "cone" else "")
    return f"""
[geometry]
beam = "{beam}"
{geometry}detector_shape = [16, 16]
pixel_size = 0.5
num_views = 4

[[objects]]
mesh = {{ box = [4, 4, 4] }}
material = "aluminium"

[source]
monochromatic_kev = 30.0
photons_per_mm2_at_1m = 1e6
{source}

[detector]
mode = "counting"
{detector}
"""


def test_realism_keys_are_read_from_source_and_detector(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(scene_text("focal_spot_mm = 0.05\nfocal_plane_mm = 90.0", "flat_fields = 8\ngain_variation = 0.01\n"
                               "psf = [[0, 1, 0], [1, 4, 1], [0, 1, 0]]"))
    loaded = load_scene_file(path)
    assert loaded.realism == Realism(focal_spot_mm=0.05, focal_plane_mm=90.0, flat_fields=8, gain_variation=0.01)
    assert loaded.detector.psf[1] == (0.125, 0.5, 0.125)
    path.write_text(scene_text())
    assert load_scene_file(path).realism == Realism() and not Realism().active


@pytest.mark.parametrize("source, detector, beam, message", [
    ("focal_spot_mm = -1", "", "cone", r"\[source\]: focal_spot_mm must be >= 0"),
    ("focal_spot_mm = 0.1", "", "parallel", r"\[source\]: focal_spot_mm applies to cone-beam scans"),
    ("focal_plane_mm = 50", "", "cone", r"\[source\]: focal_plane_mm needs focal_spot_mm > 0"),
    ("focal_spot_mm = 0.1\nfocal_plane_mm = 200", "", "cone",
     r"focal_plane_mm \(200 mm from the source\) must lie before"),
    ("", "flat_fields = 0", "cone", r"\[detector\]: flat_fields must be an integer >= 1"),
    ("", "flat_fields = 2.5", "cone", r"\[detector\]: flat_fields must be an integer >= 1"),
    ("", "gain_variation = -0.1", "cone", r"\[detector\]: gain_variation must be >= 0"),
    ("", "psf = [[1, 1], [1, 1]]", "cone", r"\[detector\]: detector psf must be a 2-D kernel of odd size"),
    ("", "psf = [[1, 1, 1], [1]]", "cone", r"\[detector\]: psf rows must all have the same length"),
    ("", "psf = [[1]]\nblur_sigma_px = 1.0", "cone", r"give blur_sigma_px or psf, not both"),
])
def test_realism_errors_name_the_key_and_the_fix(tmp_path, source, detector, beam, message):
    path = tmp_path / "scene.toml"
    path.write_text(scene_text(source, detector, beam))
    with pytest.raises(ConfigError, match=message):
        load_scene_file(path)


# ----------------------------------------------------------------------------- mount

SAMPLE_HALF = np.array([3.0, 3.0, 2.0])  # a 6 x 6 x 4 mm box on the axis
MOUNT_CENTRE, MOUNT_HALF = np.array([0.0, 0.0, -4.5]), np.array([2.0, 2.0, 3.0])  # a post, z = -7.5 to 1 mm inside


def scan_text(mount: str) -> str:
    return f"""
{mount}

[[objects]]
name = "sample"
mesh = {{ box = {(2 * SAMPLE_HALF).tolist()} }}
material = "aluminium"

[source]
monochromatic_kev = 30.0
photons_per_mm2_at_1m = 1e6

[geometry]
source_to_origin = 60.0
source_to_detector = 120.0
detector_shape = [40, 32]
pixel_size = 0.5
num_views = 2

[volume]
shape = [40, 20, 20]
voxel_size = 0.5
offset = [-2.0, 0.0, 0.0]
"""


MOUNT = f"""
[[mount]]
name = "post"
mesh = {{ box = {(2 * MOUNT_HALF).tolist()} }}
material = "pmma"
translate = {MOUNT_CENTRE.tolist()}
"""


def test_the_mount_is_projected_never_labelled_and_gives_way_to_the_sample(gl, tmp_path):
    path = tmp_path / "scan.toml"
    path.write_text(scan_text(MOUNT))
    loaded = load_scan_file(path)
    sample = loaded.sample_scene()
    scanned = loaded.with_mount(sample)
    assert [o.name for o in sample.objects] == ["sample"] and [o.name for o in scanned.objects] == ["sample", "post"]
    with xr.Renderer(loaded.geometry, context=gl) as r:
        lengths = r.path_lengths(scanned, 0)
        alone = r.path_lengths(sample, 0)
        mounted = r.project(scanned, loaded.spectrum).image
        bare = r.project(sample, loaded.spectrum).image
    origins, dirs = cone_rays(60.0, 120.0, (40, 32), 0.5, 0.0)
    chord = lambda centre, half: box_chord(origins, dirs, np.asarray(centre), np.eye(3), np.asarray(half))  # noqa: E731
    overlap_lo = np.maximum(-SAMPLE_HALF, MOUNT_CENTRE - MOUNT_HALF)
    overlap_hi = np.minimum(SAMPLE_HALF, MOUNT_CENTRE + MOUNT_HALF)
    overlap = chord((overlap_lo + overlap_hi) / 2, (overlap_hi - overlap_lo) / 2)
    np.testing.assert_allclose(lengths[0], chord(np.zeros(3), SAMPLE_HALF), atol=2e-4)  # the sample whole
    np.testing.assert_allclose(lengths[1], chord(MOUNT_CENTRE, MOUNT_HALF) - overlap, atol=2e-4)  # the post gives way
    np.testing.assert_allclose(alone[0], lengths[0], atol=1e-5)  # summed alone, resolved with the post
    changed = np.abs(mounted - bare) > 1e-6
    assert np.all(changed[lengths[1] > 1e-3]) and not changed[lengths[1] == 0].any() and changed.sum() > 100

    labels = xr.voxelize(sample, loaded.volume, context=gl).data
    z, y, x = np.meshgrid(*(np.arange(n) - (n - 1) / 2 for n in loaded.volume.shape), indexing="ij")
    centres = np.stack([x * 0.5, y * 0.5, z * 0.5 - 2.0], axis=-1)
    in_sample = np.all(np.abs(centres) < SAMPLE_HALF - 0.01, axis=-1)
    in_post = np.all(np.abs(centres - MOUNT_CENTRE) < MOUNT_HALF - 0.01, axis=-1) & ~np.all(
        np.abs(centres) < SAMPLE_HALF + 0.01, axis=-1)
    assert in_post.sum() > 100 and not labels[in_post].any()
    assert np.all(labels[in_sample] == 1)


@pytest.mark.parametrize("mount, message", [
    (MOUNT.replace('name = "post"', 'name = "post"\nlabel = 4'), r"\[\[mount\]\] #1: label does not apply to a mount"),
    (MOUNT.replace('name = "post"', 'name = "post"\npriority = 4'), r"priority does not apply to a mount"),
    (MOUNT.replace('"post"', '"sample"'), r"\[\[mount\]\] #1: name 'sample' is taken by an \[\[objects\]\] entry"),
    (MOUNT.replace('"pmma"', '"unobtainium"'), r"\[\[mount\]\] #1 \(post\): material 'unobtainium' is not defined"),
    ("mount = 3", r"mount must be a non-empty array of tables"),
])
def test_mount_errors_name_the_table_and_the_fix(tmp_path, mount, message):
    path = tmp_path / "scan.toml"
    path.write_text(scan_text(mount))
    with pytest.raises(ConfigError, match=message):
        load_scan_file(path)


def test_no_mount_leaves_the_sample_as_it_is(tmp_path):
    path = tmp_path / "scan.toml"
    path.write_text(scan_text(""))
    loaded = load_scan_file(path)
    sample = loaded.sample_scene()
    assert loaded.mount is None and loaded.with_mount(sample) is sample and loaded.realism == Realism()


def test_a_scan_reconstructs_the_mount_and_labels_only_the_sample(gl, cl, tmp_path):
    """End to end: xr.scan projects the post (its μ reconstructs inside it, monochromatic 30 keV:
    no beam hardening) and labels.tif stays 0 there; scan.json names the mount and the options."""
    path = tmp_path / "scan.toml"
    path.write_text(scan_text(MOUNT).replace("num_views = 2", "num_views = 90"))
    result = xr.scan(path)
    z, y, x = np.meshgrid(*(np.arange(n) - (n - 1) / 2 for n in result.volume.geometry.shape), indexing="ij")
    centres = np.stack([x * 0.5, y * 0.5, z * 0.5 - 2.0], axis=-1)
    # Inside the post, below the sample and within the rows the detector sees (z > -5 mm at the axis).
    post_only = np.all(np.abs(centres[..., :2]) < MOUNT_HALF[:2] - 1.0, axis=-1) & (np.abs(centres[..., 2] + 3.75) < 0.8)
    mu = 10 * xr.Material.named("pmma").attenuation_per_mm(30.0)  # cm⁻¹
    assert post_only.sum() >= 32 and not result.labels.data[post_only].any()
    assert abs(result.volume.data[post_only].mean() / mu - 1) < 0.05
    assert result.metadata["mount"][0]["name"] == "post"
    assert result.metadata["realism"] == {"focal_spot_mm": 0.0, "focal_plane_mm": None, "flat_fields": None,
                                          "gain_variation": 0.0, "scatter": "none"}
