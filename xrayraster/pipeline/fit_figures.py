"""What a segmentation network sees of a reconstruction, measured the same way on a real scan and on
its simulation (docs/fit.md): each class's attenuation, the noise, its power spectrum's shape, the
sharpness of the sample's surface and the rings.

Every figure is read off a volume (z, y, x, cm⁻¹) with a label volume on the same grid (0 the air
around the sample), ``inside``, the voxels the scan's field of view reaches, and each voxel
column's distance from the rotation axis (voxels):

* ``peaks``: per label, the median μ of its voxels a voxel or more inside its region (clear of
  the partial volume at its borders; all its voxels where too few are that far inside) and
  :data:`FACE_MARGIN_MM` or more from the sample's faces along the axis (all where too few are):
  a cone beam smears those faces (below), so μ near them tells the blur and the geometry as much
  as the class, and a blur the fit cannot pin down would bias the densities there;
* ``noise_sigma``: the noise of μ in the air three voxels or more from the sample: the standard
  deviation of the difference between neighbours along z over √2, which leaves out what varies
  slowly along z (a cone beam's streaks and cupping, the same in neighbouring slices) and keeps
  the photon noise (much of it independent from slice to slice);
* ``nps``: the noise power spectrum of that air in axial slices, radially averaged and normalised
  to sum 1 (its shape: a blur or a smoothing filter moves power to low frequencies);
* ``edge_width_mm``: the σ of the Gaussian that blurs the sample's surface: an error function fitted
  to the mean μ against the signed distance from the surface (voxels within four of it). It tells
  the blur only where the sample shows sides (surfaces whose normal lies within 45° of the orbit's
  plane), where a cone beam's FDK is sharp to the detector's resolution: a surface facing along the
  axis off the mid-plane is smeared by the cone's missing data over a width the geometry sets
  (Feldkamp's artefact: 0.25 mm for a blur of 0.05 mm, a sample wider than the grid, its top 1.9 mm
  above the mid-plane at 37 mm from the source). ``side_share`` is the sides' share of the surface's
  voxels, and :func:`sides_seen` says whether volumes show sides;
* ``ring_rms``: in the air, per axial slice, the mean μ over each one-voxel ring about the rotation
  axis, less its running median over nine rings; the RMS of that over rings and slices (cm⁻¹), at
  the rings whose nine lie wholly in the air.
  Noise alone gives a floor (the mean over a ring of n voxels has σ/√n of it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage, optimize, special

#: Voxels a class region is eroded by before its median is taken (its border's partial volume).
PEAK_EROSION = 1
#: How far (mm) a class's peak keeps from the sample's faces along the axis (module docstring): twice
#: the cone beam's smear of such a face (0.25 mm, below). On the shifted set's first scan (docs/ml.md),
#: read over the whole matrix the real and fitted peaks agreed to 0.5 % at 1.035 g/cm³ (hidden: 1.08),
#: while away from the faces the real matrix stood 4 % above the simulation's.
FACE_MARGIN_MM = 0.5
#: Voxels a class needs for its peak (after the erosion, or else before it).
MIN_VOXELS = 20
#: Voxels the air is kept from the sample for the noise, its spectrum and the rings.
AIR_MARGIN = 3
#: Voxels from the surface whose μ the edge's error function is fitted to.
EDGE_REACH = 4
#: The share of the surface's voxels within the field of view that must be sides for the edge to tell
#: the blur (a 10 × 10 × 4 mm block: 44 %; a threshold's bumps on a wide sample's faces: 6 %).
MIN_SIDE_SHARE = 0.2
#: Side of the square air patches of the noise power spectrum (voxels).
NPS_PATCH = 16
#: Rings over which the running median of the ring profile is taken.
RING_MEDIAN = 9


@dataclass(frozen=True)
class Figures:
    """A volume's figures (module docstring); a figure its volume cannot give is NaN (``nps``, the
    edge's ``edge_profile``, mean μ against the signed distance in mm: empty)."""

    peaks: dict[int, float]
    noise_sigma: float
    nps: tuple[float, ...]
    edge_width_mm: float
    ring_rms: float
    edge_profile: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())
    side_share: float = math.nan
    tracers: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"peaks": {str(k): v for k, v in self.peaks.items()}, "noise_sigma": self.noise_sigma,
                "nps": list(self.nps), "edge_width_mm": self.edge_width_mm, "ring_rms": self.ring_rms,
                "edge_profile_mm": list(self.edge_profile[0]), "edge_profile": list(self.edge_profile[1]),
                "side_share": self.side_share, **({"tracer_peaks": self.tracers} if self.tracers else {})}


def measure(volume: np.ndarray, labels: np.ndarray, inside: np.ndarray, axis_radius: np.ndarray,
            voxel_mm: float, tracers: dict | None = None) -> Figures:
    """The :class:`Figures` of ``volume`` with its ``labels``, field of view ``inside`` (bool, as the
    volume), the columns' ``axis_radius`` (rows, cols; voxels) and voxels of ``voxel_mm`` (the edge's unit);
    ``tracers`` (yarn → bool volume): the voxels each tracer's peak is the median μ of."""
    volume = np.asarray(volume, dtype=np.float64)
    peaks = class_peaks(volume, labels, inside, voxel_mm=voxel_mm)
    sample = labels > 0
    air = ~ndimage.binary_dilation(sample, iterations=AIR_MARGIN) & ndimage.binary_erosion(inside, iterations=1)
    pairs = air[1:] & air[:-1]
    noise = float((volume[1:] - volume[:-1])[pairs].std() / math.sqrt(2)) if pairs.sum() > 100 else math.nan
    near, signed = _near_surface(sample, inside)
    width, (distance, profile) = _edge(volume, near, signed)
    return Figures(peaks, noise, _nps(volume, air), width * voxel_mm, _ring_rms(volume, air, axis_radius),
                   (tuple((distance * voxel_mm).tolist()), tuple(profile.tolist())), _side_share(near, signed),
                   {yarn: float(np.median(volume[voxels])) for yarn, voxels in (tracers or {}).items() if voxels.any()})


def class_peaks(volume: np.ndarray, labels: np.ndarray, inside: np.ndarray, erosion: int = PEAK_EROSION,
                voxel_mm: float | None = None) -> dict[int, float]:
    """Each label's ``peaks`` figure (module docstring) in ``volume``, over the voxels ``inside``, its
    regions eroded by ``erosion`` voxels; with ``voxel_mm``, away from the sample's faces along the axis
    (:func:`away_from_faces`) where enough of a region is."""
    away = away_from_faces(labels > 0, voxel_mm) if voxel_mm else True
    peaks = {}
    for label in (int(v) for v in np.unique(labels) if v != 0):
        region = (labels == label) & inside
        inner = core(region & away, erosion)
        if inner.sum() < MIN_VOXELS:  # too little of it away from the faces: all of it
            inner = core(region, erosion)
        if inner.sum() >= MIN_VOXELS:
            peaks[label] = float(np.median(volume[inner]))
    return peaks


def away_from_faces(sample: np.ndarray, voxel_mm: float) -> np.ndarray:
    """The voxels of ``sample`` (bool, (z, y, x)) :data:`FACE_MARGIN_MM` or more from its faces along the
    axis (z); where the sample reaches the grid's top or bottom, that end is no face."""
    margin = max(int(math.ceil(FACE_MARGIN_MM / voxel_mm)), 1)
    return ndimage.binary_erosion(sample, np.ones((2 * margin + 1, 1, 1), bool), border_value=1)


def core(region: np.ndarray, erosion: int = PEAK_EROSION) -> np.ndarray:
    """``region`` (bool) eroded by ``erosion`` voxels, clear of the partial volume at its border; all of
    it where fewer than :data:`MIN_VOXELS` would remain (a region too thin to erode)."""
    inner = ndimage.binary_erosion(region, iterations=erosion)
    return inner if inner.sum() >= MIN_VOXELS else region


def _nps(volume: np.ndarray, air: np.ndarray) -> tuple[float, ...]:
    """The radially averaged power spectrum of the air's patches (module docstring), sums to 1."""
    n = NPS_PATCH
    power, count = np.zeros((n, n)), 0
    for z in range(volume.shape[0]):
        for y in range(0, volume.shape[1] - n + 1, n):
            for x in range(0, volume.shape[2] - n + 1, n):
                if air[z, y:y + n, x:x + n].all():
                    patch = volume[z, y:y + n, x:x + n]
                    power += np.abs(np.fft.fft2(patch - patch.mean())) ** 2
                    count += 1
    if not count or not power.any():  # no air patch, or air without noise
        return ()
    frequency = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    bins = np.minimum((frequency * n).astype(int), n // 2)
    radial = np.bincount(bins.ravel(), power.ravel()) / np.bincount(bins.ravel())
    return tuple((radial / radial.sum()).tolist())


def sides_seen(*figures: Figures) -> bool:
    """Whether in every one of ``figures`` the sides are :data:`MIN_SIDE_SHARE` of the surface's
    voxels (module docstring)."""
    return all(f.side_share >= MIN_SIDE_SHARE for f in figures)


def _side_share(near: np.ndarray, distance: np.ndarray) -> float:
    """The share of the ``near`` voxels whose surface normal (the ``distance``'s gradient) lies within
    45° of the orbit's plane."""
    gradient = np.gradient(distance)
    side = gradient[0] ** 2 <= 0.5 * (gradient[0] ** 2 + gradient[1] ** 2 + gradient[2] ** 2)
    return float((near & side).sum() / max(near.sum(), 1))


def _near_surface(sample: np.ndarray, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The voxels within :data:`EDGE_REACH` of the sample's surface and in the field of view, and every
    voxel's signed distance from the surface (voxels, + outside)."""
    outside = ndimage.distance_transform_edt(~sample)
    within = ndimage.distance_transform_edt(sample)
    distance = np.where(sample, -(within - 0.5), outside - 0.5)  # voxel centres: ±0.5 at the surface
    near = (np.abs(distance) <= EDGE_REACH) & ndimage.binary_erosion(inside, iterations=EDGE_REACH)
    return near, distance


def _edge(volume: np.ndarray, near: np.ndarray, distance: np.ndarray) -> tuple[float, tuple]:
    """σ (voxels) of the error function fitted to μ of the ``near`` voxels against their signed
    ``distance`` from the sample's surface, and that profile (distances in voxels, mean μ)."""
    if near.sum() < 50:
        return math.nan, (np.zeros(0), np.zeros(0))
    d, v = distance[near], volume[near]
    centres = np.round(d * 4) / 4  # quarter-voxel bins of the profile
    bins, index = np.unique(centres, return_inverse=True)
    profile = np.bincount(index, v) / np.bincount(index)
    weight = np.sqrt(np.bincount(index))

    def step(x, low, high, centre, width):
        return low + (high - low) * 0.5 * special.erfc((x - centre) / (math.sqrt(2) * width))

    start = (float(v[d > 1].mean()) if (d > 1).any() else 0.0, float(v[d < -1].mean()) if (d < -1).any() else 1.0,
             0.0, 0.7)
    try:
        fitted, _ = optimize.curve_fit(step, bins, profile, p0=start, sigma=1 / weight,
                                       bounds=([-np.inf, -np.inf, -2.0, 0.05], [np.inf, np.inf, 2.0, 5.0]))
    except (RuntimeError, ValueError):
        return math.nan, (bins, profile)
    return float(fitted[3]), (bins, profile)


def _ring_rms(volume: np.ndarray, air: np.ndarray, axis_radius: np.ndarray) -> float:
    """The rings' RMS (module docstring): the ring profile's fine structure in the air, cm⁻¹, at the
    rings whose nine-ring neighbourhood lies wholly in the air."""
    ring = np.asarray(axis_radius).astype(int).ravel()
    half = RING_MEDIAN // 2
    residues = []
    for z in range(volume.shape[0]):
        mask = air[z].ravel()
        counts = np.bincount(ring[mask], minlength=ring.max() + 1)
        sums = np.bincount(ring[mask], volume[z].ravel()[mask], minlength=ring.max() + 1)
        profile = np.where(counts >= 16, sums / np.maximum(counts, 1), np.nan)
        if len(profile) < RING_MEDIAN:
            continue
        windows = np.lib.stride_tricks.sliding_window_view(profile, RING_MEDIAN)
        whole = ~np.isnan(windows).any(axis=1)
        residues.append(profile[half:len(profile) - half][whole] - np.median(windows[whole], axis=1))
    values = np.concatenate(residues) if residues else np.zeros(0)
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def mixture_means(values: np.ndarray, peaks: dict[int, float], iterations: int = 100) -> dict[int, float]:
    """The means of a 1-D Gaussian mixture of ``values`` (EM on a histogram of 1024 bins), a
    component a class started at its ``peaks`` value, by class."""
    counts, edges = np.histogram(values, bins=1024)
    centres = (edges[:-1] + edges[1:]) / 2
    labels = sorted(peaks, key=peaks.get)
    means = np.array([peaks[k] for k in labels], dtype=np.float64)
    gaps = np.diff(means)
    spread = np.full(len(means), max(float(gaps[gaps > 0].min()) / 4 if (gaps > 0).any() else 0.0,
                                     float(np.std(values)) / 20, 1e-6))
    share = np.full(len(means), 1 / len(means))
    for _ in range(iterations):
        density = share * np.exp(-0.5 * ((centres[:, None] - means) / spread) ** 2) / spread
        weight = density / np.maximum(density.sum(axis=1, keepdims=True), 1e-300) * counts[:, None]
        total = np.maximum(weight.sum(axis=0), 1e-12)
        means = (weight * centres[:, None]).sum(axis=0) / total
        spread = np.maximum(np.sqrt((weight * (centres[:, None] - means) ** 2).sum(axis=0) / total), 1e-6)
        share = total / total.sum()
    return {k: float(m) for k, m in zip(labels, means)}
