"""pipeline/fit_figures.py and the fit's mixture against volumes built with known answers: a box
blurred by a known Gaussian, white noise of a known σ, rings of a known amplitude, two Gaussians."""

import numpy as np
import pytest
from scipy import ndimage

from xrayraster.pipeline.fit_figures import FACE_MARGIN_MM, class_peaks, measure, mixture_means, sides_seen

SHAPE = (24, 64, 64)


def frame():
    """A box sample (label 1) in air, every voxel in the field of view, each column's axis distance."""
    labels = np.zeros(SHAPE, np.uint8)
    labels[6:18, 16:48, 16:48] = 1
    rows, cols = SHAPE[1:]
    radius = np.hypot(*np.meshgrid(np.arange(rows) - (rows - 1) / 2, np.arange(cols) - (cols - 1) / 2, indexing="ij"))
    return labels, np.ones(SHAPE, bool), radius


@pytest.mark.parametrize("sigma_voxels", [0.8, 1.0, 1.5, 2.0])
def test_the_edge_width_is_the_blur_of_the_surface(sigma_voxels):
    """A box of μ 0.5 blurred by a Gaussian of σ (a sampled kernel, exact from 0.8 voxels up): the
    fitted error function's width is σ within 10 % (the box's edges and corners, whose voxels'
    distances are not across a face, bend the profile a little)."""
    labels, inside, radius = frame()
    volume = ndimage.gaussian_filter(0.5 * labels.astype(np.float64), sigma_voxels, mode="nearest")
    figures = measure(volume, labels, inside, radius, voxel_mm=0.1)
    print(f"σ {sigma_voxels} voxels: measured {figures.edge_width_mm / 0.1:.3f}")
    assert figures.edge_width_mm == pytest.approx(0.1 * sigma_voxels, rel=0.10)


def test_a_slab_through_the_grid_shows_no_side():
    """A box inside the grid shows sides (its surface a cone beam's FDK keeps sharp); a slab through
    the whole grid shows only faces along the axis, and two volumes show sides only if both do."""
    labels, inside, radius = frame()
    slab = np.zeros(SHAPE, np.uint8)
    slab[6:18] = 1
    box, plate = (measure(0.5 * sample.astype(np.float64), sample, inside, radius, 0.1) for sample in (labels, slab))
    assert sides_seen(box)
    assert not sides_seen(plate) and not sides_seen(box, plate)


def test_the_peaks_keep_away_from_the_faces_along_the_axis():
    """A slab of μ 0.5 whose faces along the axis are darkened (0.3) over 5 of its 14 voxels on each
    side, as a cone beam's smear does: the class's peak is 0.5 away from the faces, 0.3 (most of its
    voxels) without keeping away; in a plate thinner than the margin, the whole region's median; a
    sample through the grid's top and bottom has no face there."""
    labels, inside, radius = frame()
    margin = int(np.ceil(FACE_MARGIN_MM / 0.1))
    slab = np.zeros(SHAPE, np.uint8)
    slab[4:18, 8:56, 8:56] = 1
    volume = 0.5 * slab
    volume[4:9], volume[13:18] = 0.3 * slab[4:9], 0.3 * slab[13:18]
    assert margin == 5  # the slab's middle keeps voxels beyond the margin; the darkened faces lie within it
    assert measure(volume, slab, inside, radius, voxel_mm=0.1).peaks == {1: pytest.approx(0.5)}
    assert class_peaks(volume, slab, inside) == {1: pytest.approx(0.3)}
    plate = np.zeros(SHAPE, np.uint8)
    plate[10:13, 8:56, 8:56] = 1
    assert class_peaks(0.4 * plate, plate, inside, voxel_mm=0.1) == {1: pytest.approx(0.4)}
    through = np.ones(SHAPE, np.uint8)
    shaded = 0.5 + 0.1 * (np.arange(SHAPE[0]) >= 12)[:, None, None] * through  # 12 of 24 slices at 0.6
    shaded[:2] = 0.6  # the grid's ends: no face, so these count
    assert class_peaks(shaded, through, inside, voxel_mm=0.1) == {1: pytest.approx(0.6)}


def test_the_noise_and_its_spectrum_are_white_noises():
    labels, inside, radius = frame()
    rng = np.random.default_rng(0)
    volume = 0.5 * labels + rng.normal(0.0, 0.02, SHAPE)
    figures = measure(volume, labels, inside, radius, voxel_mm=0.1)
    assert figures.noise_sigma == pytest.approx(0.02, rel=0.02)
    nps = np.array(figures.nps)
    assert nps.sum() == pytest.approx(1.0) and nps[0] == pytest.approx(0.0, abs=1e-3)  # patches' means removed
    assert nps[1:].std() / nps[1:].mean() < 0.1  # flat: white noise
    assert figures.ring_rms < 0.02 / np.sqrt(2 * np.pi * 10) * 2  # noise alone: a floor of σ/√(ring's voxels)


def test_rings_of_a_known_amplitude():
    """Ring k about the axis offset by a·sin(2πk/3): the running median over nine rings of a pattern
    of period 3 is 0, so the profile's fine structure is the pattern, of RMS a/√2."""
    labels, inside, radius = frame()
    amplitude = 0.01
    pattern = amplitude * np.sin(2 * np.pi * radius.astype(int) / 3)
    volume = np.broadcast_to(pattern, SHAPE) + 0.5 * labels
    figures = measure(volume, labels, inside, radius, voxel_mm=0.1)
    assert figures.ring_rms == pytest.approx(amplitude / np.sqrt(2), rel=0.05)
    assert figures.peaks[1] == pytest.approx(0.5, abs=amplitude)


def test_the_mixture_finds_two_gaussians_from_a_rough_start():
    rng = np.random.default_rng(1)
    values = np.concatenate([rng.normal(0.0, 0.03, 40_000), rng.normal(0.45, 0.05, 20_000)])
    means = mixture_means(values, {"air": 0.05, "sample": 0.35})
    assert means["air"] == pytest.approx(0.0, abs=2e-3) and means["sample"] == pytest.approx(0.45, abs=3e-3)
