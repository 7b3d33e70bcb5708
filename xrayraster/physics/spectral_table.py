"""The spectral sum as a table: a scan's per-pixel sums over energy bins replaced by interpolation.

A pixel's detected moments are sums over the energy bins b of the spectrum,

    m_k(L) = Σ_b q_kb · exp(−Σ_c μ_cb · L_c),   q_0 = E·η·N, q_1 = E²·η·N, q_2 = η·N

(the integrating detector's mean and variance, and the photons it detects), with L_c the path
lengths (mm) through the material channels c. Per pixel that is channels × bins multiply-adds and
one exp per bin: ~60–80 bins at 40 kV. But when some materials' attenuation curves are
combinations of others' (carbon yarns of two densities are one curve scaled), m_k depends on L
only through r ≤ channels "equivalent lengths" a = B·L of r basis materials (r: the rank of μ,
2 for carbon yarns in a resin, however many yarn families), and smoothly: log m_k is nearly linear
in a, bent only by beam hardening. So the table holds log m_k on a regular grid over a, and a
pixel costs one r-linear interpolation (2^r table rows) and an exp.

The grid spans every a that path lengths in [0, longest chord] can give. Its spacing is refined
until the interpolation error, measured at every cell centre (where linear interpolation errs
most) against the exact sums, is within the tolerance; :attr:`SpectralTable.error` is that
measured worst relative error, which a scan records. A table that would need more than
:data:`MAX_POINTS` grid points is refused (:func:`spectral_table` returns None) and the exact sum runs.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from ..core.errors import PhysicsError

# Relative, on each moment: 1e-5 in the line integrals, a tenth of the photon noise of a pixel
# that detects 10⁸ photons (noise 1/√counts); noise-free radiographs keep the exact sum.
TOLERANCE = 1e-5
MAX_POINTS = 2**21  # grid points at most (3 moments × 8 bytes each: 48 MiB)
RANK_TOLERANCE = 1e-9  # singular values below this share of the largest do not count (exact reduction)
_MOMENTS = 3
_EDGE = 1e-9  # grid steps: rounding on the longest chord still counts as inside
_CHUNK = 4096  # grid points per block while building: (3 × bins × 4096) float64 intermediates


@dataclass(frozen=True)
class SpectralTable:
    """log m_k on a grid over a = ``basis`` @ L (module docstring); build with :func:`spectral_table`."""

    basis: np.ndarray  # (r, channels): equivalent lengths a = basis @ L of the basis materials, mm
    lower: np.ndarray  # (r,): the grid's first point, mm
    step: np.ndarray  # (r,): grid spacing, mm
    log_moments: np.ndarray  # (n_0 · … · n_{r-1}, 3) float64: log m_k at the grid points, C order
    shape: tuple  # (n_0, …, n_{r-1})
    error: float  # the worst relative error of the interpolated moments, measured at every cell centre

    def moments(self, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(moments (pixels, 3) float64, inside (pixels,) bool) for ``lengths`` (channels, pixels) mm.
        Pixels outside the grid (``inside`` False) get a clamped value: compute them exactly."""
        log_m, inside = self._interpolate(self.basis @ lengths)
        return np.exp(log_m, out=log_m), inside

    def _interpolate(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(log m (pixels, 3), inside) at equivalent lengths ``a`` (r, pixels)."""
        inside = np.ones(a.shape[1], bool)
        base = np.zeros(a.shape[1], np.intp)
        fractions = []
        stride = 1
        for k in reversed(range(len(self.shape))):  # C order: the last axis varies fastest
            u = (a[k] - self.lower[k]) / self.step[k]
            inside &= (u >= -_EDGE) & (u <= self.shape[k] - 1 + _EDGE)
            np.clip(u, 0, self.shape[k] - 1, out=u)
            cell = np.minimum(u.astype(np.intp), self.shape[k] - 2)
            u -= cell
            base += stride * cell
            fractions.append((stride, u))
            stride *= self.shape[k]
        out = np.zeros((a.shape[1], _MOMENTS))
        for corner in itertools.product((0, 1), repeat=len(fractions)):
            weight = np.ones(a.shape[1])
            offset = 0
            for (stride, frac), upper in zip(fractions, corner):
                weight *= frac if upper else 1 - frac
                offset += stride * upper
            out += weight[:, None] * np.take(self.log_moments, base + offset, axis=0)  # take: 4× fancy indexing
        return out, inside


def exact_moments(lengths: np.ndarray, mu: np.ndarray, q: np.ndarray) -> np.ndarray:
    """m_k (3, pixels) float64 by the full sum over bins: ``lengths`` (channels, pixels) mm,
    ``mu`` (channels, bins) mm⁻¹, ``q`` (3, bins)."""
    return q @ np.exp(-(mu.T @ lengths))


def moment_weights(photons, efficiency, energies_kev) -> np.ndarray:
    """q (3, bins): E·η·N, E²·η·N and η·N (module docstring)."""
    detected = np.asarray(photons, np.float64) * np.asarray(efficiency, np.float64)
    energies = np.asarray(energies_kev, np.float64)
    return np.stack([energies * detected, energies**2 * detected, detected])


def spectral_table(mu, q, longest_mm: float, tolerance: float = TOLERANCE) -> SpectralTable | None:
    """The table for attenuation ``mu`` (channels, bins) mm⁻¹ and moment weights ``q`` (3, bins)
    (:func:`moment_weights`), for path lengths up to ``longest_mm`` per channel; None if it would
    need more than :data:`MAX_POINTS` points to reach ``tolerance``."""
    mu = np.asarray(mu, np.float64)
    q = np.asarray(q, np.float64)
    if not (np.isfinite(longest_mm) and longest_mm > 0):
        raise PhysicsError(f"longest_mm must be a positive length (mm), got {longest_mm!r}")
    if np.any(q < 0) or not np.all(np.isfinite(q)):
        raise PhysicsError("spectral_table: the moment weights must be finite and >= 0")
    used = q.max(axis=0) > 0  # empty bins add nothing
    mu, q = mu[:, used], q[:, used]
    chosen = _basis_materials(mu)
    mu_basis = mu[chosen]  # (r, bins)
    basis = np.linalg.lstsq(mu_basis.T, mu.T, rcond=None)[0]  # (r, channels): μ_c = Σ_k basis_kc μ_(basis k)
    basis[:, chosen] = np.eye(len(chosen))
    lower = np.minimum(basis, 0).sum(axis=1) * longest_mm
    upper = np.maximum(basis, 0).sum(axis=1) * longest_mm
    span = np.where(upper > lower, upper - lower, 1.0)
    rank = len(basis)
    points = 17
    while points**rank <= MAX_POINTS:
        step = span / (points - 1)
        shape = (points,) * rank
        table = SpectralTable(basis, lower, step, _log_moments(_grid(lower, step, shape), mu_basis, q), shape, 0.0)
        centres = _grid(lower + step / 2, step, tuple(n - 1 for n in shape))
        error = 0.0
        for start in range(0, centres.shape[1], _CHUNK):
            chunk = centres[:, start : start + _CHUNK]
            gap = table._interpolate(chunk)[0] - _log_moments(chunk, mu_basis, q)
            error = max(error, float(np.expm1(np.abs(gap)).max()))
        if error <= tolerance:
            return dataclasses.replace(table, error=error)
        # Linear interpolation errs as step²: aim at half the tolerance, then check again.
        points = int(np.ceil(1 + (points - 1) * np.sqrt(2 * error / tolerance)))
    return None


def _basis_materials(mu: np.ndarray) -> list[int]:
    """The first channels that add to the rank of ``mu``: the basis materials. The others are
    their combinations, with weights ≥ 0 when they are scaled copies of them (yarns of one fibre
    at other densities), so every grid point is a real path."""
    scale = np.abs(mu).max() or 1.0
    chosen = []
    for c in range(len(mu)):
        if np.linalg.matrix_rank(mu[chosen + [c]].T, tol=RANK_TOLERANCE * scale) > len(chosen):
            chosen.append(c)
    return chosen or [0]


def _grid(lower: np.ndarray, step: np.ndarray, shape: tuple) -> np.ndarray:
    """(r, points) coordinates of a regular grid, C order."""
    axes = [lower[k] + step[k] * np.arange(n) for k, n in enumerate(shape)]
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])


def _log_moments(a: np.ndarray, mu_basis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """log m_k (points, 3) at equivalent lengths ``a`` (r, points), as a log-sum-exp: finite even
    where a grid corner has negative lengths (exponents > 0) or starves every bin."""
    out = np.empty((a.shape[1], _MOMENTS))
    with np.errstate(divide="ignore"):
        log_q = np.log(q)  # −inf for a bin a moment does not weigh
    for start in range(0, a.shape[1], _CHUNK):  # bounded (bins × _CHUNK) intermediates
        x = log_q[:, :, None] - (mu_basis.T @ a[:, start : start + _CHUNK])[None]  # (3, bins, points)
        top = x.max(axis=1)
        out[start : start + x.shape[2]] = (top + np.log(np.exp(x - top[:, None]).sum(axis=1))).T
    return out
