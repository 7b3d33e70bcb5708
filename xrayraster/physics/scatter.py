"""Scatter by kernel superposition: the photons the sample scatters onto the detector, added to
each view's primary before noise (``[physics] scatter = "kernel"``; docs/realism.md, "Scatter").

Each pencil beam through the sample scatters some of its photons out of the primary and onto the
detector around the pixel it would have reached. For the pencil through detector cell c, material
m and energy bin b, the photons scattered and still leaving the sample are taken as

    N_b · A_c · μs_mb · L_m(c) · T_b(c)

(N_b the bin's photons per mm² at 1 m, A_c the cell's photon factor, μs the Compton and Rayleigh
part of μ, L_m the path length, T_b the pencil's transmission: a scattered photon is attenuated as
the primary it left). They leave from where the pencil crosses the axis plane (the plane through
the rotation axis parallel to the detector, D from it), in the directions of the differential cross
sections, so a cell at R from that point receives per such photon

    K_mb = [dμC/dΩ(θ) · w(E'(θ)) + dμR/dΩ(θ) · w(E_b)] / μs_mb · D / R³ · area

with θ the angle between the pencil and the way to the cell, w the detector's signal per photon and
E' the Compton energy: single scatter from xraylib's cross sections, with nothing fitted.

The kernel depends on the offset from the pencil's own cell and, through its tilt, a little on the
pencil: it is computed exactly for 3 × 3 pencils spanning the detector and interpolated between
them (quadratic Lagrange weights on the cells' sources; nine convolutions). Behind a 1 mm water
slab 80 mm wide in a 30° cone, where a photon scatters once, this is the exact single-scatter
integral within 1 % (tests/physics/test_scatter.py). Photons that scatter more than once are not in
it; the Monte-Carlo reference (references/scatter_mc.py) measures what that leaves out
(docs/realism.md).

The sums over cells are convolutions, done on a coarse grid (scatter varies over centimetres:
:data:`COARSE_CELLS` cells along the longer side) by FFT, the bins gathered into
:data:`ENERGY_GROUPS` groups whose kernels are their bins' means, and interpolated back to the
pixels. The model is made once per scan (:func:`scatter_model`); a view costs milliseconds
(:func:`scatter_signal`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..core.errors import PhysicsError
from ..core.geometry import as_vector_geometry

ELECTRON_REST_KEV = 510.99895
#: Cells of the coarse grid along the detector's longer side (at most; a pixel is the smallest cell).
COARSE_CELLS = 32
#: Energy groups whose bins share a kernel (by the open beam's scattered signal, equal shares).
ENERGY_GROUPS = 4
#: Samples per coarse cell side over which a kernel is averaged (the Rayleigh peak is narrow).
KERNEL_SUBSAMPLES = 4
#: Scattering angles (0 to π) at which the cross sections are tabulated for the kernels.
ANGLES = 2048


@dataclass(frozen=True)
class DetectorLayout:
    """Where a view's detector lies for its scatter: ``shape`` (rows, cols), ``pitch_mm`` (rows, cols),
    ``distance_mm`` from the rotation axis (the origin) to the detector plane, the axis plane's
    ``magnification`` onto it (1 for a parallel beam), ``principal_px``, the (row, col) where the
    source's perpendicular meets it (the source's foot), and ``source_mm``,
    the source's distance from the axis plane (infinite for a parallel beam: no pencil is tilted)."""

    shape: tuple[int, int]
    pitch_mm: tuple[float, float]
    distance_mm: float
    magnification: float
    principal_px: tuple[float, float]
    source_mm: float


def detector_layout(geometry, view: int = 0) -> DetectorLayout:
    """The :class:`DetectorLayout` of ``geometry``'s ``view``."""
    vec = as_vector_geometry(geometry)
    rows, cols = vec.detector_shape
    s, d, u, v = np.split(vec.array[view], 4)
    normal = np.cross(u, v)
    normal /= np.linalg.norm(normal)
    distance = abs(float(normal @ d))
    if vec.beam != "cone":
        return DetectorLayout((rows, cols), (float(np.linalg.norm(v)), float(np.linalg.norm(u))), distance, 1.0,
                              ((rows - 1) / 2, (cols - 1) / 2), math.inf)
    foot = s + float(normal @ (d - s)) * normal - d
    principal = (float(foot @ v / (v @ v)) + (rows - 1) / 2, float(foot @ u / (u @ u)) + (cols - 1) / 2)
    source = abs(float(normal @ s))
    return DetectorLayout((rows, cols), (float(np.linalg.norm(v)), float(np.linalg.norm(u))), distance,
                          abs(float(normal @ (d - s))) / source, principal, source)


@dataclass(frozen=True, eq=False)
class ScatterModel:
    """What every view of a scan shares (:func:`scatter_model`): the coarse grid (``cell`` pixels a
    side, ``coarse`` cells), each material channel's photons scattered per mm of path by energy group
    and bin (``emission``: N_b · μs_mb in its bin's group, 0 elsewhere: channel, group, bin), the
    kernels' spectra (rfft2 of the padded grid: channel, pencil, group) and each cell's interpolation
    weights of the pencils (``pencil_weights``: pencil, rows, cols), the pixels in each cell
    (``pixels``), and the signal per detected scattered photon (``quantum``, for its noise)."""

    cell: int
    coarse: tuple[int, int]
    emission: np.ndarray
    kernels: np.ndarray
    pencil_weights: np.ndarray
    pixels: np.ndarray
    quantum: float


def scatter_model(materials, energies, photons, detector, layout: DetectorLayout) -> ScatterModel:
    """The kernels of ``materials`` under the bins ``energies`` (keV) and ``photons`` for ``detector``
    placed as ``layout`` says."""
    if not layout.distance_mm > 0:
        raise PhysicsError(f"scatter needs the detector at a distance > 0 from the rotation axis, got "
                           f"{layout.distance_mm!r} mm")
    energies = np.asarray(energies, dtype=np.float64)
    photons = np.asarray(photons, dtype=np.float64)
    rows, cols = layout.shape
    cell = max(1, math.ceil(max(rows, cols) / COARSE_CELLS))
    coarse = (-(-rows // cell), -(-cols // cell))
    cell_mm = (cell * layout.pitch_mm[0], cell * layout.pitch_mm[1])
    # Each cell's offset from the source's foot (mm on the detector), and the pencils the kernels are
    # made for: 3 a side spanning the cells, or the one of a parallel beam.
    offsets = [(_cell_centres(n, cell, size) - principal) * pitch
               for n, size, principal, pitch in zip(coarse, layout.shape, layout.principal_px, layout.pitch_mm)]
    span = [0.0 if math.isinf(layout.source_mm) else float(np.abs(o).max()) for o in offsets]
    nodes = [(-1.0, 0.0, 1.0) if s > 0 else (0.0,) for s in span]
    pencils = [(i * span[0], j * span[1]) for i in nodes[0] for j in nodes[1]]
    by_rows, by_cols = (_lagrange(o / s if s else o, n) for o, s, n in zip(offsets, span, nodes))
    pencil_weights = (by_rows[:, None, :, None] * by_cols[None, :, None, :]).reshape(-1, *coarse)
    geometry = [_pencil_geometry(coarse, cell_mm, layout, pencil) for pencil in pencils]  # (angle, solid angle)

    weights = detector.weights(energies)
    parts = [material.scattering_per_mm(energies) for material in materials]
    mu_scatter = np.stack([compton + rayleigh for compton, rayleigh in parts])
    source = (photons * mu_scatter * weights).sum(axis=0)  # the open beam's scattered signal per bin
    groups = _energy_groups(source)
    grid = np.linspace(0.0, math.pi, ANGLES)
    compton_energy = energies[:, None] / (1 + energies[:, None] / ELECTRON_REST_KEV * (1 - np.cos(grid)))
    compton_weights = detector.weights(compton_energy.ravel()).reshape(compton_energy.shape)
    kernels = []
    for material, mu_s in zip(materials, mu_scatter):
        compton, rayleigh = material.scattering_per_mm_sr(energies, grid)
        per_photon = (compton * compton_weights + rayleigh * weights[:, None]) / np.maximum(mu_s, 1e-300)[:, None]
        share = photons * mu_s + 1e-300
        by_group = [np.average(per_photon[groups == g], axis=0, weights=share[groups == g])
                    for g in range(groups.max() + 1)]
        sampled = [[(np.interp(angle, grid, row) * solid).mean(axis=(-1, -2)) for row in by_group]
                   for angle, solid in geometry]
        kernels.append(scipy.fft.rfft2(np.array(sampled)))
    open_beam = source.sum()
    quantum = 1.0 if detector.counting or not open_beam else float((source * energies).sum() / open_beam)
    pixels = _block_sum(np.ones((1, rows, cols)), cell)[0]
    emission = np.zeros((len(materials), groups.max() + 1, len(energies)))
    emission[:, groups, np.arange(len(energies))] = photons * mu_scatter
    return ScatterModel(cell, coarse, emission, np.stack(kernels), pencil_weights, pixels, quantum)


def _pencil_geometry(coarse, cell_mm, layout: DetectorLayout, pencil_mm) -> tuple[np.ndarray, np.ndarray]:
    """For the pencil that meets the detector ``pencil_mm`` (rows, cols) from the source's foot: the
    scattering angle (rad) into each sub-sample of the padded grid's offsets from that point, and the
    solid angle of a cell there (sr), both ``(rows, cols, sub, sub)``."""
    along = _kernel_offsets(coarse, cell_mm)
    distance = layout.distance_mm
    if math.isinf(layout.source_mm):  # parallel: the pencil runs along the normal
        direction, crossing = np.array([0.0, 0.0, 1.0]), np.zeros(2)
    else:  # from the source, (0, 0, −source) from the foot's plane, through the axis plane
        crossing = np.asarray(pencil_mm) / layout.magnification
        direction = np.array([crossing[0], crossing[1], layout.source_mm])
        direction /= np.linalg.norm(direction)
    # From where the pencil crosses the axis plane to the cell.
    way = [pencil_mm[0] + along[0] - crossing[0], pencil_mm[1] + along[1] - crossing[1]]
    reach = np.sqrt(way[0] ** 2 + way[1] ** 2 + distance**2)
    cosine = (direction[0] * way[0] + direction[1] * way[1] + direction[2] * distance) / reach
    return np.arccos(np.clip(cosine, -1.0, 1.0)), distance / reach**3 * cell_mm[0] * cell_mm[1]


def _lagrange(at: np.ndarray, nodes: tuple[float, ...]) -> np.ndarray:
    """Lagrange interpolation weights ``(nodes, points)`` of the points ``at`` between ``nodes``."""
    return np.stack([np.prod([(at - other) / (node - other) for other in nodes if other != node], axis=0)
                     * np.ones_like(at) for node in nodes])


def _padded(coarse: tuple[int, int]) -> tuple[int, int]:
    """The FFT grid of a coarse grid: twice its size, so no cell's scatter wraps onto another."""
    return 2 * coarse[0], 2 * coarse[1]


def _kernel_offsets(coarse, cell_mm) -> tuple[np.ndarray, np.ndarray]:
    """The padded grid's sub-samples' offsets along the rows and the columns (mm), each
    ``(rows, cols, sub, sub)``, wrapped as an FFT's."""
    axes = []
    for size, step in zip(_padded(coarse), cell_mm):
        offsets = np.fft.fftfreq(size, 1.0 / size)  # 0, 1, …, −1 cells
        sub = (np.arange(KERNEL_SUBSAMPLES) + 0.5) / KERNEL_SUBSAMPLES - 0.5
        axes.append((offsets[:, None] + sub[None, :]) * step)
    y, x = axes
    shape = (len(y), len(x), KERNEL_SUBSAMPLES, KERNEL_SUBSAMPLES)
    return np.broadcast_to(y[:, None, :, None], shape), np.broadcast_to(x[None, :, None, :], shape)


def _cell_centres(count: int, cell: int, size: int) -> np.ndarray:
    """Pixel coordinates of the coarse cells' centres along an axis of ``size`` pixels."""
    starts = np.arange(count) * cell
    return starts + (np.minimum(cell, size - starts) - 1) / 2


def _energy_groups(source: np.ndarray) -> np.ndarray:
    """A group index per bin: :data:`ENERGY_GROUPS` runs of consecutive bins with equal shares of
    ``source`` (the open beam's scattered signal per bin)."""
    total = source.sum()
    if total <= 0:
        return np.zeros(len(source), dtype=np.int64)
    edges = np.cumsum(source) / total
    groups = np.minimum((edges * ENERGY_GROUPS - 1e-9).astype(np.int64), ENERGY_GROUPS - 1)
    return np.unique(groups, return_inverse=True)[1]


def scatter_signal(model: ScatterModel, lengths, mu, factor) -> np.ndarray:
    """The mean scatter signal of one view, ``(rows, cols)`` float64, in the detector's signal units:
    ``lengths`` (channels, rows, cols) mm, ``mu`` (channels, bins) mm⁻¹ of the model's bins,
    ``factor`` the pixels' photon factor (module docstring)."""
    rows, cols = lengths.shape[1:]
    factor = np.broadcast_to(np.asarray(factor, dtype=np.float64), (rows, cols))
    area = _block_sum(factor[None], model.cell)[0]  # mm² at 1 m each coarse cell collects
    mean_lengths = _block_sum(np.asarray(lengths), model.cell).astype(np.float64) / model.pixels
    transmission = np.exp(-np.tensordot(mu.T, mean_lengths, axes=1))  # (bins, cells)
    padded = _padded(model.coarse)
    spectrum = np.zeros(model.kernels.shape[-2:], dtype=np.complex128)
    for m in range(len(lengths)):
        if not mean_lengths[m].any():
            continue
        sources = np.tensordot(model.emission[m], transmission, axes=1) * (area * mean_lengths[m])  # (groups, cells)
        by_pencil = sources[None] * model.pencil_weights[:, None]  # (pencils, groups, cells)
        spectrum += (scipy.fft.rfft2(by_pencil, s=padded) * model.kernels[m]).sum(axis=(0, 1))
    coarse = scipy.fft.irfft2(spectrum, s=padded)[: model.coarse[0], : model.coarse[1]]
    return _upsampled(coarse, model.cell, (rows, cols)) / model.cell**2


def _block_sum(images: np.ndarray, cell: int) -> np.ndarray:
    """Sums over ``cell`` × ``cell`` blocks of ``(channels, rows, cols)`` (the last blocks may be
    smaller). Rows, then columns, each a contiguous reshape: 7× numpy's ``reduceat`` at 512²."""
    channels, rows, cols = images.shape
    short = (-rows % cell, -cols % cell)
    if any(short):
        images = np.pad(images, ((0, 0), (0, short[0]), (0, short[1])))
    rows, cols = rows + short[0], cols + short[1]
    by_rows = images.reshape(channels, rows // cell, cell, cols).sum(axis=2)
    return by_rows.reshape(channels, rows // cell, cols // cell, cell).sum(axis=3)


def _upsampled(coarse: np.ndarray, cell: int, shape: tuple[int, int]) -> np.ndarray:
    """``coarse`` (one value per cell) linearly interpolated between cell centres onto every pixel
    (held beyond the outer centres)."""
    rows, cols = (_interpolation(_cell_centres(n, cell, size), size) for n, size in zip(coarse.shape, shape))
    return rows @ coarse @ cols.T


def _interpolation(centres: np.ndarray, size: int) -> np.ndarray:
    """The (size × centres) matrix that interpolates values at ``centres`` linearly onto pixels 0 … size − 1."""
    at = np.arange(size, dtype=np.float64)
    return np.stack([np.interp(at, centres, row) for row in np.eye(len(centres))], axis=1)
