"""Scanner realism: imperfections of a real scan, each off by default (docs/realism.md).

* **Focal spot** (``focal_spot_mm``, the FWHM in mm of a Gaussian source spot): an object plane at
  distance z from the source casts a penumbra of ``spot · (SDD − z) / z`` on the detector, so the
  transmitted intensity is blurred by a Gaussian of that FWHM, z being one chosen plane
  (``focal_plane_mm``, default the rotation axis), before its photons are counted. A penumbra whose
  σ is below :data:`~xrayraster.physics.detector.NEGLIGIBLE_BLUR_PX` pixels is skipped (docs/realism.md).
* **Flat fields** (``flat_fields = N``): the flat that normalises every view is the mean of N noisy
  open-beam exposures, one realisation per scan, instead of the exact (noise-free) flat.
* **Gain variation** (``gain_variation = σ``): a fixed per-pixel gain map g, mean 1 and relative
  standard deviation σ, multiplies the signal and is not corrected by the (gain-free) flat: each line
  integral gains −ln g(p), the same in every view, which reconstructs as rings.
* **Scatter** (``scatter = "kernel"``): the photons the sample scatters onto the detector, added to
  each view's primary before its noise (:mod:`~xrayraster.physics.scatter`).

The two fixed patterns (the flat's noise and the gain map) are drawn once per scan from the scan's
seed, on streams of their own (:func:`calibration_rng`) apart from the views' noise streams.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..core.choices import SCATTER_MODELS, check_choice
from ..core.errors import PhysicsError
from ..core.geometry import as_vector_geometry

FWHM_PER_SIGMA = 2 * math.sqrt(2 * math.log(2))  # a Gaussian's full width at half maximum over its σ

# Seed-sequence words of the scan's fixed patterns. Each is wider than 32 bits, so ``[seed, tag]``
# becomes three words and never equals a view's ``[seed, view]`` stream.
FLAT_TAG = int.from_bytes(b"flat fields", "big")
GAIN_TAG = int.from_bytes(b"gain map", "big")


@dataclass(frozen=True)
class Realism:
    """Which imperfections a scan has (module docstring); the defaults are an ideal scanner.

    * ``focal_spot_mm``: FWHM of the Gaussian focal spot, mm (0: a point source).
    * ``focal_plane_mm``: distance from the source of the object plane whose magnification sets the
      blur, mm; None: the rotation axis (the plane through the origin parallel to the detector).
    * ``flat_fields``: number of noisy flats averaged into the scan's flat; None: the exact flat.
    * ``gain_variation``: relative standard deviation of the per-pixel gain (0: uniform gain).
    * ``scatter``: the scatter model, ``"none"`` or ``"kernel"`` (:mod:`~xrayraster.physics.scatter`).
    """

    focal_spot_mm: float = 0.0
    focal_plane_mm: float | None = None
    flat_fields: int | None = None
    gain_variation: float = 0.0
    scatter: str = "none"

    def __post_init__(self):
        check_choice(self.scatter, SCATTER_MODELS, "realism scatter", PhysicsError)
        for name in ("focal_spot_mm", "gain_variation"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise PhysicsError(f"realism {name} must be a finite number >= 0, got {value!r}")
        plane = self.focal_plane_mm
        if plane is not None:
            if isinstance(plane, bool) or not isinstance(plane, (int, float)) or not math.isfinite(plane) or plane <= 0:
                raise PhysicsError(f"realism focal_plane_mm must be a distance > 0 from the source (mm), got {plane!r}")
            if not self.focal_spot_mm:
                raise PhysicsError("realism focal_plane_mm needs focal_spot_mm > 0 "
                                   "(it sets where the spot's blur is exact)")
        frames = self.flat_fields
        if frames is not None and (isinstance(frames, bool) or not isinstance(frames, int) or frames < 1):
            raise PhysicsError(f"realism flat_fields must be an integer >= 1 (or None for the exact flat), "
                               f"got {frames!r}")

    @property
    def active(self) -> bool:
        """Whether any option is on (an ideal scanner otherwise)."""
        return self != Realism()

    @property
    def needs_seed(self) -> bool:
        """Whether a fixed random pattern (the flats' noise, the gain map) must be drawn."""
        return self.flat_fields is not None or self.gain_variation > 0

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def calibration_rng(seed: int, tag: int) -> np.random.Generator:
    """The generator of one of the scan's fixed patterns (:data:`FLAT_TAG`, :data:`GAIN_TAG`)."""
    return np.random.default_rng([int(seed), tag])


def focal_sigma_px(geometry, view: int, spot_fwhm_mm: float, plane_mm: float | None = None) -> tuple[float, float]:
    """The focal spot's blur on the detector as Gaussian standard deviations ``(rows, cols)`` in pixels.

    The object plane at ``plane_mm`` from the source (default the rotation axis, at the source's
    distance from the origin along the detector normal) is magnified M = SDD / z, and a spot of FWHM
    ``spot_fwhm_mm`` casts its points there ``spot · (M − 1)`` apart on the detector.
    """
    vec = as_vector_geometry(geometry)
    if vec.beam != "cone":
        raise PhysicsError("focal_spot_mm applies to cone-beam scans (a parallel beam has no source point)")
    s, d, u, v = np.split(vec.array[view], 4)
    normal = np.cross(u, v)
    normal /= np.linalg.norm(normal)
    sdd = abs(float(normal @ (d - s)))
    z = abs(float(normal @ s)) if plane_mm is None else float(plane_mm)
    if not 0 < z < sdd:
        raise PhysicsError(f"focal_plane_mm ({z:g} mm) must lie between the source and the detector ({sdd:g} mm away)")
    sigma_mm = spot_fwhm_mm / FWHM_PER_SIGMA * (sdd - z) / z
    return sigma_mm / float(np.linalg.norm(v)), sigma_mm / float(np.linalg.norm(u))


def gain_map(sigma: float, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """A per-pixel gain map ``shape`` (float64): log-normal with mean 1 and standard deviation ``sigma``.

    ln g ~ Normal(−s²/2, s²) with s² = ln(1 + σ²), so every gain is positive and −ln g, the offset it
    adds to a line integral, has standard deviation s (≈ σ for small σ: s = 0.0998 at σ = 0.1).
    """
    s2 = math.log1p(sigma * sigma)
    return np.exp(rng.normal(-s2 / 2, math.sqrt(s2), shape))
