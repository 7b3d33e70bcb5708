"""Materials: elemental composition + density, and their X-ray attenuation from xraylib.

A :class:`Material` is an immutable, hashable value. Two materials are equal when their
composition (atomic number, mass fraction) and density are equal; the ``name`` is a label only.
This is what lets the scene collapse objects made of the same stuff into one output channel::

    water = Material.from_formula("H2O", density=1.0)
    same = Material.from_mass_fractions({"H": 0.1119, "O": 0.8881}, 1.0)   # not equal: 4 digits
    carbon = Material.element("C", density=1.72)
    epoxy = Material.from_mass_fractions({"C": 0.404, "H": 0.481, "Cl": 0.019, "O": 0.096}, 1.2)

Canonical form (applied on every construction, so equal compositions compare equal):
elements sorted by atomic number, zero fractions dropped, fractions normalised to sum 1 and
rounded to 12 significant digits.

Named materials with published compositions and densities: ``Material.named("water")``
(:meth:`Material.library_names` lists them; sources in :mod:`xrayraster.scene.material_library`).

Units: density g/cm³, energies keV, :meth:`Material.mass_attenuation` cm²/g,
:meth:`Material.attenuation_per_mm` (also :meth:`Material.attenuation`) mm⁻¹, the package's
internal unit; reconstructions (``xr.Volume``) are in cm⁻¹ (docs/physics.md).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Mapping

import numpy as np
import xraylib

from ..core.errors import MaterialError
from .material_library import LIBRARY, library_key

try:  # array interface shipped with the xraylib wheels; same C code as the scalar functions
    import xraylib_np as _xraylib_np
except ImportError:  # pragma: no cover - older/partial installs: scalar loop with a cache (_scalar)
    _xraylib_np = None

__all__ = ["Material", "MaterialError", "ENERGY_MIN_KEV", "ENERGY_MAX_KEV", "Z_MAX"]

# Range over which xraylib 4.3's cross-section splines are defined (measured: CS_Total raises
# "Spline extrapolation is not allowed" above 800 keV and "Energy must be strictly positive" /
# extrapolation below 0.1 keV). Outside it we raise rather than extrapolate.
ENERGY_MIN_KEV = 0.1
ENERGY_MAX_KEV = 800.0
# Highest atomic number with cross sections in xraylib (Z 99+ raise "Z out of range").
Z_MAX = 98

_SUM_TOL_SILENT = 1e-6  # |sum - 1| up to this: normalised silently
_SUM_TOL_WARN = 1e-2  # up to this: normalised with a warning; beyond it: error
_SIG_DIGITS = 12  # fractions are rounded to this many significant digits


def _round_sig(x: float, digits: int = _SIG_DIGITS) -> float:
    return float(f"{x:.{digits - 1}e}") if x != 0.0 else 0.0


def _symbol(z: int) -> str:
    return xraylib.AtomicNumberToSymbol(int(z))


def _atomic_number(symbol) -> int:
    """Element symbol (case-sensitive, e.g. "Cl") or atomic number → Z, validated."""
    if isinstance(symbol, (int, np.integer)) and not isinstance(symbol, bool):
        z = int(symbol)
        if not 1 <= z <= Z_MAX:
            raise MaterialError(f"element: atomic number {z} is out of range; use 1..{Z_MAX} (H..Cf)")
        return z
    if not isinstance(symbol, str):
        raise MaterialError(f"element: expected a chemical symbol such as 'Al' or an atomic number, got {symbol!r}")
    try:
        z = xraylib.SymbolToAtomicNumber(symbol.strip())
    except ValueError:
        raise MaterialError(
            f"element: unknown chemical symbol {symbol!r}; use a symbol such as 'C', 'Al' or 'Cl' "
            "(case matters)"
        ) from None
    if not 1 <= z <= Z_MAX:
        raise MaterialError(f"element: {symbol!r} (Z={z}) has no cross sections in xraylib; use Z <= {Z_MAX}")
    return z


def _canonical(composition) -> tuple[tuple[int, float], ...]:
    """Validate and canonicalise ((Z, mass fraction), ...): see the module docstring."""
    try:
        items = [(z, w) for z, w in composition]
    except (TypeError, ValueError):
        raise MaterialError(
            "composition: expected pairs (atomic number, mass fraction), e.g. ((1, 0.112), (8, 0.888))"
        ) from None
    if not items:
        raise MaterialError("composition: no elements given; give at least one element with a mass fraction")
    merged: dict[int, float] = {}
    for z, w in items:
        z = _atomic_number(z)
        try:
            w = float(w)
        except (TypeError, ValueError):
            raise MaterialError(f"composition: mass fraction of {_symbol(z)} must be a number, got {w!r}") from None
        if not math.isfinite(w) or w < 0:
            raise MaterialError(
                f"composition: mass fraction of {_symbol(z)} must be finite and >= 0, got {w!r}"
            )
        merged[z] = merged.get(z, 0.0) + w
    total = math.fsum(merged.values())
    if total == 0:
        raise MaterialError("composition: mass fractions sum to 0; give positive mass fractions summing to 1")
    _check_sum(total, "composition", "mass fractions")
    # A composition that is already canonical (rounded, sum within ~n*5e-13 of 1) passes through
    # unchanged, so canonicalisation is idempotent and repr() round-trips exactly.
    if abs(total - 1.0) > 1e-10:
        merged = {z: w / total for z, w in merged.items()}
    return tuple((z, _round_sig(merged[z])) for z in sorted(merged) if merged[z] > 0)


def _check_sum(total: float, field: str, what: str) -> None:
    """Fractions (``what``) of ``field`` summing to ``total`` are usable as they are within
    _SUM_TOL_SILENT of 1, with a warning (the caller normalises) up to _SUM_TOL_WARN; else an error."""
    dev = abs(total - 1.0)
    if dev > _SUM_TOL_WARN:
        raise MaterialError(
            f"{field}: {what} sum to {total:.6g}, not 1; give fractions (not percent) "
            f"summing to 1 (within {_SUM_TOL_WARN:g})"
        )
    if dev > _SUM_TOL_SILENT:
        warnings.warn(
            f"{field}: {what} sum to {total:.6g}, not 1; normalised to sum to 1",
            UserWarning,
            stacklevel=_caller_stacklevel(),
        )


def _caller_stacklevel() -> int:
    """stacklevel that points a warning at the first frame outside this module."""
    import sys

    level, frame = 1, sys._getframe(1)
    while frame is not None and (
        frame.f_code.co_filename == __file__  # this module, or the dataclass-generated __init__:
        or (frame.f_code.co_name == "__init__" and isinstance(frame.f_locals.get("self"), Material))
    ):
        level, frame = level + 1, frame.f_back
    return level


def _check_density(density) -> float:
    try:
        d = float(density)
    except (TypeError, ValueError):
        raise MaterialError(f"density: expected a number in g/cm³, got {density!r}") from None
    if not math.isfinite(d) or d <= 0:
        raise MaterialError(f"density: must be finite and > 0 (g/cm³), got {density!r}")
    return d


def _check_energies(energies_kev) -> np.ndarray:
    try:
        e = np.asarray(energies_kev, dtype=np.float64)
    except (TypeError, ValueError):
        raise MaterialError(f"energies: expected numbers in keV, got {energies_kev!r}") from None
    if e.size and not (np.all(np.isfinite(e)) and e.min() >= ENERGY_MIN_KEV and e.max() <= ENERGY_MAX_KEV):
        bad = e[~(np.isfinite(e) & (e >= ENERGY_MIN_KEV) & (e <= ENERGY_MAX_KEV))]
        raise MaterialError(
            f"energies: {bad.ravel()[:5].tolist()} keV outside xraylib's cross-section range; "
            f"use finite energies in [{ENERGY_MIN_KEV:g}, {ENERGY_MAX_KEV:g}] keV"
        )
    return e


@dataclass(frozen=True)
class Material:
    """An element, compound or mixture with a density.

    ``composition`` is ((Z, mass fraction), ...) sorted by Z, fractions summing to 1;
    ``density`` in g/cm³. Equality and hashing use composition and density only, never
    ``name``. Build with :meth:`element`, :meth:`from_formula`, :meth:`from_mass_fractions`,
    :meth:`mixture` (of other materials) or :meth:`named` (the library), or directly (the
    composition is validated and canonicalised the same way).
    """

    name: str = field(compare=False)
    composition: tuple[tuple[int, float], ...]
    density: float

    def __post_init__(self):
        object.__setattr__(self, "composition", _canonical(self.composition))
        object.__setattr__(self, "density", _check_density(self.density))
        if not isinstance(self.name, str):
            raise MaterialError(f"name: expected a string, got {self.name!r}")

    def __repr__(self) -> str:
        return f"Material(name={self.name!r}, composition={self.composition!r}, density={self.density!r})"

    # -- constructors ------------------------------------------------------------------------

    @classmethod
    def element(cls, symbol, density: float | None = None, name: str | None = None) -> Material:
        """A pure element; ``density`` defaults to xraylib's ElementDensity (g/cm³)."""
        z = _atomic_number(symbol)
        if density is None:
            density = xraylib.ElementDensity(z)
        return cls(name if name is not None else _symbol(z), ((z, 1.0),), density)

    @classmethod
    def from_formula(cls, formula: str, density: float, name: str | None = None) -> Material:
        """A compound from a chemical formula such as "H2O", "CaCO3" or "Ca(OH)2"."""
        if not isinstance(formula, str):
            raise MaterialError(f"formula: expected a chemical formula string such as 'H2O', got {formula!r}")
        try:
            parsed = xraylib.CompoundParser(formula)
        except ValueError as exc:
            raise MaterialError(
                f"formula: cannot parse {formula!r} ({exc}); write it like 'H2O' or 'Ca(OH)2' "
                "(symbols case-sensitive)"
            ) from None
        comp = tuple(zip(parsed["Elements"], parsed["massFractions"]))
        return cls(name if name is not None else formula, comp, density)

    @classmethod
    def from_mass_fractions(
        cls, fractions: Mapping[str, float], density: float, name: str | None = None
    ) -> Material:
        """A mixture from {symbol: mass fraction}, e.g. {"C": 0.404, "H": 0.481, "Cl": 0.019, "O": 0.096}.

        Fractions (not percent) must be finite, >= 0 and sum to 1; a sum off by more than 1e-6
        but at most 1e-2 is normalised with a warning, anything further off is an error.
        """
        if not isinstance(fractions, Mapping):
            raise MaterialError(
                f"fractions: expected a mapping {{symbol: mass fraction}}, got {type(fractions).__name__}"
            )
        zs = [_atomic_number(s) for s in fractions]
        material = cls("", tuple(zip(zs, fractions.values())), density)
        if name is None:  # compact percent string in the caller's order, e.g. "C40.4H48.1Cl1.9O9.6"
            w = dict(material.composition)
            name = "".join(f"{_symbol(z)}{100 * w[z]:.3g}" for z in dict.fromkeys(zs) if z in w)
        object.__setattr__(material, "name", name)
        return material

    @classmethod
    def mixture(cls, parts, by: str = "volume", name: str | None = None) -> Material:
        """An ideal mixture of materials: ``parts`` is a sequence of ``(Material, fraction)`` pairs,
        the fractions by ``volume`` (default) or by ``mass``, each >= 0, summing to 1 (normalised
        as in :meth:`from_mass_fractions`: silently within 1e-6, with a warning up to 1e-2).

        Ideal means the parts keep their own densities and fill the volume with no voids:

        - by volume (f_i): density ρ = Σ f_i ρ_i and part i's mass fraction m_i = f_i ρ_i / ρ;
        - by mass (m_i): 1/ρ = Σ m_i / ρ_i.

        Element j's mass fraction is then Σ m_i w_ij, so the linear attenuation of a volume mixture
        is Σ f_i μ_i and the mass attenuation of a mass mixture Σ m_i (μ/ρ)_i. The name defaults to
        e.g. ``"0.6 carbon_fibre + 0.4 epoxy (by volume)"``.
        """
        if by not in ("volume", "mass"):
            raise MaterialError(f"by: expected 'volume' or 'mass' (what the fractions measure), got {by!r}")
        try:
            pairs = [(material, fraction) for material, fraction in parts]
        except (TypeError, ValueError):
            raise MaterialError(
                "parts: expected (Material, fraction) pairs, e.g. [(carbon_fibre, 0.6), (epoxy, 0.4)]"
            ) from None
        if not pairs:
            raise MaterialError("parts: no materials given; give at least one (Material, fraction) pair")
        fractions = []
        for i, (material, fraction) in enumerate(pairs):
            if not isinstance(material, Material):
                raise MaterialError(f"parts[{i}]: expected a Material, got {material!r}")
            try:
                f = float(fraction)
            except (TypeError, ValueError):
                raise MaterialError(f"parts[{i}]: {by} fraction of {material.name} must be a number, "
                                    f"got {fraction!r}") from None
            if not math.isfinite(f) or f < 0:
                raise MaterialError(f"parts[{i}]: {by} fraction of {material.name} must be finite and >= 0, "
                                    f"got {fraction!r}")
            fractions.append(f)
        total = math.fsum(fractions)
        _check_sum(total, "parts", f"{by} fractions")
        materials = [material for material, _ in pairs]
        fractions = [f / total for f in fractions]
        if by == "volume":
            density = math.fsum(f * m.density for m, f in zip(materials, fractions))
            masses = [f * m.density / density for m, f in zip(materials, fractions)]
        else:
            density = 1.0 / math.fsum(f / m.density for m, f in zip(materials, fractions))
            masses = fractions
        elements: dict[int, list[float]] = {}
        for material, mass in zip(materials, masses):
            for z, w in material.composition:
                elements.setdefault(z, []).append(mass * w)
        if name is None:
            name = " + ".join(f"{f:g} {m.name}" for m, f in zip(materials, fractions)) + f" (by {by})"
        return cls(name, tuple((z, math.fsum(ws)) for z, ws in elements.items()), density)

    @classmethod
    def named(cls, name: str) -> Material:
        """A material of the library (:meth:`library_names`): e.g. ``"water"``, ``"pmma"``,
        ``"aluminium"``, ``"epoxy"`` (DGEBA), ``"carbon_fibre"``, ``"e_glass"``, ``"steel"``,
        ``"bone"`` (ICRU-44 cortical), ``"csi"``, ``"gd2o2s"``; case, spaces and dashes are
        ignored, and aliases such as "aluminum" or "perspex" accepted. Each composition and
        density, with its published source, is in :mod:`xrayraster.scene.material_library`."""
        key = library_key(name)
        if key is None:
            raise MaterialError(f"no material named {name!r} in the library; known: {', '.join(cls.library_names())}")
        return _library_material(key)

    @staticmethod
    def library_names() -> tuple[str, ...]:
        """The names :meth:`named` knows (without aliases)."""
        return tuple(LIBRARY)

    # -- properties --------------------------------------------------------------------------

    @property
    def mass_fractions(self) -> dict[str, float]:
        """{symbol: mass fraction}, sorted by atomic number."""
        return {_symbol(z): w for z, w in self.composition}

    # -- attenuation -------------------------------------------------------------------------

    def mass_attenuation(self, energies_kev) -> np.ndarray:
        """Mass attenuation coefficient μ/ρ in cm²/g at ``energies_kev`` (same shape, float64).

        This is the *total cross section with coherent scattering* — photoelectric absorption
        + incoherent (Compton) + coherent (Rayleigh) — i.e. NIST XCOM's "total attenuation with
        coherent scattering", which is what determines the narrow-beam transmission
        exp(-μ·L) a CT simulator models (every scattered photon is removed from the primary
        beam). Per element it is ``xraylib.CS_Total(Z, E)``, mixed by mass fraction:
        μ/ρ = Σ_i w_i (μ/ρ)_i (the same rule as ``xraylib.CS_Total_CP``).

        Energies must be finite and within [0.1, 800] keV, the range of xraylib's tables;
        otherwise :class:`MaterialError`.
        """
        e = _check_energies(energies_kev)
        return _by_element(self, "CS_Total", e.reshape(-1)).reshape(e.shape)

    def attenuation_per_mm(self, energies_kev) -> np.ndarray:
        """Linear attenuation coefficient μ in mm⁻¹ (= μ/ρ [cm²/g] · ρ [g/cm³] / 10), the unit
        the path-length physics uses (path lengths are in mm)."""
        return self.mass_attenuation(energies_kev) * (self.density / 10.0)

    def attenuation(self, energies_kev) -> np.ndarray:
        """The same as :meth:`attenuation_per_mm`: μ in mm⁻¹."""
        return self.attenuation_per_mm(energies_kev)

    def scattering_per_mm(self, energies_kev) -> tuple[np.ndarray, np.ndarray]:
        """The Compton (incoherent) and Rayleigh (coherent) parts of μ, mm⁻¹, each shaped as
        ``energies_kev``: xraylib's ``CS_Compt`` and ``CS_Rayl`` mixed by mass fraction."""
        e = _check_energies(energies_kev)
        parts = (_by_element(self, name, e.reshape(-1)) for name in ("CS_Compt", "CS_Rayl"))
        return tuple(part.reshape(e.shape) * (self.density / 10.0) for part in parts)

    def scattering_per_mm_sr(self, energies_kev, theta_rad) -> tuple[np.ndarray, np.ndarray]:
        """The Compton and Rayleigh differential attenuation dμ/dΩ, mm⁻¹ sr⁻¹, ``(energies,
        angles)`` float64: xraylib's ``DCS_Compt`` (Klein–Nishina with the incoherent scattering
        function) and ``DCS_Rayl`` (Thomson with the atomic form factor) mixed by mass fraction, at
        polar scattering angles ``theta_rad``."""
        e = _check_energies(energies_kev).reshape(-1)
        theta = np.ascontiguousarray(theta_rad, dtype=np.float64).reshape(-1)
        return tuple(_by_element(self, name, e, theta) * (self.density / 10.0) for name in ("DCS_Compt", "DCS_Rayl"))


def _by_element(material: Material, function: str, energies: np.ndarray, *angles: np.ndarray) -> np.ndarray:
    """xraylib's per-element ``function`` (a cross section, cm²/g, or a differential one, cm²/g/sr,
    given ``angles``) at every energy (and angle), mixed by the material's mass fractions."""
    zs = np.array([z for z, _ in material.composition], dtype=np.int64)
    ws = np.array([w for _, w in material.composition], dtype=np.float64)
    if _xraylib_np is not None:
        table = getattr(_xraylib_np, function)(zs, np.ascontiguousarray(energies, dtype=np.float64), *angles)
    else:  # pragma: no cover - scalar fallback
        grid = np.stack(np.meshgrid(energies, *angles, indexing="ij"), axis=-1).reshape(-1, 1 + len(angles))
        table = np.array([[_scalar(function, int(z), *map(float, point)) for point in grid] for z in zs])
        table = table.reshape(len(zs), len(energies), *(len(a) for a in angles))
    return np.tensordot(ws, table, axes=1)


@lru_cache(maxsize=65536)
def _scalar(function: str, *args) -> float:
    """xraylib's scalar ``function(*args)``, 0 where its tables do not reach (a differential cross
    section at the smallest momentum transfers; the energies are checked before)."""
    try:
        return getattr(xraylib, function)(*args)
    except ValueError:
        return 0.0


@lru_cache(maxsize=None)
def _library_material(key: str) -> Material:
    kind, value, density, _source = LIBRARY[key]
    if kind == "element":
        return Material.element(value, density, name=key)
    if kind == "formula":
        return Material.from_formula(value, density, name=key)
    if kind == "oxides":  # oxide mass fractions → element mass fractions
        elements: dict[int, float] = {}
        for oxide, share in value.items():
            parsed = xraylib.CompoundParser(oxide)
            for z, w in zip(parsed["Elements"], parsed["massFractions"]):
                elements[z] = elements.get(z, 0.0) + share * w
        return Material(key, tuple(elements.items()), density)
    return Material.from_mass_fractions(value, density, name=key)
