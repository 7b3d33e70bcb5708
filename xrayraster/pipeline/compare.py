"""Sim-to-real metrics: how alike two volumes on one voxel grid are (docs/compare.md).

Pure functions on NumPy volumes (z, y, x) in the same unit (cm⁻¹ for xrayraster's
reconstructions), voxel for voxel: the two must already be on one grid (registered). Every
function takes an optional boolean ``mask`` of the same shape; the metrics then use the voxels
where it is True, and values outside it may be anything, NaN included (a real scan's
outside-the-field-of-view voxels).

* **Range**: :func:`value_range`, the lowest to the highest value of both volumes inside the
  mask. It is the default histogram range and, as its width, the default ``data_range`` of SSIM
  and PSNR (the ``L`` of their formulas), so a comparison is symmetric in its two volumes.
* **Histograms** (:func:`histogram`): ``bins`` equal bins over the range; values outside a given
  ``range_`` are not counted. The default is √n bins for n voxels, at most :data:`MAX_BINS`
  (the square-root rule: a small mask gets wide bins, whose counts are not all noise).
  :func:`histogram_peaks` finds the peaks.
* **Cosine similarity** (:func:`cosine_similarity`): c = a·b / (‖a‖‖b‖) of the flattened
  voxels, in float64; 1 for a scaled copy, 0 for orthogonal volumes.
* **SSIM** (:func:`ssim`): scikit-image's ``structural_similarity`` map (a uniform window of
  ``win_size``³ voxels, its defaults otherwise), averaged over the masked voxels at least
  ``(win_size - 1) // 2`` voxels from every face: the voxels where scikit-image's own mean looks,
  so without a mask it equals that mean. Voxels outside the mask but within a window still count.
* **PSNR** (:func:`psnr`): scikit-image's ``peak_signal_noise_ratio`` of the masked voxels,
  10·log10(L² / MSE) dB; infinite for identical volumes.

scikit-image, SciPy and matplotlib come with the ``compare`` extra (``pip install
"xrayraster[compare]"``) and are imported only when needed, so the package imports without them.
"""

from __future__ import annotations

import importlib
import math
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..core.errors import CompareError
from ..core.files import atomic_write
from ..core.ownership import SOFTWARE, check_replaceable_files

MAX_BINS = 256  # default histogram bins at most: over a woven sample's range (about -0.3 to 1.2 cm⁻¹) 0.006 cm⁻¹
SSIM_WINDOW = 7  # scikit-image's default window side, voxels
SMOOTH_BINS = 1.0  # σ (bins) of the Gaussian that smooths a histogram before its peaks are found
MIN_PROMINENCE = 0.1  # a peak must stand this share of the highest (smoothed) bin above its surroundings
PLOT_PEAKS = 6  # peaks per curve drawn and listed in the plot (the highest; Comparison keeps all)
INSTALL = 'pip install "xrayraster[compare]"'


@dataclass(frozen=True, eq=False)
class Histogram:
    """``counts`` (int64, one per bin) of the values in the bins between ``edges`` (float64, one more
    than the bins, in the volume's unit: cm⁻¹)."""

    counts: np.ndarray
    edges: np.ndarray

    @property
    def centres(self) -> np.ndarray:
        return (self.edges[:-1] + self.edges[1:]) / 2

    @property
    def bin_width(self) -> float:
        return float(self.edges[1] - self.edges[0])

    @property
    def density(self) -> np.ndarray:
        """Counts per voxel counted per unit of value (area 1), so volumes of different sizes overlay."""
        total = self.counts.sum()
        return self.counts / (total * self.bin_width) if total else np.zeros(self.counts.shape)


@dataclass(frozen=True)
class Comparison:
    """What :func:`compare` measured: ``names`` of the two volumes, ``mask`` (its name, or None
    for all voxels), ``voxels`` compared, the metrics (``data_range`` and the peaks in the volumes'
    unit, ``psnr_db`` in dB), the two :class:`Histogram` over one range and their peaks, each
    ranked by height."""

    names: tuple[str, str]
    mask: str | None
    voxels: int
    cosine_similarity: float
    ssim: float
    psnr_db: float
    data_range: float
    ssim_window: int
    histograms: tuple[Histogram, Histogram]
    peaks: tuple[tuple[float, ...], tuple[float, ...]]

    def to_dict(self) -> dict:
        """JSON-ready; ``psnr_db`` is None when infinite (identical volumes: JSON has no infinity)."""
        edges = self.histograms[0].edges
        return {
            "names": list(self.names), "mask": self.mask, "voxels": self.voxels,
            "cosine_similarity": self.cosine_similarity, "ssim": self.ssim, "ssim_window": self.ssim_window,
            "psnr_db": self.psnr_db if math.isfinite(self.psnr_db) else None, "data_range": self.data_range,
            "histogram": {"range": [float(edges[0]), float(edges[-1])], "bins": len(edges) - 1,
                          "counts": {n: h.counts.tolist() for n, h in zip(self.names, self.histograms)}},
            "peaks": {n: list(p) for n, p in zip(self.names, self.peaks)},
        }


def label_mask(labels: np.ndarray, classes=None, *, name: str = "the label volume") -> np.ndarray:
    """Boolean mask of a label volume (``labels.tif`` of ``xrayraster scan``: 0 background, matrix 1,
    weft 2, warp 3): the voxels of ``classes``, or every labelled (non-zero) voxel. ``name``
    is what an error calls the volume."""
    labels = np.asarray(labels)
    if classes is None:
        return labels != 0
    present = sorted(int(k) for k in np.unique(labels))
    missing = [k for k in classes if k not in present]
    if missing:
        raise CompareError(f"label classes {missing} are not in {name}, which holds {present}; choose among those")
    return np.isin(labels, list(classes))


def value_range(a, b=None, mask=None) -> tuple[float, float]:
    """(lowest, highest) value of ``a`` and ``b`` (if given) inside ``mask``."""
    a, b, mask = _checked(a, b, mask)
    return _span(_inside(a, mask), None if b is None else _inside(b, mask))


def histogram(volume, mask=None, bins: int | None = None, range_: tuple[float, float] | None = None) -> Histogram:
    """The :class:`Histogram` of ``volume`` inside ``mask`` over ``range_`` (default :func:`value_range`)."""
    volume, _, mask = _checked(volume, None, mask, names=("volume", "", "mask"))
    values = _inside(volume, mask)
    return _histogram(values, bins, range_ or _span(values))


def histogram_peaks(hist: Histogram, *, smooth_bins: float = SMOOTH_BINS,
                    min_prominence: float = MIN_PROMINENCE) -> tuple[float, ...]:
    """Peak positions (the histogram's unit: cm⁻¹), highest first.

    The counts are smoothed by a Gaussian of σ = ``smooth_bins`` bins, so that bin-to-bin noise
    makes no peaks. A peak is a local maximum of the smoothed counts whose prominence (its height
    above the higher of the two lowest points that part it from any higher bin, scipy's
    definition) is at least ``min_prominence`` of the highest smoothed bin: a shoulder or a noise
    ripple is dropped, two materials' peaks with a dip between them are kept (a woven carbon
    composite: matrix near 0.42 cm⁻¹, yarns near 0.50). Each position is refined between bins by
    the parabola through the peak's bin and its two neighbours. A peak in the first or last bin
    is not found: widen the range.
    """
    ndimage, signal = _require("scipy.ndimage", "histogram peaks"), _require("scipy.signal", "histogram peaks")
    if not (smooth_bins >= 0 and 0 <= min_prominence <= 1):
        raise CompareError(f"smooth_bins must be >= 0 (got {smooth_bins}) and min_prominence within [0, 1] "
                           f"(got {min_prominence})")
    y = ndimage.gaussian_filter1d(hist.counts.astype(np.float64), smooth_bins, mode="constant") if smooth_bins \
        else hist.counts.astype(np.float64)
    if not y.max() > 0:
        return ()
    found, _ = signal.find_peaks(y, prominence=min_prominence * y.max())
    positions = []
    for i in found[np.argsort(-y[found], kind="stable")]:
        curvature = y[i - 1] - 2 * y[i] + y[i + 1]
        shift = 0.5 * (y[i - 1] - y[i + 1]) / curvature if curvature < 0 else 0.0
        positions.append(float(hist.centres[i] + shift * hist.bin_width))
    return tuple(positions)


def cosine_similarity(a, b, mask=None) -> float:
    """c = a·b / (‖a‖‖b‖) of the voxels inside ``mask``, flattened, in float64."""
    a, b, mask = _checked(a, b, mask)
    return _cosine(_inside(a, mask), _inside(b, mask))


def ssim(a, b, mask=None, data_range: float | None = None, *, win_size: int = SSIM_WINDOW) -> float:
    """Mean structural similarity over ``mask`` (module docstring); ``data_range`` default: the
    width of :func:`value_range`."""
    a, b, mask = _checked(a, b, mask)
    return _ssim(a, b, mask, _data_range(_span(_inside(a, mask), _inside(b, mask)), data_range), win_size)


def psnr(a, b, mask=None, data_range: float | None = None) -> float:
    """Peak signal-to-noise ratio (dB) of the voxels inside ``mask``; ``data_range`` default: the
    width of :func:`value_range`."""
    a, b, mask = _checked(a, b, mask)
    av, bv = _inside(a, mask), _inside(b, mask)
    return _psnr(av, bv, _data_range(_span(av, bv), data_range))


def compare(a, b, mask=None, *, bins: int | None = None, range_: tuple[float, float] | None = None,
            data_range: float | None = None, win_size: int = SSIM_WINDOW, names: tuple[str, str] = ("a", "b"),
            mask_name: str = "mask") -> Comparison:
    """Every metric of ``a`` against ``b`` inside ``mask``, as a :class:`Comparison`.

    ``names`` (and ``mask_name``) are what error messages, :meth:`Comparison.to_dict` and the
    histogram plot call the volumes (and the mask): the command line passes the file names.
    ``range_`` defaults to :func:`value_range` and ``data_range`` to its width.
    """
    a, b, mask = _checked(a, b, mask, names=(*names, mask_name))
    av, bv = _inside(a, mask), _inside(b, mask)
    span = _span(av, bv)
    dr = _data_range(span, data_range)
    hists = (_histogram(av, bins, range_ or span), _histogram(bv, bins, range_ or span))
    return Comparison(
        names=tuple(names), mask=None if mask is None else mask_name, voxels=int(av.size),
        cosine_similarity=_cosine(av, bv), ssim=_ssim(a, b, mask, dr, win_size), psnr_db=_psnr(av, bv, dr),
        data_range=dr, ssim_window=win_size, histograms=hists, peaks=tuple(histogram_peaks(h) for h in hists),
    )


def write_histogram_png(path, histograms: Comparison | Mapping[str, Histogram], *,
                        xlabel: str = "linear attenuation μ (cm⁻¹)", title: str | None = None):
    """Plot the histograms (densities, so volumes of different sizes overlay) as a PNG at ``path``
    (atomically): each curve's highest :data:`PLOT_PEAKS` peaks as dashed lines and as numbers
    in the legend below the plot; a :class:`Comparison` also puts its metrics in the title.
    An existing file at ``path`` is replaced only if xrayraster wrote it (a link is followed).
    Returns the path written."""
    _require("matplotlib", "the histogram plot")
    [target] = check_replaceable_files([path])
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if isinstance(histograms, Comparison):
        c = histograms
        curves = list(zip(c.names, c.histograms, c.peaks))
        title = title or (f"cosine similarity {c.cosine_similarity:.6f}, SSIM {c.ssim:.4f}, PSNR {c.psnr_db:.1f} dB "
                          f"over {c.voxels} voxels" + (f" ({c.mask})" if c.mask else ""))
    else:
        curves = [(name, h, histogram_peaks(h)) for name, h in histograms.items()]
    # The object-oriented API with its own Agg canvas leaves pyplot's global backend alone.
    figure = Figure(figsize=(8, 6), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    for k, (name, h, peaks) in enumerate(curves):
        colour = f"C{k}"
        shown = peaks[:PLOT_PEAKS]
        numbers = ", ".join(f"{p:.3f}" for p in shown) + (f" (+{len(peaks) - len(shown)} lower)" if peaks[len(shown):]
                                                         else "")
        axes.plot(h.centres, h.density, color=colour, label=f"{name}\npeaks, highest first: {numbers or 'none'}")
        for p in shown:
            axes.axvline(p, color=colour, linestyle="--", linewidth=0.8)
    axes.set_xlabel(xlabel)
    axes.set_ylabel("voxel share per unit μ")
    figure.legend(loc="outside lower center", fontsize="small")  # below the axes: long file names squeeze nothing
    if title:
        axes.set_title(textwrap.fill(title, 100), fontsize="small")
    return atomic_write(target, lambda tmp: figure.savefig(tmp, format="png", dpi=100, metadata={"Software": SOFTWARE}))


def _require(module: str, what: str):
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise CompareError(f"{what} needs {exc.name or module}, which is not installed: {INSTALL}") from None


def _checked(a, b=None, mask=None, names=("a", "b", "mask")):
    """``a``, ``b`` (or None) and ``mask`` (or None) as arrays, checked: non-empty volumes of real
    numbers of one shape, a boolean mask of that shape with a True voxel, finite values inside it."""
    volumes = [(names[0], np.asarray(a))] + ([] if b is None else [(names[1], np.asarray(b))])
    for name, v in volumes:
        if not (np.issubdtype(v.dtype, np.integer) or np.issubdtype(v.dtype, np.floating)) or v.size == 0:
            raise CompareError(f"{name} is a {v.dtype} array of shape {v.shape}; give a volume of real numbers "
                               "(float32 in cm⁻¹)")
    shape = volumes[0][1].shape
    if len(volumes) == 2 and volumes[1][1].shape != shape:
        raise CompareError(f"{names[0]} has shape {shape} and {names[1]} {volumes[1][1].shape}: the volumes must be "
                           "on one voxel grid; resample or crop one onto the other's grid")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != bool:
            raise CompareError(f"{names[2]} holds {mask.dtype} values; give a boolean mask (for a label volume: "
                               "label_mask(labels, classes))")
        if mask.shape != shape:
            raise CompareError(f"{names[2]} has shape {mask.shape}, the volumes {shape}; give a mask on their grid")
        if not mask.any():
            raise CompareError(f"{names[2]} selects no voxel; give a mask with at least one True voxel")
    for name, v in volumes:
        bad = int(np.count_nonzero(~np.isfinite(_inside(v, mask))))
        if bad:
            where = f" inside {names[2]}" if mask is not None else ""
            raise CompareError(f"{name} has {bad} non-finite voxels (NaN or infinity){where}; give a mask that "
                               "excludes them, or fix the volume")
    return volumes[0][1], (volumes[1][1] if b is not None else None), mask


def _inside(volume: np.ndarray, mask) -> np.ndarray:
    return volume.ravel() if mask is None else volume[mask]


def _span(*values) -> tuple[float, float]:
    """(lowest, highest) of the arrays in ``values`` (None ones skipped)."""
    present = [v for v in values if v is not None]
    return min(float(v.min()) for v in present), max(float(v.max()) for v in present)


def _histogram(values: np.ndarray, bins: int, range_) -> Histogram:
    lo, hi = (float(x) for x in range_)
    bins = min(MAX_BINS, math.ceil(math.sqrt(values.size))) if bins is None else bins
    if not (isinstance(bins, (int, np.integer)) and bins >= 1):
        raise CompareError(f"bins must be an integer >= 1, got {bins!r}")
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise CompareError(f"the histogram range ({lo:g}, {hi:g}) must be finite and increasing"
                           + ("; all values are equal: give range_ around them" if lo == hi else ""))
    counts, edges = np.histogram(values, bins=int(bins), range=(lo, hi))
    return Histogram(counts.astype(np.int64), edges.astype(np.float64))


def _data_range(span: tuple[float, float], data_range) -> float:
    """``data_range``, checked, or the width of ``span``."""
    if data_range is None:
        lo, hi = span
        if not hi > lo:
            raise CompareError(f"both volumes are constant ({lo:g}) inside the mask, so the data range is 0; "
                               "give data_range")
        return hi - lo
    if not (isinstance(data_range, (int, float, np.number)) and math.isfinite(data_range) and data_range > 0):
        raise CompareError(f"data_range must be a number > 0 (the value span L of SSIM and PSNR), got {data_range!r}")
    return float(data_range)


def _cosine(av: np.ndarray, bv: np.ndarray) -> float:
    av, bv = av.astype(np.float64), bv.astype(np.float64)
    norms = float(np.linalg.norm(av)), float(np.linalg.norm(bv))
    if not (norms[0] > 0 and norms[1] > 0):
        raise CompareError("the cosine similarity is undefined: a volume is zero at every compared voxel; "
                           "choose a mask over the sample")
    return float(np.dot(av, bv) / (norms[0] * norms[1]))


def _ssim(a, b, mask, data_range: float, win_size: int) -> float:
    metrics = _require("skimage.metrics", "SSIM")
    if not (isinstance(win_size, (int, np.integer)) and win_size >= 3 and win_size % 2):
        raise CompareError(f"win_size must be an odd integer >= 3, got {win_size!r}")
    if min(a.shape) < win_size:
        raise CompareError(f"SSIM's {win_size}-voxel window does not fit in volumes of shape {a.shape}; "
                           f"give a smaller odd win_size (>= 3) or compare a larger region")
    pad = (win_size - 1) // 2
    where = np.zeros(a.shape, bool)
    where[tuple(slice(pad, n - pad) for n in a.shape)] = True
    if mask is not None:
        where &= mask
    if not where.any():
        raise CompareError(f"the mask has no voxel at least {pad} voxels from the volume's faces, where SSIM's "
                           f"{win_size}-voxel window fits; give a larger mask or a smaller win_size")
    _, full = metrics.structural_similarity(a.astype(np.float64), b.astype(np.float64), win_size=win_size,
                                            data_range=data_range, full=True)
    return float(full[where].mean())


def _psnr(av: np.ndarray, bv: np.ndarray, data_range: float) -> float:
    metrics = _require("skimage.metrics", "PSNR")
    with np.errstate(divide="ignore"):  # identical volumes: MSE 0, PSNR infinite
        return float(metrics.peak_signal_noise_ratio(av.astype(np.float64), bv.astype(np.float64),
                                                     data_range=data_range))
