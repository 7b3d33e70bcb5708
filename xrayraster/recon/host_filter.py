"""FDK stage 1 on the host, for CPU devices: pre-weight, extend and ramp-filter detector rows with
SciPy's FFT (pocketfft, threaded), writing exactly what ``shaders/fdk_filter.cl`` writes.

Why a second path: on a CPU OpenCL device (PoCL) the kernel's radix-2 FFT in local memory, each
barrier-separated stage a loop over the work-items, is slow on long rows: with the rows extended
past the detector (the truncation correction, which a dataset sample whose corners reach the edge
of the field of view gets), 180 views of 128² took 0.52-0.56 s on one core against 0.24-0.27 s
here (0.25-0.29 against 0.21-0.23 s on two; the same without the extension). GPUs keep the kernel:
there the rows are filtered where they are backprojected. Both follow the same formulas
(fdk_filter.cl and :mod:`~xrayraster.recon.truncation`): the tests run both against one reference.
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from .fdk_weights import FDKViews
from .truncation import row_extensions

CHUNK_BYTES = 64 << 20  # padded rows filtered per FFT call, at most: bounds the scratch memory


def filter_rows_host(lineint: np.ndarray, vectors: np.ndarray, toward_axis: np.ndarray, redundancy: np.ndarray,
                     ends: np.ndarray, response: np.ndarray, lead: int, out_cols: int, pad: int, cone: bool,
                     column_major: bool, widths: np.ndarray | None = None, workers: int | None = None) -> np.ndarray:
    """Filtered views of one batch, float32: ``(views, out_cols + 2, rows + 2)`` with ``column_major``,
    else ``(views, rows + 2, out_cols + 2)``, with a one-pixel ring of zeros as the backprojection reads them.

    ``lineint`` (views, rows, cols) line integrals; ``vectors`` (views, 12) and ``toward_axis``
    (views, 3): source, detector centre and pixel steps (mm) and the unit vector from the source
    towards the axis of each view (:class:`~xrayraster.recon.fdk_weights.FDKViews`); ``redundancy`` (views, cols);
    ``ends`` (views, rows) the row ends to extrapolate (:func:`~xrayraster.recon.truncation.truncated_row_ends`)
    over up to ``pad`` columns (:func:`~xrayraster.recon.truncation.row_extensions`, mirrors rolled
    off over ``widths`` (views, 2) columns, default ``pad``); ``response`` the ramp's real, even frequency response (its length n is the
    padded row's); pixel column c sits at index ``(c + lead) mod n`` of the padded row, and the output
    keeps indices ``0 … out_cols − 1``. ``workers``: FFT threads (None: every core)."""
    views, rows, cols = lineint.shape
    n = len(response)
    workers = -1 if workers is None else workers  # SciPy's None is one thread
    half = response[: n // 2 + 1].astype(np.float32)
    ring = (views, out_cols + 2, rows + 2) if column_major else (views, rows + 2, out_cols + 2)
    out = np.zeros(ring, np.float32)
    step = max(1, CHUNK_BYTES // (rows * n * 16))
    for first in range(0, views, step):
        part = slice(first, min(first + step, views))
        q = lineint[part] * pre_weights(vectors[part], toward_axis[part], redundancy[part], rows, cols, cone)
        if lead or pad:
            padded = np.zeros((len(q), rows, n), np.float32)
            padded[..., lead : lead + cols] = q
        else:  # the rows first, zeros after them: the FFT pads them itself (a tenth of the filtering saved)
            padded = q
        if pad:
            widths = np.full((views, 2), pad) if widths is None else widths
            extension = row_extensions(q, ends[part], vectors[part], toward_axis[part], cone, pad, widths[part])
            j = np.arange(1, pad + 1)
            padded[..., (lead - j) % n] = extension[:, :, 0]
            padded[..., (lead + cols - 1 + j) % n] = extension[:, :, 1]
        spectrum = scipy.fft.rfft(padded, n=n, axis=-1, workers=workers)
        spectrum *= half
        filtered = scipy.fft.irfft(spectrum, n=n, axis=-1, workers=workers)[..., :out_cols]
        if column_major:
            out[part, 1:-1, 1:-1] = filtered.transpose(0, 2, 1)
        else:
            out[part, 1:-1, 1:-1] = filtered
    return out


def kernel_extensions(lineint: np.ndarray, views: FDKViews, part: slice, ends: np.ndarray, pad: int,
                      widths: np.ndarray) -> np.ndarray:
    """(views, rows, 2, pad) float32 for ``shaders/fdk_filter.cl``: the values the rows of views
    ``part`` take past each edge (:func:`~xrayraster.recon.truncation.row_extensions`), from the
    pre-weighted rows; one float when nothing is extrapolated. The kernel filters on the device,
    but the fits are made here."""
    if not pad or not ends.any():
        return np.zeros(max(1, lineint.shape[0] * lineint.shape[1] * 2 * pad), np.float32)
    rows, cols = views.detector_shape
    cone = views.beam == "cone"
    q = lineint * pre_weights(views.vectors[part], views.toward_axis[part], views.redundancy[part], rows, cols, cone)
    return row_extensions(q, ends, views.vectors[part], views.toward_axis[part], cone, pad, widths)


def pre_weights(vectors, toward_axis, redundancy, rows: int, cols: int, cone: bool) -> np.ndarray:
    """(views, rows, cols) float32: redundancy × cosine weight ŝ·(p − s) / |p − s| (1 for parallel
    beams), p the pixel centre, ŝ ``toward_axis``; ``p − s`` expanded in the pixel offsets so that
    no (views, rows, cols, 3) array is made."""
    if not cone:
        return np.broadcast_to(redundancy[:, None, :], (len(redundancy), rows, cols)).astype(np.float32)
    cosine = cosine_weights(vectors, toward_axis, rows, cols)
    return np.multiply(cosine, redundancy[:, None, :], dtype=np.float32)


def cosine_weights(vectors, toward_axis, rows: int, cols: int) -> np.ndarray:
    """(views or 1, rows, cols) float64: the cosine weight ŝ·(p − s) / |p − s| of each pixel. It
    depends on a view only through nine dot products of its source, detector and ŝ; where every
    view has view 0's (a circular orbit: each view is view 0 turned, equal to float rounding,
    relative 1e-12), one plane serves them all. That is 1/32 of the work of a twin's batch, whose
    weights, made per view, had taken half its filtering time (0.17 of 0.34 s, 32 views of 512²)."""
    s, d, u, v = (vectors[:, 3 * k : 3 * k + 3] for k in range(4))
    a = d - s
    pairs = ((a, a), (v, v), (a, v), (u, u), (a, u), (u, v), (a, toward_axis), (v, toward_axis), (u, toward_axis))
    terms = np.stack([np.einsum("ij,ij->i", x, y) for x, y in pairs], axis=1)  # (views, 9)
    if np.all(np.abs(terms - terms[0]) <= 1e-12 * np.abs(terms).max()):
        terms = terms[:1]
    aa, vv, av, uu, au, uv, a_s, v_s, u_s = (terms[:, k, None, None] for k in range(9))  # per view, broadcast
    c = (np.arange(cols) - 0.5 * (cols - 1))[None, None, :]
    r = (np.arange(rows) - 0.5 * (rows - 1))[None, :, None]
    # The terms that vary along one axis only are summed before the (views, rows, cols) arrays are
    # made, and the cross term is left out where u ⟂ v (every circular scan): a third of the time.
    squared = (aa + r * r * vv + 2 * r * av) + (c * c * uu + 2 * c * au)
    if uv.any():
        squared += (2 * r * uv) * c
    np.sqrt(squared, out=squared)
    along = a_s + r * v_s  # ŝ·(p − s), its part along the rows
    if u_s.any():  # 0 unless the source is offset sideways (or the detector turned): no third full array
        along = along + c * u_s
    np.divide(along, squared, out=squared)
    return squared
