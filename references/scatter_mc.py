"""A Monte-Carlo reference for X-ray scatter (tests only): photons tracked interaction by
interaction through one homogeneous object, with xraylib's cross sections, onto a flat detector.

It is the independent reference the scatter model of issue 41 is set and checked against, so it
shares nothing with ``xrayraster`` but the spectrum it is given. The setup (mm):

* a point source at ``(0, -source_to_origin, 0)`` emitting along +y; a flat energy-integrating
  detector (every photon absorbed, its energy counted) in the plane ``y = source_to_detector -
  source_to_origin``, ``rows × cols`` pixels of ``pixel_mm``, centred on the beam axis, rows along z;
* the object centred on the origin: a ``"cylinder"`` (axis z, ``diameter_mm``, ``height_mm``) or a
  ``"slab"`` (``thickness_mm`` along y, ``width_mm`` along x, ``height_mm`` along z), of one
  material given as a formula (xraylib's ``CompoundParser``) and a density.

Photons are drawn from the spectrum (bin energies and weights) and aimed uniformly at a window in
the plane of the object's near face that holds its silhouette, each weighted by the solid angle it
stands for; those that miss the object are primary and are not tracked. Inside, a free path
is drawn from the total attenuation coefficient (``CS_Total_CP``: photoelectric, Compton, Rayleigh);
at an interaction the photon is absorbed (photoelectric, its fluorescence ignored: under 1 keV for
water-like matter), or scattered: Compton (the polar angle from ``DCS_Compt_CP``, Klein–Nishina with
the incoherent scattering function; the energy from the Compton formula for a free electron at
rest, no Doppler broadening) or Rayleigh (``DCS_Rayl_CP``, the form factor; energy kept), the
azimuth uniform. A photon leaving the object after at least one scatter is followed to the
detector plane and its energy added to the pixel it reaches. The primary image is analytic: each
pixel centre's chord through the object and Beer–Lambert, per energy.

Both images are energy per pixel (keV) per photon the source emits into 4π, so their ratio is the
scatter-to-primary ratio (SPR) an energy-integrating detector sees. The scatter image's noise falls
as 1/√photons; :func:`simulate` returns the photon count so a caller can size its tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ELECTRON_REST_KEV = 510.99895
THETA_POINTS = 721  # polar-angle grid of the sampling tables (0.25°)
ENERGY_STEP_KEV = 0.5  # energy grid of the sampling tables


@dataclass(frozen=True)
class Setup:
    """One Monte-Carlo setup (module docstring); lengths in mm, energies in keV."""

    energies_kev: tuple[float, ...]
    weights: tuple[float, ...]  # photons per bin, any scale
    source_to_origin: float = 150.0
    source_to_detector: float = 300.0
    rows: int = 32
    cols: int = 64
    pixel_mm: float = 2.0
    shape: str = "cylinder"
    diameter_mm: float = 20.0
    thickness_mm: float = 20.0
    width_mm: float = 60.0
    height_mm: float = 60.0
    formula: str = "H2O"
    density: float = 1.0

    def __post_init__(self):
        if self.shape not in ("cylinder", "slab"):
            raise ValueError(f"shape must be 'cylinder' or 'slab', got {self.shape!r}")
        if len(self.energies_kev) != len(self.weights) or not len(self.weights):
            raise ValueError("energies_kev and weights must be of the same, non-zero length")


@dataclass(frozen=True)
class Result:
    primary: np.ndarray  # (rows, cols) keV per source photon into 4π
    scatter: np.ndarray  # (rows, cols) likewise
    photons: int  # photons aimed at the object
    scattered_hits: int  # scattered photons that reached the detector

    @property
    def spr(self) -> np.ndarray:
        return self.scatter / self.primary


def _attenuation(setup: Setup, energies) -> dict[str, np.ndarray]:
    """μ (1/mm) of each process at ``energies`` (keV)."""
    import xraylib

    rho = setup.density / 10.0  # g/cm³ · cm²/g = 1/cm; /10: 1/mm
    out = {}
    for name, cs in (("total", xraylib.CS_Total_CP), ("compton", xraylib.CS_Compt_CP), ("rayleigh", xraylib.CS_Rayl_CP)):
        out[name] = np.array([cs(setup.formula, float(e)) for e in energies]) * rho
    return out


def _angle_tables(setup: Setup, grid):
    """Inverse-CDF tables of the polar angle for Compton and Rayleigh at each grid energy."""
    import xraylib

    theta = np.linspace(0.0, math.pi, THETA_POINTS)
    tables = {}
    for name, dcs in (("compton", xraylib.DCS_Compt_CP), ("rayleigh", xraylib.DCS_Rayl_CP)):
        pdf = np.array([[_dcs(dcs, setup.formula, e, t) * math.sin(t) for t in theta] for e in grid])
        for row in pdf:  # where xraylib's tables end (the smallest momentum transfers): the nearest value
            bad = np.isnan(row)
            if bad.any():
                row[bad] = np.interp(np.flatnonzero(bad), np.flatnonzero(~bad), row[~bad])
        cdf = np.concatenate([np.zeros((len(grid), 1)), np.cumsum(0.5 * (pdf[:, 1:] + pdf[:, :-1]), axis=1)], axis=1)
        tables[name] = cdf / cdf[:, -1:]
    return theta, tables


def _dcs(dcs, formula: str, energy: float, theta: float) -> float:
    """``dcs(formula, energy, theta)``, nan where xraylib's tables do not reach."""
    try:
        return dcs(formula, float(energy), max(float(theta), 1e-6))
    except ValueError:
        return math.nan


def _sample_theta(u: np.ndarray, rows: np.ndarray, cdf: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Polar angles for uniform ``u`` from the CDF rows ``rows`` (linear between grid angles)."""
    c = cdf[rows]
    k = np.clip((c < u[:, None]).sum(axis=1), 1, len(theta) - 1)
    lo, hi = c[np.arange(len(u)), k - 1], c[np.arange(len(u)), k]
    f = np.where(hi > lo, (u - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0)
    return theta[k - 1] + f * (theta[k] - theta[k - 1])


def _exit_distance(setup: Setup, p: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance from points ``p`` inside the object along unit ``d`` to its surface."""
    h = setup.height_mm / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        tz = np.where(d[:, 2] > 0, (h - p[:, 2]) / d[:, 2], np.where(d[:, 2] < 0, (-h - p[:, 2]) / d[:, 2], np.inf))
        if setup.shape == "cylinder":
            r = setup.diameter_mm / 2
            a = d[:, 0] ** 2 + d[:, 1] ** 2
            b = p[:, 0] * d[:, 0] + p[:, 1] * d[:, 1]
            c = p[:, 0] ** 2 + p[:, 1] ** 2 - r * r
            side = np.where(a > 0, (-b + np.sqrt(np.maximum(b * b - a * c, 0.0))) / np.where(a > 0, a, 1.0), np.inf)
        else:
            half = np.array([setup.width_mm / 2, setup.thickness_mm / 2])
            side = np.min(np.where(d[:, :2] > 0, (half - p[:, :2]) / d[:, :2],
                                   np.where(d[:, :2] < 0, (-half - p[:, :2]) / d[:, :2], np.inf)), axis=1)
    return np.maximum(np.minimum(tz, side), 0.0)


def _entry(setup: Setup, source: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance from the source along unit ``d`` to where each ray enters the object (nan: it misses)."""
    h = setup.height_mm / 2
    if setup.shape == "cylinder":
        r = setup.diameter_mm / 2
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = source[0] * d[:, 0] + source[1] * d[:, 1]
        c = source[0] ** 2 + source[1] ** 2 - r * r
        disc = b * b - a * c
        t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0.0))) / a, np.nan)
    else:
        t = (-setup.thickness_mm / 2 - source[1]) / d[:, 1]
        x = source[0] + t * d[:, 0]
        t = np.where(np.abs(x) <= setup.width_mm / 2, t, np.nan)
    z = source[2] + t * d[:, 2]
    return np.where(np.abs(z) <= h, t, np.nan)


def _chords(setup: Setup, source: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Length of each ray's chord through the object (mm)."""
    t = _entry(setup, source, d)
    inside = ~np.isnan(t)
    out = np.zeros(len(d))
    if inside.any():
        p = source + (t[inside, None] + 1e-9) * d[inside]
        out[inside] = _exit_distance(setup, p, d[inside])
    return out


def _pixel_centres(setup: Setup):
    y = setup.source_to_detector - setup.source_to_origin
    zs = (np.arange(setup.rows) - (setup.rows - 1) / 2) * setup.pixel_mm
    xs = (np.arange(setup.cols) - (setup.cols - 1) / 2) * setup.pixel_mm
    z, x = np.meshgrid(zs, xs, indexing="ij")
    return np.stack([x, np.full_like(x, y), z], axis=-1)


def primary_image(setup: Setup) -> np.ndarray:
    """The analytic primary (module docstring): energy per pixel per source photon into 4π."""
    source = np.array([0.0, -setup.source_to_origin, 0.0])
    centres = _pixel_centres(setup).reshape(-1, 3)
    to = centres - source
    distance = np.linalg.norm(to, axis=1)
    d = to / distance[:, None]
    solid = setup.pixel_mm**2 * d[:, 1] / distance**2  # the pixel's solid angle (small pixels)
    chords = _chords(setup, source, d)
    e = np.asarray(setup.energies_kev, float)
    w = np.asarray(setup.weights, float) / np.sum(setup.weights)
    mu = _attenuation(setup, e)["total"]
    energy = (w * e * np.exp(-np.outer(chords, mu))).sum(axis=1)
    return (energy * solid / (4 * math.pi)).reshape(setup.rows, setup.cols)


def simulate(setup: Setup, photons: int, seed: int = 0, batch: int = 200_000) -> Result:
    """The primary (analytic) and scatter (``photons`` tracked) images of ``setup``."""
    rng = np.random.default_rng(seed)
    energies = np.asarray(setup.energies_kev, float)
    weights = np.asarray(setup.weights, float) / np.sum(setup.weights)
    grid = np.arange(1.0, energies.max() + ENERGY_STEP_KEV, ENERGY_STEP_KEV)
    mu = _attenuation(setup, grid)
    theta, tables = _angle_tables(setup, grid)
    source = np.array([0.0, -setup.source_to_origin, 0.0])
    # Rays are aimed uniformly at a window in the plane of the object's near face that holds its
    # silhouette, each photon weighted by its solid angle: dΩ/dA = cos θ / r² over 4π, times the area.
    if setup.shape == "cylinder":
        r = setup.diameter_mm / 2
        y_front = -r
        x_half = (setup.source_to_origin - r) * math.tan(math.asin(r / setup.source_to_origin)) * 1.001
    else:
        y_front, x_half = -setup.thickness_mm / 2, setup.width_mm / 2
    z_half = setup.height_mm / 2
    area = 4 * x_half * z_half
    y_detector = setup.source_to_detector - setup.source_to_origin
    scatter = np.zeros((setup.rows, setup.cols))
    hits = 0
    for start in range(0, photons, batch):
        n = min(batch, photons - start)
        e = rng.choice(energies, n, p=weights)
        aim = np.column_stack([rng.uniform(-x_half, x_half, n), np.full(n, y_front), rng.uniform(-z_half, z_half, n)])
        to = aim - source
        distance = np.linalg.norm(to, axis=1)
        d = to / distance[:, None]
        weight = area * d[:, 1] / distance**2 / (4 * math.pi)  # the share of 4π this photon stands for
        t = _entry(setup, source, d)
        keep = ~np.isnan(t)
        p, d, e, weight = source + (t[keep, None] + 1e-9) * d[keep], d[keep], e[keep], weight[keep]
        scattered = np.zeros(len(e), bool)
        while len(e):
            k = np.clip(np.rint((e - grid[0]) / ENERGY_STEP_KEV).astype(int), 0, len(grid) - 1)
            mu_total = np.interp(e, grid, mu["total"])
            free = -np.log1p(-rng.random(len(e))) / mu_total
            leave = free >= _exit_distance(setup, p, d)
            gone = leave & scattered
            out_d, out_p, out_e = d[gone], p[gone], e[gone] * weight[gone]
            forward = out_d[:, 1] > 0
            s = (y_detector - out_p[forward, 1]) / out_d[forward, 1]
            at = out_p[forward] + s[:, None] * out_d[forward]
            col = np.floor(at[:, 0] / setup.pixel_mm + setup.cols / 2).astype(int)
            row = np.floor(at[:, 2] / setup.pixel_mm + setup.rows / 2).astype(int)
            on = (col >= 0) & (col < setup.cols) & (row >= 0) & (row < setup.rows)
            np.add.at(scatter, (row[on], col[on]), out_e[forward][on])
            hits += int(on.sum())
            stay = ~leave
            p, d, e, k, free = p[stay] + free[stay, None] * d[stay], d[stay], e[stay], k[stay], free[stay]
            scattered, weight = scattered[stay], weight[stay]
            u = rng.random(len(e)) * np.interp(e, grid, mu["total"])
            compton = u < np.interp(e, grid, mu["compton"])
            rayleigh = ~compton & (u < np.interp(e, grid, mu["compton"]) + np.interp(e, grid, mu["rayleigh"]))
            alive = compton | rayleigh  # the rest: photoelectric absorption
            p, d, e, k, compton, weight = p[alive], d[alive], e[alive], k[alive], compton[alive], weight[alive]
            polar = np.where(compton, _sample_theta(rng.random(len(e)), k, tables["compton"], theta),
                             _sample_theta(rng.random(len(e)), k, tables["rayleigh"], theta))
            e = np.where(compton, e / (1 + e / ELECTRON_REST_KEV * (1 - np.cos(polar))), e)
            d = _turned(d, polar, rng.uniform(0.0, 2 * math.pi, len(e)))
            scattered = np.ones(len(e), bool)
    scatter /= photons
    return Result(primary_image(setup), scatter, photons, hits)


def _turned(d: np.ndarray, polar: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """Unit directions ``d`` turned by ``polar`` about a perpendicular at ``azimuth``."""
    helper = np.where(np.abs(d[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    s = np.sin(polar)[:, None]
    out = np.cos(polar)[:, None] * d + s * (np.cos(azimuth)[:, None] * u + np.sin(azimuth)[:, None] * v)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def single_scatter(setup: Setup, energy: float, pixels: np.ndarray) -> np.ndarray:
    """Scatter energy per source photon (into 4π) reaching each pixel (centre, pixel's solid angle)
    behind ``setup``'s slab: the slab cut in cells, each scattering the primary fluence reaching it
    into the pixel by ρ · dσ/dΩ (Compton at the Compton energy, Rayleigh at the primary's), both
    attenuated by half the slab (it is thin). Deterministic: the check of :func:`simulate` and of
    the package's scatter kernels where a photon scatters once."""
    import xraylib

    theta = np.linspace(1e-4, math.pi, 4000)

    def table(dcs):
        values = np.full(len(theta), np.nan)
        for k, t in enumerate(theta):
            try:
                values[k] = dcs("H2O", energy, float(t))
            except ValueError:  # beyond xraylib's tables at the smallest angles: the nearest value
                pass
        bad = np.isnan(values)
        values[bad] = np.interp(np.flatnonzero(bad), np.flatnonzero(~bad), values[~bad])
        return values

    compton, rayleigh = table(xraylib.DCS_Compt_CP), table(xraylib.DCS_Rayl_CP)
    mu = xraylib.CS_Total_CP("H2O", energy) * setup.density / 10
    n, layers = 241, 4
    xs = np.linspace(-setup.width_mm / 2, setup.width_mm / 2, n)
    zs = np.linspace(-setup.height_mm / 2, setup.height_mm / 2, n)
    ys = -setup.thickness_mm / 2 + (np.arange(layers) + 0.5) * setup.thickness_mm / layers
    cell = (xs[1] - xs[0]) * (zs[1] - zs[0]) * setup.thickness_mm / layers  # mm³ (edges: half weight below)
    y, x, z = np.meshgrid(ys, xs, zs, indexing="ij")
    q = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    edge = ((np.abs(q[:, 0]) == xs[-1]).astype(float) + (np.abs(q[:, 2]) == zs[-1])) * 0.5
    share = 1.0 - edge + edge * edge / 2  # trapezoid weights in x and z
    source = np.array([0.0, -setup.source_to_origin, 0.0])
    incoming = q - source
    r_in = np.linalg.norm(incoming, axis=1)
    fluence = np.exp(-mu * setup.thickness_mm / 2) / (4 * math.pi * r_in**2)  # photons per mm² at q
    out = []
    for p in pixels:
        outgoing = p - q
        r_out = np.linalg.norm(outgoing, axis=1)
        cos = np.clip(np.einsum("ij,ij->i", incoming / r_in[:, None], outgoing / r_out[:, None]), -1.0, 1.0)
        angle = np.arccos(cos)
        solid = setup.pixel_mm**2 * outgoing[:, 1] / r_out**3
        e_compton = energy / (1 + energy / ELECTRON_REST_KEV * (1 - cos))
        per_sr = setup.density / 10 * (np.interp(angle, theta, compton) * e_compton
                                       + np.interp(angle, theta, rayleigh) * energy)  # keV per mm per sr
        out.append(np.sum(fluence * per_sr * solid * share * np.exp(-mu * setup.thickness_mm / 2)) * cell)
    return np.array(out)
