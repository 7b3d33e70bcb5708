"""X-ray source spectra: photons per energy bin, per mm², at 1 m from the focal spot.

A :class:`Spectrum` is an immutable value: bin centres ``energies_kev`` (keV, strictly
increasing, > 0) and ``photons`` = photons per mm² in each bin at the reference distance
:data:`REFERENCE_DISTANCE_MM` (1 m) on the central axis, for the whole exposure the spectrum was
made with (e.g. the tube's mAs). Everything downstream scales from there::

    spec = Spectrum.from_tube(kvp=40, anode="W", filters={"Al": 2.0}, mas=10)
    n = spec.photons_per_pixel(distance_mm=140.0, pixel_area_mm2=0.0723**2)   # (bins,)
    fast = spec.trimmed(1e-4)   # drop bins carrying ≤ 1e-4 of the detector signal

Sources: :meth:`Spectrum.from_tube` (SpekPy), :meth:`Spectrum.monochromatic`,
:meth:`Spectrum.from_arrays`, :meth:`Spectrum.from_file` (two-column text; :meth:`Spectrum.to_file`
writes it).

SpekPy units (read from SpekPy 2.5.4's source, ``SpekPy.get_spectrum`` and
``SpekTools.generate_spectrum``): ``get_spectrum()`` returns mid-bin energies [keV] and
"[Photons cm^-2 keV^-1]" at the focus-to-detector distance ``z`` [cm] (default 100 cm), already
multiplied by the ``mas`` the Spek was made with (``spk = ... * mas * dscale * ...`` with
``dscale = 1 / (x² + y² + z²)``); filter thicknesses are in mm. So photons per mm² per bin at
1 m = ``spk · dk / 100`` with ``z = 100``.
"""

from __future__ import annotations

import functools
import math
import re
import sys
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.errors import SpectrumError
from ..core.files import atomic_write_text
from ..core.inputs import read_text_file

if TYPE_CHECKING:
    from ..core.estimate import Estimate

__all__ = ["REFERENCE_DISTANCE_MM", "SPEKPY_ANODES", "Spectrum", "SpectrumError"]

REFERENCE_DISTANCE_MM = 1000.0  # spectra are photons per mm² at 1 m from the focal spot
SPEKPY_ANODES = ("W", "Mo", "Rh", "Cr", "Cu", "Ag", "Au")  # SpekPy 2.x reflection-target anodes
_MM2_PER_CM2 = 100.0
_SPLIT = re.compile(r"[\s,]+")


#: What SpekPy holds and takes per energy bin of a tube spectrum: measured at 40 kV, 2.0 GiB and
#: 13.6 s for 39,000 bins (bin_kev = 0.001), 0.3 GiB and 1.7 s for 3,900, rounded up.
BYTES_PER_SPEKPY_BIN = 56_000
MAX_KVP = 1000.0
SECONDS_PER_SPEKPY_BIN = 3.5e-4


@dataclass(frozen=True)
class SpectrumJob:
    """SpekPy's tube spectrum of ``kvp`` kV in bins ``bin_kev`` keV wide, before SpekPy runs: a
    :class:`~xrayraster.core.estimate.Planned` job (a bin width that makes more energy bins than
    memory holds is refused)."""

    kvp: float
    bin_kev: float

    def estimate(self) -> Estimate:
        from ..core.estimate import Estimate, Part  # the spectrum module stays light to import

        kvp, bin_kev = self.kvp, self.bin_kev
        bins = math.ceil(kvp / bin_kev)
        part = Part(f"{bins} energy bins", bins * BYTES_PER_SPEKPY_BIN, f"bin_kev = {bin_kev:g}",
                    "use wider energy bins (bin_kev, default 0.5 keV)")
        return Estimate(f"tube spectrum of {kvp:g} kV", bins * SECONDS_PER_SPEKPY_BIN, (part,))


def _finite_number(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise SpectrumError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise SpectrumError(f"{name} must be finite, got {value!r}")
    return x


def _as_float_tuple(name: str, values) -> tuple[float, ...]:
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise SpectrumError(f"{name} must be a sequence of numbers, got {values!r:.80}") from None
    if arr.ndim != 1:
        raise SpectrumError(f"{name} must be one-dimensional (one value per energy bin), got shape {arr.shape}")
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class Spectrum:
    """Photons per energy bin per mm² at 1 m (:data:`REFERENCE_DISTANCE_MM`), central axis.

    ``energies_kev``: bin centres in keV, strictly increasing, all > 0. ``photons``: photons per
    mm² in each bin at 1 m for the exposure the spectrum was made with; finite, ≥ 0, at least one
    > 0. ``description`` is a free-text record of where the spectrum came from; it is not part of
    equality. Sequences (lists, arrays) are accepted and stored as tuples of float, so a spectrum
    is hashable.
    """

    energies_kev: tuple[float, ...]
    photons: tuple[float, ...]
    description: str = field(default="", compare=False)

    def __post_init__(self):
        energies = _as_float_tuple("energies_kev", self.energies_kev)
        photons = _as_float_tuple("photons", self.photons)
        object.__setattr__(self, "energies_kev", energies)
        object.__setattr__(self, "photons", photons)
        object.__setattr__(self, "description", str(self.description))
        if len(energies) == 0:
            raise SpectrumError("energies_kev is empty: a spectrum needs at least one energy bin")
        if len(photons) != len(energies):
            raise SpectrumError(
                f"photons has {len(photons)} values but energies_kev has {len(energies)}: give one photon count per energy bin"
            )
        e = np.asarray(energies)
        n = np.asarray(photons)
        if not np.all(np.isfinite(e)):
            i = int(np.flatnonzero(~np.isfinite(e))[0])
            raise SpectrumError(f"energies_kev[{i}] = {e[i]!r} is not finite: energies must be finite keV values")
        if not np.all(e > 0):
            i = int(np.flatnonzero(~(e > 0))[0])
            raise SpectrumError(f"energies_kev[{i}] = {e[i]!r}: energies must be > 0 keV")
        if e.size > 1 and not np.all(np.diff(e) > 0):
            i = int(np.flatnonzero(~(np.diff(e) > 0))[0])
            raise SpectrumError(
                f"energies_kev must be strictly increasing: energies_kev[{i}] = {e[i]!r} ≥ energies_kev[{i + 1}] = {e[i + 1]!r}; "
                "sort the bins and merge duplicates"
            )
        if not np.all(np.isfinite(n)):
            i = int(np.flatnonzero(~np.isfinite(n))[0])
            raise SpectrumError(f"photons[{i}] = {n[i]!r} is not finite: photon counts must be finite")
        if not np.all(n >= 0):
            i = int(np.flatnonzero(~(n >= 0))[0])
            raise SpectrumError(f"photons[{i}] = {n[i]!r} is negative: photon counts must be ≥ 0")
        if not np.any(n > 0):
            raise SpectrumError("photons are all zero: at least one energy bin must have photons > 0")

    # ---------------------------------------------------------------- constructors

    @classmethod
    def from_arrays(cls, energies_kev, photons_per_mm2_at_1m, description: str = "") -> Spectrum:
        """Bin centres (keV) and photons per mm² per bin at 1 m, validated as in the class."""
        return cls(energies_kev, photons_per_mm2_at_1m, description=description or "from arrays")

    @classmethod
    def monochromatic(cls, energy_kev: float, photons_per_mm2_at_1m: float) -> Spectrum:
        """One bin: ``photons_per_mm2_at_1m`` photons per mm² at 1 m, all at ``energy_kev``."""
        energy = _finite_number("energy_kev", energy_kev)
        photons = _finite_number("photons_per_mm2_at_1m", photons_per_mm2_at_1m)
        if photons <= 0:
            raise SpectrumError(f"photons_per_mm2_at_1m must be > 0, got {photons_per_mm2_at_1m!r}")
        return cls((energy,), (photons,), description=f"monochromatic {energy:g} keV, {photons:g} photons/mm² at 1 m")

    @classmethod
    def from_file(cls, path) -> Spectrum:
        """Two columns per line: energy (keV), photons per mm² in that bin at 1 m.

        Columns are separated by commas and/or whitespace; ``#`` starts a comment (whole line or
        the rest of a line); blank lines are skipped. Errors name the file and line number and say
        what is wrong, but never quote the line: a message can travel where the file's text must
        not (a preview's answer to a web page).
        """
        path = Path(path)
        text = read_text_file(path, "spectrum file", SpectrumError)
        energies: list[float] = []
        photons: list[float] = []
        for number, raw in enumerate(text.splitlines(), start=1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            where = f"spectrum file {str(path)!r} line {number}"
            cols = [c for c in _SPLIT.split(line) if c]
            if len(cols) != 2:
                raise SpectrumError(f"{where}: expected 2 columns (energy keV, photons per mm² at 1 m), got {len(cols)}")
            try:
                e, n = float(cols[0]), float(cols[1])
            except ValueError:
                raise SpectrumError(f"{where}: not two numbers (energy keV, photons per mm² at 1 m)") from None
            if not (math.isfinite(e) and math.isfinite(n)):
                raise SpectrumError(f"{where}: values must be finite (not nan or inf)")
            if e <= 0:
                raise SpectrumError(f"{where}: energy must be > 0 keV")
            if n < 0:
                raise SpectrumError(f"{where}: photons must be ≥ 0")
            if energies and e <= energies[-1]:
                raise SpectrumError(f"{where}: energies must be strictly increasing (above the line before's)")
            energies.append(e)
            photons.append(n)
        if not energies:
            raise SpectrumError(f"spectrum file {str(path)!r} has no data lines: give 'energy_keV photons' pairs, one per line")
        try:
            return cls(energies, photons, description=f"from file {path.name}")
        except SpectrumError as exc:
            raise SpectrumError(f"spectrum file {str(path)!r}: {exc}") from None

    def to_file(self, path) -> Path:
        """Write the two-column text that :meth:`from_file` reads (exact round trip), atomically."""
        lines = ["# xrayraster spectrum: energy_keV, photons per mm² per bin at 1 m"]
        lines += [f"# {line}" for line in self.description.splitlines()]
        lines += [f"{e!r}, {n!r}" for e, n in zip(self.energies_kev, self.photons)]
        content = "\n".join(lines) + "\n"
        return atomic_write_text(path, content)

    @classmethod
    def from_tube(
        cls,
        kvp: float,
        anode: str = "W",
        anode_angle_deg: float = 12.0,
        filters: Mapping[str, float] | None = None,
        mas: float = 1.0,
        bin_kev: float = 0.5,
    ) -> Spectrum:
        """A tube spectrum from SpekPy, on the central axis, at 1 m, for ``mas``.

        ``kvp``: tube potential (kV; SpekPy 2 allows 10–500 kV for W, 10–50 kV for the other
        anodes). ``anode``: one of :data:`SPEKPY_ANODES`. ``anode_angle_deg``: anode (target)
        angle. ``filters``: added filtration, SpekPy material name → thickness in mm, e.g.
        ``{"Al": 2.0, "Cu": 0.1}`` (names as ``spekpy.Spek.show_matls()`` lists them; add
        ``"Air": 1000.0`` for 1 m of air — nothing else is assumed between focus and detector).
        ``mas``: tube current × time (mAs). ``bin_kev``: energy bin width (keV).

        Photons per mm² per bin at 1 m = SpekPy ``get_spectrum()`` [photons cm⁻² keV⁻¹ at z = 100 cm,
        for ``mas``] × ``bin_kev`` ÷ 100 (mm² per cm²). SpekPy's default physics model ("casim")
        and attenuation data are used; the heel effect and off-axis filter obliquity are not
        modelled (the spectrum is the central-axis one everywhere).
        """
        kvp = _finite_number("kvp", kvp)
        if not 0.0 < kvp <= MAX_KVP:  # SpekPy has the last word inside; a bound first keeps the bin count finite
            raise SpectrumError(f"kvp must be > 0 and at most {MAX_KVP:g} kV (SpekPy models 10–500 kV tubes), got {kvp!r}")
        if not isinstance(anode, str) or anode not in SPEKPY_ANODES:
            raise SpectrumError(f"anode {anode!r} is not a SpekPy anode: use one of {', '.join(SPEKPY_ANODES)}")
        angle = _finite_number("anode_angle_deg", anode_angle_deg)
        if not 0.0 < angle < 90.0:
            raise SpectrumError(f"anode_angle_deg must be between 0 and 90 degrees (typically 5–20), got {anode_angle_deg!r}")
        mas = _finite_number("mas", mas)
        if mas <= 0:
            raise SpectrumError(f"mas must be > 0 (tube current × time, mAs), got {mas!r}")
        dk = _finite_number("bin_kev", bin_kev)
        if dk <= 0 or dk >= kvp:
            raise SpectrumError(f"bin_kev must be > 0 keV and below kvp ({kvp:g}), got {bin_kev!r}")
        from ..core.estimate import plan  # the spectrum module stays light to import

        plan(SpectrumJob(kvp, dk), SpectrumError)
        if filters is None:
            filters = {}
        if not isinstance(filters, Mapping):
            raise SpectrumError(f"filters must be a dict of SpekPy material name → thickness in mm, e.g. {{'Al': 2.0}}, got {filters!r}")
        filter_list: list[tuple[str, float]] = []
        for material, thickness in filters.items():
            if not isinstance(material, str) or not material:
                raise SpectrumError(f"filters: material names must be non-empty strings (SpekPy names), got {material!r}")
            t = _finite_number(f"filters[{material!r}] (mm)", thickness)
            if t < 0:
                raise SpectrumError(f"filters[{material!r}] = {thickness!r} mm: filter thickness must be ≥ 0 mm")
            filter_list.append((material, t))

        spek = _tube_model(kvp, angle, anode, dk, tuple(filter_list))
        with _TUBE_LOCK:  # the cached model is shared: set its mAs and read it in one step
            spek.set(mas=mas)
            energies, per_kev_per_cm2 = spek.get_spectrum(edges=False, flu=True, diff=True)
        photons = np.asarray(per_kev_per_cm2, dtype=np.float64) * dk / _MM2_PER_CM2

        version = getattr(sys.modules["spekpy"], "__version__", "?")
        filt = ", ".join(f"{m} {t:g} mm" for m, t in filter_list) or "none"
        physics = getattr(getattr(spek.state, "model_parameters", None), "physics", "default")
        description = (
            f"SpekPy {version} tube spectrum: {kvp:g} kVp, {anode} anode at {angle:g}°, filters: {filt}, "
            f"{mas:g} mAs, {dk:g} keV bins, physics {physics}; photons per mm² per bin at 1 m, central axis"
        )
        if not np.any(photons > 0):
            raise SpectrumError(f"filters: no photons leave the tube ({filt}): reduce the filtration or raise kvp")
        return cls(np.asarray(energies, dtype=np.float64), photons, description=description)

    # ---------------------------------------------------------------- arrays

    @property
    def energies(self) -> np.ndarray:
        """Bin centres, keV, float64 (a new array)."""
        return np.array(self.energies_kev, dtype=np.float64)

    @property
    def fluence(self) -> np.ndarray:
        """Photons per mm² per bin at 1 m, float64 (a new array)."""
        return np.array(self.photons, dtype=np.float64)

    @property
    def total(self) -> float:
        """Photons per mm² at 1 m, all bins."""
        return float(np.sum(self.fluence))

    @property
    def n_bins(self) -> int:
        return len(self.energies_kev)

    def __len__(self) -> int:
        return len(self.energies_kev)

    # ---------------------------------------------------------------- geometry

    def photons_per_pixel(self, distance_mm, pixel_area_mm2, cos_obliquity=1.0) -> np.ndarray:
        """Photons per bin arriving on a pixel (expected count, no attenuation).

        ``n_b = photons_b · (REFERENCE_DISTANCE_MM / distance_mm)² · pixel_area_mm2 · cos_obliquity``

        inverse square from 1 m to the pixel's distance from the focal spot, times the pixel area,
        times the cosine of the angle between the ray and the pixel normal (a tilted pixel
        intercepts less of the beam). No air attenuation beyond what the spectrum includes.
        Scalars give shape ``(bins,)``; arrays broadcast against each other and give
        ``(bins, *broadcast_shape)`` — bins first, like ``(bins, rows, cols)`` in the physics.
        """
        d = np.asarray(distance_mm, dtype=np.float64)
        a = np.asarray(pixel_area_mm2, dtype=np.float64)
        c = np.asarray(cos_obliquity, dtype=np.float64)
        if not np.all(np.isfinite(d) & (d > 0)):
            raise SpectrumError("distance_mm must be finite and > 0 (focal spot to pixel, mm)")
        if not np.all(np.isfinite(a) & (a > 0)):
            raise SpectrumError("pixel_area_mm2 must be finite and > 0 (mm²)")
        if not np.all(np.isfinite(c) & (c >= 0) & (c <= 1)):
            raise SpectrumError("cos_obliquity must be in [0, 1] (cosine of the ray's incidence on the pixel)")
        try:
            factor = (REFERENCE_DISTANCE_MM / d) ** 2 * a * c
        except ValueError:
            raise SpectrumError(
                f"distance_mm {d.shape}, pixel_area_mm2 {a.shape} and cos_obliquity {c.shape} do not broadcast together"
            ) from None
        fluence = self.fluence
        return fluence.reshape(fluence.shape + (1,) * factor.ndim) * factor

    # ---------------------------------------------------------------- trimming

    def trim_mask(self, tolerance: float = 1e-4, weights=None) -> tuple[np.ndarray, float]:
        """Which bins :meth:`trimmed` keeps, and the fraction of the signal it drops.

        Contribution of bin i: ``photons_i · weights_i`` (default weights: the energy, i.e. an
        energy-integrating detector, signal ∝ N·E; pass ``E·η(E)`` for a detector efficiency η, or
        ``η`` for photon counting). Bins are dropped smallest contribution first while the
        cumulative dropped contribution stays ≤ ``tolerance`` × total; ties go lowest energy first.
        Zero contributions (e.g. zero-photon bins) are always dropped; at least one bin is kept.
        Returns ``(keep, dropped_fraction)``: a bool array of shape (bins,) and the dropped
        contribution ÷ total (≤ tolerance unless only the one largest bin was left).
        """
        tol = _finite_number("tolerance", tolerance)
        if tol < 0:
            raise SpectrumError(f"tolerance must be ≥ 0 (fraction of the signal that may be dropped), got {tolerance!r}")
        if weights is None:
            w = self.energies
        else:
            try:
                w = np.asarray(weights, dtype=np.float64)
            except (TypeError, ValueError):
                raise SpectrumError("weights must be numbers, one per energy bin") from None
            if w.shape != (self.n_bins,):
                raise SpectrumError(f"weights must have one value per energy bin ({self.n_bins}), got shape {w.shape}")
            if not np.all(np.isfinite(w) & (w >= 0)):
                raise SpectrumError("weights must be finite and ≥ 0 (signal per photon in each bin)")
        contribution = self.fluence * w
        total = float(contribution.sum())
        if not total > 0:
            raise SpectrumError("weights give zero signal for every bin with photons: nothing to trim against; check the weights")
        order = np.argsort(contribution, kind="stable")
        cumulative = np.cumsum(contribution[order])
        n_drop = int(np.searchsorted(cumulative, tol * total, side="right"))
        n_drop = min(n_drop, self.n_bins - 1)
        keep = np.ones(self.n_bins, dtype=bool)
        keep[order[:n_drop]] = False
        dropped = float(contribution[~keep].sum()) / total
        return keep, dropped

    def trimmed(self, tolerance: float = 1e-4, weights=None) -> Spectrum:
        """A spectrum without the bins that together carry ≤ ``tolerance`` of the signal.

        See :meth:`trim_mask` for the rule and the weights; use it directly for the mask and the
        dropped fraction. The kept bins stay in energy order with their photon counts unchanged
        (the dropped photons are not redistributed); the description records what was dropped.
        """
        keep, dropped = self.trim_mask(tolerance, weights)
        e = np.asarray(self.energies_kev)[keep]
        n = np.asarray(self.photons)[keep]
        what = "energy-weighted" if weights is None else "weighted"
        note = (
            f"trimmed: kept {int(keep.sum())} of {self.n_bins} bins, dropped {dropped:.3g} of the {what} signal "
            f"(tolerance {float(tolerance):g})"
        )
        description = f"{self.description}; {note}" if self.description else note
        return Spectrum(e, n, description=description)


# SpekPy builds its tube model (the electron penetration and bremsstrahlung tables for one kVp,
# anode, angle and bin width; 0.3-0.5 s) in Spek(), and scales it by mAs only when the spectrum is
# read, so a model is kept per tube and filtration and only its mAs is set anew: a dataset that
# draws the exposure but keeps the tube, or a preview changing the mAs, pays for the model once.
# The spectrum is the same, bit for bit, as a new Spek's (tests/physics/test_spectrum.py).
_TUBE_LOCK = threading.Lock()


@functools.lru_cache(maxsize=8)
def _tube_model(kvp: float, angle: float, anode: str, dk: float, filters: tuple[tuple[str, float], ...]):
    """A SpekPy ``Spek`` of this tube (mAs 1 until set), with ``filters`` ((material, mm), ...) applied."""
    try:
        import spekpy
    except ImportError:  # pragma: no cover - spekpy is a declared dependency
        raise SpectrumError("from_tube needs SpekPy: pip install 'spekpy>=2.0'") from None
    try:
        spek = spekpy.Spek(kvp=kvp, th=angle, targ=anode, dk=dk, mas=1.0, x=0.0, y=0.0, z=REFERENCE_DISTANCE_MM / 10.0)
    except Exception as exc:  # noqa: BLE001 - SpekPy raises bare Exception naming the limit
        message = str(exc)
        name = "kvp" if "kvp" in message.lower() else "anode" if "anode" in message.lower() else "tube parameters"
        raise SpectrumError(f"{name}: SpekPy refused kvp={kvp:g}, anode={anode!r}, bin_kev={dk:g}: {message}") from None
    for material, t in filters:
        try:
            spek.filter(material, t)
        except Exception:  # noqa: BLE001 - SpekPy: bare Exception for an unknown material
            raise SpectrumError(
                f"filters: {material!r} is not a SpekPy material; use a SpekPy name such as 'Al', 'Cu', 'Be', 'Air' "
                "(spekpy.Spek.show_matls() lists them; names are case-sensitive)"
            ) from None
    return spek
