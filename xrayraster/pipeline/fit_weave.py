"""A woven sample's cell fitted to a real reconstruction: the first step of :func:`~xrayraster.pipeline.fit.fit`
for a scan file with a ``[weave]`` (docs/fit.md, "The weave and its tracers").

The real volume is cut into three classes, air, matrix and yarn: by the user's region labels where
given, else by μ, smoothed over a voxel against the noise, at half the matrix's peak and halfway
between the matrix's and the yarns' peaks, first the simulation's of the start file. The cell's
spacings, thickness, yarn widths and the weft's share of the stack (:data:`KEYS`; 2D plies have no
share) are those whose labels, voxelized on the grid as the scan would label them, agree with that
class map in the most voxels of the field of view. The agreement moves in steps of a voxel, so the
search is Nelder–Mead's, which needs no gradient: the spacings and the thickness first (the rest
follows them), then every key. Without labels the peaks are then taken again in the real volume
under the fitted cell's labels, and where they moved by more than :data:`PEAK_SHIFT` the volume is
cut again and every key searched once more from a fresh simplex (a start file's densities need not
be right). Each step meshes and voxelizes a cell: 0.13 s at 112² × 56 voxels here; a grid of more
than :data:`SEARCH_VOXELS` is searched in blocks (:class:`SearchGrid`), its cells meshed as finely
as the blocks need.

The sample stays where the file places it (its box centred on the axis): a cell's phase, its
distortion and its seed are not fitted; the report gives the agreement before and after.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, optimize

from ..gl.voxelize import voxelize
from ..core.volume import VolumeGeometry
from ..io.scan_file import ScanFile, mesh_resolution_for
from ..scene.scene import Scene
from .fit_figures import class_peaks

#: The cell's keys the fit moves (``[weave]``'s names), in the order of the search's first step.
KEYS = ("weft_spacing", "warp_spacing", "thickness", "weft_width_fraction", "warp_width_fraction", "weft_share")
#: The first step: the keys that set where the yarns are.
PLACING = 3
#: Each key's first step of the simplex, a share of its value.
STEP = 0.08
#: Cells meshed in each step, at most: the spacings and thickness, every key, every key again after
#: the volume is cut anew.
EVALUATIONS = (80, 200, 150)
#: σ (voxels) of the Gaussian the real volume is smoothed by before it is cut into classes.
SMOOTHING = 0.7
#: Voxels of the grid the search voxelizes its cells on, at most (about 100³: :class:`SearchGrid`).
SEARCH_VOXELS = 2**20
#: The share of the field of view a step's cell must agree in beyond the cell it starts from to be
#: taken, where the classes are cut by μ: a smaller gain is within what the real classes' blur and
#: noise leave open (on a 256³ twin told its own cell, the search traded a 9 % thinner stack and
#: ±20 % yarn widths for 0.6 % more agreement), and the cell it started from is kept. With the user's
#: labels any gain is taken.
MIN_GAIN = 0.01
#: A relative move of a class's peak under the fitted labels that has the volume cut again.
PEAK_SHIFT = 0.01
#: Voxels a class region of the fitted cell's labels is eroded by before its peak is taken: a voxel more
#: than for exact labels (:data:`~xrayraster.pipeline.fit_figures.PEAK_EROSION`), as the fitted surfaces
#: lie within about a voxel of the real ones.
FITTED_EROSION = 2
AIR, MATRIX, YARN = 0, 1, 2


@dataclass(frozen=True)
class WeaveFit:
    """The fitted cell's ``values`` (``weave.KEY`` → (start, fitted)), the share of the field of
    view whose class the cell's labels give as the real volume shows it (``agreement``: start,
    fitted), the cells meshed (``evaluations``), the wall ``seconds``, the classes' peaks in the
    real volume (``means``, class → μ cm⁻¹), the ``smoothed`` real volume, the scan file with the
    fitted cell (``scan``), and the keys a step would have moved for less than :data:`MIN_GAIN`
    (``held``: at the file's values)."""

    values: dict
    agreement: tuple[float, float]
    evaluations: int
    seconds: float
    means: dict
    smoothed: np.ndarray = dataclasses.field(repr=False)
    scan: ScanFile = dataclasses.field(repr=False)
    held: tuple[str, ...] = ()

    @property
    def unidentified(self) -> dict[str, str]:
        """The cell's keys kept at the file's values where the real classes left room to agree better, and why."""
        why = (f"no cell tried agrees with the real classes in {MIN_GAIN:.0%} more of the field of view by moving it "
               f"(the cell's agreement: {self.agreement[1]:.1%}): the file's kept")
        return dict.fromkeys(self.held, why)

    def to_dict(self) -> dict:
        return {"agreement": {"start": self.agreement[0], "fitted": self.agreement[1]},
                "evaluations": self.evaluations, "seconds": self.seconds,
                "class_peaks": {name: self.means[cls] for name, cls in (("matrix", MATRIX), ("yarn", YARN))}}


def class_of_labels(sample: Scene) -> dict[int, int]:
    """Each label of a scan's ``sample`` (its :meth:`~xrayraster.io.scan_file.ScanFile.sample_scene`)
    → its class: the matrix's, the yarns' (a label the matrix's voids take is air)."""
    out = {}
    for o in sample.objects:
        if o.name == "matrix":
            out[o.label] = MATRIX
        elif not o.name.startswith("void"):
            out.setdefault(o.label, YARN)
    return out


def fit_weave(scan: ScanFile, real: np.ndarray, use: np.ndarray, peaks: dict[int, float], gl,
              labels: np.ndarray | None = None, sample: Scene | None = None) -> WeaveFit:
    """The cell of ``scan``'s weave whose labels agree best with the classes of the ``real`` volume
    (cm⁻¹) over the voxels of ``use``: the user's region ``labels`` where given, else cut at ``peaks``
    (class → μ, cm⁻¹; module docstring), on the GL context ``gl``. ``sample``: the scan's sample
    scene where the caller has it meshed already."""
    started = time.perf_counter()
    cell = scan.weave.sample.cell
    keys = KEYS[:-1] if getattr(cell, "plies", None) else KEYS
    class_of = class_of_labels(sample if sample is not None else scan.sample_scene())
    lookup = np.zeros(max(max(class_of), int(labels.max()) if labels is not None else 0) + 1, np.uint8)
    for label, cls in class_of.items():
        lookup[label] = cls
    smoothed = ndimage.gaussian_filter(np.asarray(real, np.float64), SMOOTHING)
    grid = SearchGrid.of(scan.volume)
    coarse, inside = grid.mean(smoothed), grid.all(use)
    classes = grid.centre(lookup[labels])[inside] if labels is not None else _cut(coarse[inside], peaks)
    searched = mesh_resolution_for(scan.weave, grid.volume, scan.options.mesh_tolerance_voxels,
                                   {"points_per_section": False, "samples_per_mm": False})[0].sample
    knobs = {k: min(getattr(searched, k), getattr(scan.weave.sample, k))
             for k in ("points_per_section", "samples_per_mm")}
    count = [0]

    def with_cell(x, **meshing) -> ScanFile:
        fitted = dataclasses.replace(cell, **{k: float(v) for k, v in zip(keys, x)})
        sample = dataclasses.replace(scan.weave.sample, cell=fitted, **meshing)
        return dataclasses.replace(scan, weave=dataclasses.replace(scan.weave, sample=sample))

    def cell_labels(x) -> np.ndarray:
        return voxelize(with_cell(x, **knobs).sample_scene(), grid.volume, context=gl).data

    def disagreement(x) -> float:
        count[0] += 1
        try:
            found = cell_labels(x)
        except Exception:  # a cell the weave refuses (yarns wider than their spacing, too thin a stack)
            return 1.0
        return float(np.mean(lookup[found[inside]] != classes))

    x0 = np.array([getattr(cell, k) for k in keys], np.float64)
    first = disagreement(x0)
    x, worst = x0, first
    rejected: set[str] = set()  # keys of a step that gained too little to be taken

    gain = 0.0 if labels is not None else MIN_GAIN  # the user's labels are not a blurred cut: any gain counts

    def search(x, worst, free, evaluations):
        """Nelder–Mead's cell, where it agrees better by more than ``gain``."""
        y, fewer = _nelder_mead(disagreement, x, free, evaluations)
        if fewer < worst - gain:
            return y, fewer
        if worst > gain:  # there was room to agree better
            rejected.update(keys[i] for i in free)
        return x, worst

    for free, evaluations in zip((range(PLACING), range(len(keys))), EVALUATIONS):
        if worst == 0:  # the classes are the cell's already (labels made from it)
            break
        x, worst = search(x, worst, list(free), evaluations)
    means = dict(peaks)
    if labels is not None or worst < first:
        found = (class_peaks(smoothed, lookup[labels], use, FITTED_EROSION) if labels is not None
                 else class_peaks(coarse, lookup[cell_labels(x)], inside, FITTED_EROSION))
        means.update({cls: found[cls] for cls in (MATRIX, YARN) if cls in found})
        if labels is None and any(abs(means[c] / peaks[c] - 1) > PEAK_SHIFT for c in (MATRIX, YARN) if peaks[c]):
            classes = _cut(coarse[inside], means)
            first, worst = disagreement(x0), disagreement(x)
            x, worst = search(x, worst, list(range(len(keys))), EVALUATIONS[-1])
            if worst >= first - MIN_GAIN:
                x, worst = x0, first
                rejected.update(keys)
    values = {f"weave.{k}": (float(a), float(b)) for k, a, b in zip(keys, x0, x)}
    held = [k for k, a, b in zip(keys, x0, x) if k in rejected and a == b]
    return WeaveFit(values, (1 - first, 1 - worst), count[0], time.perf_counter() - started, means, smoothed,
                    with_cell(x), tuple(f"weave.{k}" for k in held))


@dataclass(frozen=True)
class SearchGrid:
    """The grid the search voxelizes its cells on: the scan's, its voxels merged ``factor`` to a side
    where it holds more than :data:`SEARCH_VOXELS` (the scan's grid cropped by ``crop`` voxels at the
    start of each axis so that whole blocks remain, centred as they are)."""

    volume: VolumeGeometry
    factor: int
    crop: tuple[int, int, int]

    @classmethod
    def of(cls, volume: VolumeGeometry) -> "SearchGrid":
        factor = max(1, math.ceil((math.prod(volume.shape) / SEARCH_VOXELS) ** (1 / 3)))
        if factor == 1:
            return cls(volume, 1, (0, 0, 0))
        shape = tuple(n // factor for n in volume.shape)
        left = tuple((n % factor) // 2 for n in volume.shape)
        offset = tuple(o + (c - (n % factor) / 2) * v
                       for o, c, n, v in zip(volume.offset, left, volume.shape, volume.voxel_size))
        coarse = VolumeGeometry(shape, tuple(v * factor for v in volume.voxel_size), offset)
        return cls(coarse, factor, left)

    def _blocks(self, values: np.ndarray) -> np.ndarray:
        f = self.factor
        (nz, ny, nx), (cz, cy, cx) = self.volume.shape, self.crop
        cropped = values[cz:cz + nz * f, cy:cy + ny * f, cx:cx + nx * f]
        return cropped.reshape(nz, f, ny, f, nx, f)

    def mean(self, values: np.ndarray) -> np.ndarray:
        """Each block's mean."""
        return values if self.factor == 1 else self._blocks(values).mean(axis=(1, 3, 5))

    def all(self, mask: np.ndarray) -> np.ndarray:
        """Whether all of each block is in ``mask``."""
        return mask if self.factor == 1 else self._blocks(mask).all(axis=(1, 3, 5))

    def centre(self, labels: np.ndarray) -> np.ndarray:
        """Each block's voxel at (or next after) its centre."""
        return labels if self.factor == 1 else self._blocks(labels)[:, self.factor // 2, :, self.factor // 2, :,
                                                                     self.factor // 2]


def _cut(values: np.ndarray, peaks: dict[int, float]) -> np.ndarray:
    """The class of each smoothed μ: air below half the matrix's peak, yarn above halfway from the
    matrix's peak to the yarns'."""
    return np.digitize(values, [peaks[MATRIX] / 2, (peaks[MATRIX] + peaks[YARN]) / 2]).astype(np.uint8)


def _nelder_mead(cost, x: np.ndarray, free: list[int], evaluations: int) -> tuple[np.ndarray, float]:
    """``x`` with its ``free`` entries moved by Nelder–Mead from a simplex of :data:`STEP` of each."""
    def of(y):
        z = x.copy()
        z[free] = y
        return z

    y0 = x[free]
    simplex = np.vstack([y0] + [y0 * (1 + STEP * np.eye(len(free))[i]) for i in range(len(free))])
    result = optimize.minimize(lambda y: cost(of(y)), y0, method="Nelder-Mead",
                               options={"initial_simplex": simplex, "xatol": 2e-3, "fatol": 1e-9,
                                        "maxfev": evaluations})
    return of(result.x), float(result.fun)
