"""One radiograph from per-material path lengths: spectrum × materials × detector (+ noise).

The flat field is the noise-free signal with nothing in the beam (a scanner averages many flats)
unless a scan's finite number of flats gives it noise (``flat_noise``), the dark field the
detector's mean offset; ``transmission`` and ``lineint`` are normalised by them as a scanner does
(:func:`xrayraster.physics.beer_lambert.normalise`). The scanner's imperfections (a focal spot,
noisy flats, an uncorrected gain map) are modelled in :mod:`xrayraster.physics.realism`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.choices import RADIOGRAPH_OUTPUTS, check_choice
from ..core.errors import PhysicsError
from . import beer_lambert
from .beer_lambert import scaled_poisson
from .detector import Detector, gaussian_blur, negligible_blur
from .scatter import ScatterModel, scatter_signal
from .spectral_table import SpectralTable, moment_weights, spectral_table


@dataclass(frozen=True)
class Radiograph:
    image: np.ndarray  # float32 (rows, cols): raw signal, transmission or line integral
    output: str
    starved: int  # photon-starved pixels: clamped before −log, or a transmission that is 0 in float32; 0 for raw output
    bins: int  # energy bins used
    dropped: float  # share of the open-beam signal in the bins dropped (0 when none were)
    covered: int  # pixels whose ray crosses the scene (a non-zero path length): the sample's share of the view
    starved_covered: int  # the starved pixels among them (physics/starvation.py)
    spr_centre: float = 0.0  # scatter over primary signal in the detector's middle pixels (0 without scatter)
    spr_covered: float = 0.0  # the same over the pixels the scene covers


def attenuation_table(materials, energies_kev) -> np.ndarray:
    """μ (mm⁻¹) per material channel and energy bin, ``(channels, bins)``.

    Materials must provide ``attenuation(energies_kev)`` (:class:`~xrayraster.Material`).
    """
    table = []
    for m in materials:
        if not hasattr(m, "attenuation"):
            raise PhysicsError(
                f"material {m!r} has no attenuation data: give objects an xr.Material "
                "(e.g. xr.Material.from_formula('H2O', density=1.0)), not a plain name"
            )
        table.append(np.asarray(m.attenuation(energies_kev), dtype=np.float64))
    return np.stack(table)


# Energy bins whose combined share of the open-beam signal is at most this are dropped. Behind
# an object the share can differ (hard bins gain weight behind thick material), so the error is
# measured where it matters (tests/physics/test_radiograph.py): 80 kVp W + 2 mm Al, CsI 0.5 mm, 0-60 mm
# of aluminium: 20 of 158 bins dropped, transmission within 2.2e-7 relative of all bins.
BIN_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class SpectralModel:
    """What every view of a scan shares (:func:`spectral_model`): the energy bins kept (``energies``
    keV, ``photons`` per mm² at 1 m, the open-beam signal share ``dropped``), μ per material
    channel and bin (``mu``, mm⁻¹), and the spectral table that noisy views interpolate their sums
    from (:mod:`~xrayraster.physics.spectral_table`; None: the exact sum)."""

    energies: np.ndarray
    photons: np.ndarray
    dropped: float
    mu: np.ndarray
    table: SpectralTable | None = None


def spectral_model(materials, spectrum, detector: Detector, *, bin_tolerance: float = BIN_TOLERANCE,
                   longest_mm: float | None = None) -> SpectralModel:
    """The bins, μ and, given ``longest_mm`` (the longest path through the scene, mm), the
    spectral table of ``materials`` under ``spectrum`` and ``detector``: built once per scan
    instead of once per view."""
    energies, photons, dropped = _bins(spectrum, detector, bin_tolerance)
    mu = attenuation_table(materials, energies)
    table = None
    if longest_mm is not None:
        table = spectral_table(mu, moment_weights(photons, detector.efficiency(energies), energies), longest_mm)
    return SpectralModel(energies, photons, dropped, mu, table)


def radiograph(lengths, materials, spectrum, detector: Detector, factor, *, output="lineint", noise=False, rng=None,
               bin_tolerance: float = BIN_TOLERANCE, threads: int | None = None, focal_sigma_px=(0.0, 0.0),
               gain=None, flat_noise=None, model: SpectralModel | None = None,
               scatter: ScatterModel | None = None) -> Radiograph:
    """The radiograph of one view.

    ``lengths``: ``(channels, rows, cols)`` mm, channels in ``materials`` order; ``spectrum``:
    photons per mm² at 1 m per bin (:class:`~xrayraster.Spectrum`); ``factor``: per-pixel photon
    factor (:func:`~xrayraster.physics.beer_lambert.pixel_photon_factor`); ``noise``: draw quantum noise
    (and the detector's electronic noise) from ``rng`` (a ``numpy.random.Generator``);
    ``bin_tolerance``: see :data:`BIN_TOLERANCE` (0 keeps every non-empty bin); ``threads``: of the
    spectral sum (default every core; :func:`~xrayraster.physics.beer_lambert.thread_count`).
    The scanner's imperfections (:mod:`~xrayraster.physics.realism`): ``focal_sigma_px``, the focal
    spot's Gaussian blur ``(rows, cols)`` in pixels; ``gain``, a per-pixel gain map the flat does not
    correct; ``flat_noise``, the scan's flat over the exact one (:func:`flat_noise`). A focal blur
    narrower than :data:`~xrayraster.physics.detector.NEGLIGIBLE_BLUR_PX` along an axis is skipped
    there, and with both axes skipped the view is exactly the view without a spot. ``model``:
    the bins, μ and spectral table of :func:`spectral_model` for these materials, spectrum and
    detector (made here when None, without a table), so the views of a scan share them. ``scatter``:
    the scan's scatter kernels (:func:`~xrayraster.physics.scatter.scatter_model`), whose scatter is
    added to the primary before its noise; None: no scatter.
    """
    check_choice(output, RADIOGRAPH_OUTPUTS, "output", PhysicsError)
    if noise and rng is None:
        raise PhysicsError("noise=True needs rng (a numpy.random.Generator, e.g. np.random.default_rng(seed))")
    model = model or spectral_model(materials, spectrum, detector, bin_tolerance=bin_tolerance)
    energies, photons, dropped, mu = model.energies, model.photons, model.dropped, model.mu
    focal_sigma_px = applied_focal_sigma_px(focal_sigma_px)
    scattered = None if scatter is None else scatter_signal(scatter, lengths, mu, factor)
    extra = None if scattered is None else (scattered, scattered * scatter.quantum)
    quantum = _detected(lengths, mu, photons, energies, detector, factor, focal_sigma_px, rng if noise else None,
                        threads, model.table, extra)
    # The path lengths are at hand, so the pixels the scene covers are counted here, per view, for
    # the share of them that starve (a grazing ray's tiny path counts: it is still the sample's).
    covered = np.any(np.asarray(lengths) != 0, axis=0)
    ratios = {}
    if scattered is not None:
        ratios = _scatter_ratios(scattered, quantum, covered, lengths, model, detector.weights(energies), factor)
    raw = detector.read_out(quantum, rng if noise else None, gain=gain)
    if output == "raw":
        return Radiograph(raw.astype(np.float32), output, 0, len(energies), dropped, int(covered.sum()), 0, **ratios)
    flat = _exact_flat(photons, energies, detector, factor, raw.shape, focal_sigma_px)
    if flat_noise is not None:
        flat = detector.dark + (flat - detector.dark) * flat_noise
    weights = detector.weights(energies)
    floor = 0.5 * float((photons * weights).sum() / photons.sum())  # half a mean detected photon
    normalised = beer_lambert.normalise(raw, flat, detector.dark, floor)
    image = (normalised.transmission if output == "transmission" else normalised.line_integral).astype(np.float32)
    starved = normalised.starved_mask
    if output == "transmission":
        # A transmission below float32's smallest subnormal (~1.4e-45) is stored as 0: as
        # photon-starved as a clamped pixel (its −log is infinite), so it is counted with them.
        starved = starved | (image == 0)
    return Radiograph(image, output, int(starved.sum()), len(energies), dropped, int(covered.sum()),
                      int(np.count_nonzero(starved & covered)), **ratios)


def _scatter_ratios(scattered, detected, covered, lengths, model: SpectralModel, weights, factor) -> dict:
    """The view's scatter-to-primary ratios: in the detector's middle pixels (one, or the two or four
    around the centre), against their exact primary, and over the pixels the scene covers, against
    their summed primary (the ``detected`` signal, noisy or not, less the scatter: a sum over many
    pixels)."""
    rows, cols = scattered.shape
    middle = (slice((rows - 1) // 2, rows // 2 + 1), slice((cols - 1) // 2, cols // 2 + 1))
    exact = beer_lambert.expected_signal(np.asarray(lengths)[(slice(None), *middle)], model.mu, model.photons, weights,
                                         np.broadcast_to(factor, scattered.shape)[middle], threads=1)
    behind = detected[covered].sum() - scattered[covered].sum()
    return {"spr_centre": float(scattered[middle].sum() / exact.sum()),
            "spr_covered": float(scattered[covered].sum() / behind) if behind > 0 else 0.0}


def flat_noise(spectrum, detector: Detector, factor, shape: tuple[int, int], frames: int, rng, *,
               focal_sigma_px=(0.0, 0.0), bin_tolerance: float = BIN_TOLERANCE,
               threads: int | None = None) -> np.ndarray:
    """A scan's flat from ``frames`` noisy open-beam exposures, as a factor on the exact flat:
    ``(flat − dark) / (exact flat − dark)`` per pixel, float64 ``shape``.

    The flats' mean is drawn in one go: the sum of ``frames`` independent exposures is one exposure
    of ``frames`` times the photons, and their read noises average to ``electronic_noise / √frames``.
    """
    energies, photons, _ = _bins(spectrum, detector, bin_tolerance)
    focal_sigma_px = applied_focal_sigma_px(focal_sigma_px)
    open_beam = np.zeros((1, *shape), np.float32), np.zeros((1, len(energies)))  # no path length, no μ
    exposed = _detected(*open_beam, photons, energies, detector, frames * np.asarray(factor, dtype=np.float64),
                        focal_sigma_px, rng, threads, None) / frames
    flat = detector.read_out(exposed, rng, frames=frames) - detector.dark
    ratio = flat / (_exact_flat(photons, energies, detector, factor, shape, focal_sigma_px) - detector.dark)
    if np.any(ratio <= 0):
        raise PhysicsError(f"the mean of {frames} noisy flats has pixels without signal; raise the exposure (mas) "
                           "or the number of flats (flat_fields)")
    return ratio


def applied_focal_sigma_px(sigma_px) -> tuple[float, float]:
    """The focal blur's ``(rows, cols)`` standard deviations in pixels as applied: an axis whose blur is
    negligible (:func:`~xrayraster.physics.detector.negligible_blur`) gets 0, so it costs nothing,
    and a view with neither axis left is drawn as without a spot (Beer–Lambert's own noise sampling)."""
    return tuple(0.0 if negligible_blur(sigma) else float(sigma) for sigma in sigma_px)


def _bins(spectrum, detector: Detector, bin_tolerance: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The energy bins kept (:data:`BIN_TOLERANCE`): energies keV, photons, and the signal share dropped."""
    keep, dropped = spectrum.trim_mask(bin_tolerance, detector.weights(spectrum.energies))
    return spectrum.energies[keep], spectrum.fluence[keep], dropped


def _detected(lengths, mu, photons, energies, detector: Detector, factor, focal_sigma_px, rng, threads,
              table: SpectralTable | None, extra=None) -> np.ndarray:
    """The detected signal before read-out: expected (``rng`` None) or one noisy realisation, its
    sums over bins interpolated from ``table`` where there is one (noisy views without a focal spot).
    ``extra``: the mean and variance of the scatter's signal, added to the primary's and drawn with it.

    A focal spot blurs the transmitted intensity before its photons are counted, so the blurred
    mean (and, integrating, the blurred variance Σ E²·η·n) is drawn from: a Poisson count (counting)
    or :func:`~xrayraster.physics.beer_lambert.scaled_poisson`. Without one, Beer–Lambert's own sampling.
    """
    weights = detector.weights(energies)
    extra_mean, extra_variance = (0.0, 0.0) if extra is None else extra
    if not any(focal_sigma_px):
        if rng is None:
            return beer_lambert.expected_signal(lengths, mu, photons, weights, factor, threads) + extra_mean
        return beer_lambert.sampled_signal(lengths, mu, photons, detector.efficiency(energies), energies, factor,
                                           detector.counting, rng, threads, table, extra)
    mean = _focal_blur(beer_lambert.expected_signal(lengths, mu, photons, weights, factor, threads), *focal_sigma_px)
    mean += extra_mean
    if rng is None:
        return mean
    if detector.counting:
        return rng.poisson(mean).astype(np.float64)
    variance = beer_lambert.expected_signal(lengths, mu, photons, energies * weights, factor, threads)
    return scaled_poisson(mean, _focal_blur(variance, *focal_sigma_px) + extra_variance, rng)


def _focal_blur(image: np.ndarray, sigma_rows_px: float, sigma_cols_px: float) -> np.ndarray:
    """The focal spot's Gaussian averaged over each pixel: exact on the pixel-sharp edges of a view
    at any width (docs/realism.md measures it against sub-source sampling). ``image`` itself without a
    spot, or with one too small to show (:func:`applied_focal_sigma_px`)."""
    if not (sigma_rows_px or sigma_cols_px):
        return image
    return gaussian_blur(image, sigma_rows_px, sigma_cols_px, pixel_averaged=True)


def _exact_flat(photons, energies, detector: Detector, factor, shape, focal_sigma_px) -> np.ndarray:
    """The noise-free flat (dark included): the open beam, blurred as the views are."""
    open_beam = np.broadcast_to((photons * detector.weights(energies)).sum() * np.asarray(factor, dtype=np.float64),
                                shape)
    return detector.blur(_focal_blur(open_beam, *focal_sigma_px)) + detector.dark
