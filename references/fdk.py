"""FDK / FBP in plain float64 NumPy, derived here from the documented conventions alone.

This is the reference the OpenCL reconstruction (:mod:`xrayraster.recon`) is checked against, so
it shares none of its code: it imports only NumPy, and reads the geometry value objects of
:mod:`xrayraster.core.geometry` it is given (the inputs) through their ``to_vec()`` 12-vectors. Every weight, the ramp kernel and the
backprojection are written out below from their textbook definitions and the conventions of
``docs/geometry.md`` and ``docs/reconstruction.md``:

* **Scanner frame.** Rotation axis z through the origin. A cone-beam source at gantry angle θ
  sits at ``R_z(θ)·(0, −R, ·)``; a parallel beam at θ runs along ``R_z(θ)·(0, 1, 0)``. Every
  view is read from its 12-vector ``s|r, d, u, v``; pixel ``(row, col)`` is centred at
  ``d + (col − (ncol−1)/2)·u + (row − (nrow−1)/2)·v``.
* **Cosine weight** (cone): the cosine of the angle between the ray to the pixel centre and
  the horizontal line from the source to the rotation axis, ``ŝ·(p − s)/|p − s|`` with
  ``ŝ = −(s_x, s_y, 0)/|(s_x, s_y)|`` (the same number as ``D/|p − s|`` on a detector facing the
  axis; the fan-beam change of variables measures ray angles from that line); 1 for parallel beams.
* **Redundancy weight** W per view and column, for the line through the pixel centre of the
  detector's middle row (``row = (nrow−1)/2``), projected onto the xy-plane: its fan angle γ
  (from the central ray, the source's direction to the axis, counter-clockwise about +z) and its
  signed distance t from the axis.

  - full scan, centred detector: ½ (every line measured twice);
  - full scan, laterally displaced detector (Wang 2002): with Δ the half-width of the band of
    lines seen on both sides of the axis, ``W = sin²(π/4·(1 + t/Δ))`` inside it (t measured
    positive towards the detector's long side, +t for a centred view), 1 on the long side beyond
    it. Chosen (``displaced="auto"``) when the object reaches past Δ (the smallest over the views:
    ``object_radius_mm``, else the farthest corner of the grid's voxels from the axis) and in some
    view the two ends' offsets, t_min + t_max, differ by more than 2 % of t_max − t_min; else ½
    everywhere. ``True``/``False`` force it;
  - short scan (Parker 1982, in the generalised form with the overscan angle δ = (arc − π)/2
    in place of the half fan angle, Wesarg et al. 2002): with β the source angle from the
    start of the arc,
    ``W = sin²(π/4·β/(δ − γ))`` for ``β < 2δ − 2γ``,
    ``W = sin²(π/4·(π + 2δ − β)/(δ + γ))`` for ``β > π − 2γ``, 0 past ``π + 2δ``, else 1.
    The line (β, γ) is measured again at (β + π + 2γ, −γ) and the two weights add to 1.
* **Angular weights.** Each view stands for the cell of the arc between the midpoints to its
  neighbours (sorted by angle, any input order): circular cells for a full scan; for a short scan
  the arc starts half a step before its first view and ends half a step after its last. A scan
  is full ("auto") when no gap between neighbouring views exceeds 3× the median gap.
* **Ramp filter.** Kak & Slaney's band-limited discrete kernel (eq. 3.61) with the sample
  spacing τ (the column pitch, mm) of the convolution sum folded in: ``h₀ = 1/(4τ)``,
  ``h_k = −1/(π²k²τ)`` for odd k, 0 for even k ≠ 0. A window multiplies the kernel's spectrum
  (sampled by ``numpy.fft`` on the padded length: the smallest power of two ≥ 2·cols), with ω
  the frequency as a fraction of Nyquist and c the cut-off, zero above ω = c: ram-lak 1,
  shepp-logan ``sinc(ω/2c)``, cosine ``cos(πω/2c)``, hamming ``0.54 + 0.46·cos(πω/c)``, hann
  ``0.5 + 0.5·cos(πω/c)``. Each detector row is then filtered by a direct linear convolution
  (``np.convolve``) with the windowed kernel.
* **Backprojection** (voxel driven, FDK on a general flat detector): a voxel centre x meets the
  detector plane on the line from s (cone) or along r (parallel); the hit point's (row, col)
  comes from solving ``p − d = a·u + b·v`` by least squares. The voxel adds
  ``Δθ·R/D / w² · q(row, col)`` (cone; ``w = n̂·(x − s)/D`` its depth as a fraction of the
  source-to-detector-plane distance D, R the source's distance from the axis) or ``Δθ·q``
  (parallel), q bilinearly interpolated between pixel centres with zero outside the detector.

Slow; for small cases only. Returns mm⁻¹ for line integrals in the projections.
"""

from __future__ import annotations

import math

import numpy as np

WINDOWS = ("ram-lak", "shepp-logan", "cosine", "hamming", "hann")


# --------------------------------------------------------------------------------------------
# Ramp filter
# --------------------------------------------------------------------------------------------


def fft_length(cols: int) -> int:
    """The padded length on which the window is sampled: the smallest power of two ≥ 2·cols."""
    n = 1
    while n < 2 * cols:
        n *= 2
    return n


def kak_slaney_kernel(lags: np.ndarray, pitch: float) -> np.ndarray:
    """The band-limited ramp kernel at integer ``lags``, τ of the convolution sum included (mm⁻²·mm)."""
    lags = np.asarray(lags)
    h = np.zeros(lags.shape)
    h[lags == 0] = 1.0 / (4.0 * pitch)
    odd = lags % 2 == 1
    h[odd] = -1.0 / (math.pi**2 * lags[odd].astype(np.float64) ** 2 * pitch)
    return h


def window_gain(omega: np.ndarray, window: str, cutoff: float) -> np.ndarray:
    """Window at ``omega`` = |frequency| / Nyquist, cut off (zero) above ``cutoff``."""
    x = np.asarray(omega, dtype=np.float64) / cutoff
    if window == "ram-lak":
        gain = np.ones_like(x)
    elif window == "shepp-logan":
        arg = 0.5 * math.pi * x
        gain = np.ones_like(x)
        nz = arg != 0
        gain[nz] = np.sin(arg[nz]) / arg[nz]
    elif window == "cosine":
        gain = np.cos(0.5 * math.pi * x)
    elif window == "hamming":
        gain = 0.54 + 0.46 * np.cos(math.pi * x)
    elif window == "hann":
        gain = 0.5 + 0.5 * np.cos(math.pi * x)
    else:
        raise ValueError(f"unknown window {window!r}; one of {WINDOWS}")
    return np.where(x > 1.0, 0.0, gain)


def ramp_kernel(cols: int, pitch: float, window: str = "ram-lak", cutoff: float = 1.0) -> np.ndarray:
    """The windowed spatial kernel at lags −(cols−1) … cols−1 (length 2·cols − 1), float64.

    The Kak–Slaney kernel is laid out circularly on the padded length N, transformed with
    ``numpy.fft``, multiplied by the window, and transformed back."""
    n = fft_length(cols)
    lags = np.fft.fftfreq(n, 1.0 / n).astype(int)  # 0, 1, …, N/2−1, −N/2, …, −1
    spectrum = np.fft.fft(kak_slaney_kernel(np.abs(lags), pitch))
    nu = np.abs(lags) / (n / 2)  # |frequency| / Nyquist for frequency index = lag index
    windowed = np.fft.ifft(spectrum * window_gain(nu, window, cutoff)).real
    wanted = np.arange(-(cols - 1), cols)
    return windowed[wanted % n]


def ramp_filter_rows(image: np.ndarray, pitch: float, window: str = "ram-lak", cutoff: float = 1.0) -> np.ndarray:
    """Every row of ``image`` convolved (linearly, ``np.convolve``) with the windowed ramp kernel."""
    image = np.asarray(image, dtype=np.float64)
    cols = image.shape[-1]
    kernel = ramp_kernel(cols, pitch, window, cutoff)
    flat = image.reshape(-1, cols)
    out = np.empty_like(flat)
    for k, row in enumerate(flat):
        full = np.convolve(row, kernel)  # length 3·cols − 2; output pixel j sits at j + cols − 1
        out[k] = full[cols - 1 : 2 * cols - 1]
    return out.reshape(image.shape)


# --------------------------------------------------------------------------------------------
# Per-view geometry and weights
# --------------------------------------------------------------------------------------------


class _View:
    """One view's vectors and what follows from them directly."""

    def __init__(self, row: np.ndarray, cone: bool):
        self.cone = cone
        self.s, self.d, self.u, self.v = (np.array(row[k : k + 3], dtype=np.float64) for k in (0, 3, 6, 9))
        n = np.cross(self.u, self.v)
        n /= np.linalg.norm(n)
        towards = (self.d - self.s) if cone else self.s
        self.n = n if n @ towards > 0 else -n  # unit normal pointing away from the source
        if cone:
            self.D = float(self.n @ (self.d - self.s))
            self.R = math.hypot(self.s[0], self.s[1])
            self.S = float(np.linalg.norm(self.s))  # the source's distance from the isocentre (RTK's scaling)
            self.theta = math.atan2(self.s[0], -self.s[1]) % (2 * math.pi)  # s_xy = R·(sin θ, −cos θ)
        else:
            self.D = self.R = self.S = 1.0
            self.theta = math.atan2(-self.s[0], self.s[1]) % (2 * math.pi)  # r_xy ∝ (−sin θ, cos θ)

    def pixel_centres(self, rows: np.ndarray, cols: np.ndarray, shape) -> np.ndarray:
        nrow, ncol = shape
        a = np.asarray(cols, dtype=np.float64) - (ncol - 1) / 2
        b = np.asarray(rows, dtype=np.float64) - (nrow - 1) / 2
        return self.d + a[..., None] * self.u + b[..., None] * self.v

    def cosine(self, shape) -> np.ndarray:
        """(rows, cols): cos of the angle between each pixel's ray and the source's horizontal line to the axis."""
        if not self.cone:
            return np.ones(shape)
        rr, cc = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
        ray = self.pixel_centres(rr, cc, shape) - self.s
        toward = np.array([-self.s[0], -self.s[1], 0.0]) / math.hypot(self.s[0], self.s[1])
        return (ray @ toward) / np.linalg.norm(ray, axis=-1)

    def middle_row_lines(self, shape):
        """Fan angle γ and signed axis distance t (xy-plane) of the lines through the middle row's pixels."""
        nrow, ncol = shape
        cols = np.arange(ncol)
        p = self.pixel_centres(np.full(ncol, (nrow - 1) / 2), cols, shape)[:, :2]
        direction = (p - self.s[:2]) if self.cone else np.broadcast_to(self.s[:2], p.shape)
        direction = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
        t = p[:, 0] * direction[:, 1] - p[:, 1] * direction[:, 0]
        if not self.cone:
            return np.zeros(ncol), t
        centre = -self.s[:2] / np.linalg.norm(self.s[:2])  # central ray: source towards the axis
        # γ: angle from the central ray to the line, counter-clockwise about +z.
        gamma = np.arctan2(centre[0] * direction[:, 1] - centre[1] * direction[:, 0], direction @ centre)
        return gamma, t

    def lines(self, row: float, cols, shape):
        """(t, cos γ) of the horizontal lines through pixels (``row``, ``cols``): signed distance from
        the axis and the fan angle's cosine (1 for parallel beams)."""
        p = self.pixel_centres(np.full(len(cols), float(row)), np.asarray(cols, float), shape)[:, :2]
        direction = (p - self.s[:2]) if self.cone else np.broadcast_to(self.s[:2], p.shape)
        direction = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
        t = p[:, 0] * direction[:, 1] - p[:, 1] * direction[:, 0]
        if not self.cone:
            return t, np.ones(len(t))
        return t, direction @ (-self.s[:2] / np.linalg.norm(self.s[:2]))

    def detector_coordinates(self, x: np.ndarray, shape):
        """(row, col, w) where voxel centres ``x`` (…, 3) project onto the detector: pixel indices
        (fractional) and the voxel's relative depth."""
        if self.cone:
            w = (x - self.s) @ self.n / self.D
            hit = self.s + (x - self.s) / w[..., None]
        else:
            w = np.ones(x.shape[:-1])
            r = self.s
            along = ((self.d - x) @ self.n) / (r @ self.n)
            hit = x + along[..., None] * r
        basis = np.stack([self.u, self.v], axis=1)  # (3, 2)
        ab, *_ = np.linalg.lstsq(basis, (hit - self.d).reshape(-1, 3).T, rcond=None)
        col = ab[0].reshape(x.shape[:-1]) + (shape[1] - 1) / 2
        row = ab[1].reshape(x.shape[:-1]) + (shape[0] - 1) / 2
        return row, col, w


def _is_full(theta_sorted: np.ndarray, scan: str) -> bool:
    if scan in ("full", "short"):
        return scan == "full"
    gaps = np.diff(np.concatenate([theta_sorted, [theta_sorted[0] + 2 * math.pi]]))
    return bool(gaps.max() <= 3 * np.median(gaps))


def angular_cells(theta: np.ndarray, full: bool):
    """Arc each view stands for (radians, input order), the arc's start angle and its length."""
    n = len(theta)
    order = np.argsort(theta, kind="stable")
    ts = theta[order]
    cells = np.empty(n)
    if full:
        nxt = np.roll(ts, -1) + np.where(np.arange(n) == n - 1, 2 * math.pi, 0.0)
        prv = np.roll(ts, 1) - np.where(np.arange(n) == 0, 2 * math.pi, 0.0)
        cells[order] = 0.5 * (nxt - ts) + 0.5 * (ts - prv)  # from midpoint to midpoint
        return cells, 0.0, 2 * math.pi
    # Short: the arc is the circle minus its largest gap; unwrap it to run upwards from its first view.
    after = np.diff(np.concatenate([ts, [ts[0] + 2 * math.pi]]))
    first = (int(np.argmax(after)) + 1) % n
    seq = np.roll(np.arange(n), -first)
    arc = ts[seq].copy()
    arc[arc < arc[0]] += 2 * math.pi
    mids = 0.5 * (arc[1:] + arc[:-1])
    lo = np.concatenate([[arc[0] - 0.5 * (arc[1] - arc[0])], mids])
    hi = np.concatenate([mids, [arc[-1] + 0.5 * (arc[-1] - arc[-2])]])
    cells_seq = hi - lo
    cells[order[seq]] = cells_seq
    return cells, float(lo[0]), float(hi[-1] - lo[0])


def parker_weight(beta: np.ndarray, gamma: np.ndarray, delta: float) -> np.ndarray:
    """Parker's short-scan weight (generalised: overscan δ ≥ max |γ|), β from the arc start."""
    beta, gamma = np.broadcast_arrays(np.asarray(beta, np.float64), np.asarray(gamma, np.float64))
    w = np.ones(beta.shape)
    rise = beta < 2 * delta - 2 * gamma
    w[rise] = np.sin(0.25 * math.pi * beta[rise] / (delta - gamma[rise])) ** 2
    fall = beta > math.pi - 2 * gamma
    w[fall] = np.sin(0.25 * math.pi * (math.pi + 2 * delta - beta[fall]) / (delta + gamma[fall])) ** 2
    w[beta > math.pi + 2 * delta] = 0.0
    return w


def wang_weight(t: np.ndarray, overlap: float, long_side: float) -> np.ndarray:
    """Wang's displaced-detector weight: sin² ramp over the doubly measured band |t| ≤ Δ."""
    x = long_side * np.asarray(t) / overlap
    return np.where(x >= 1, 1.0, np.where(x <= -1, 0.0, np.sin(0.25 * math.pi * (1 + np.clip(x, -1, 1))) ** 2))


def virtual_detector(views, shape, displaced: bool) -> tuple[int, int]:
    """(before, after): zero columns a displaced detector's rows get on each side before the ramp
    filter, so the short side reaches as far from the axis as the long one, whose mirrored lines
    it stands for; the backprojection reads the filtered values there. (0, 0) otherwise."""
    if not displaced:
        return 0, 0
    before = after = 0
    for view in views:
        _, t = view.middle_row_lines(shape)
        step = np.abs(np.diff(t)).min()
        before = max(before, math.ceil((abs(t[-1]) - abs(t[0])) / step))
        after = max(after, math.ceil((abs(t[0]) - abs(t[-1])) / step))
    return before, after


def redundancy_weights(views, shape, scan: str, displaced="auto", reach_mm: float = math.inf):
    """(views, cols) redundancy weights, (views,) angular cells, and whether the scan is full;
    ``reach_mm``: the object's farthest distance from the axis."""
    theta = np.array([view.theta for view in views])
    full = _is_full(np.sort(theta), scan)
    cells, start, arc = angular_cells(theta, full)
    lines = [view.middle_row_lines(shape) for view in views]
    gamma = np.array([g for g, _ in lines])
    t = np.array([tt for _, tt in lines])
    if not full:
        beta = ((theta - start) % (2 * math.pi))[:, None]
        return parker_weight(beta, gamma, 0.5 * (arc - math.pi)), cells, full
    low, high = t.min(axis=1), t.max(axis=1)
    off_centre = np.abs(high + low) / (high - low)
    both_sides = np.minimum(-low, high).min()
    if not (reach_mm > both_sides and np.any(off_centre > 0.02) if displaced == "auto" else displaced):
        return np.full(t.shape, 0.5), cells, full
    weights = np.empty(t.shape)
    for i in range(len(views)):
        long_side = -1.0 if high[i] + low[i] < -1e-9 * (high[i] - low[i]) else 1.0
        weights[i] = wang_weight(t[i], min(-low[i], high[i]), long_side)
    return weights, cells, full


# --------------------------------------------------------------------------------------------
# Backprojection and the whole reconstruction
# --------------------------------------------------------------------------------------------


def bilinear(image: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Bilinear interpolation between pixel centres (integer indices); pixels outside count as 0."""
    nrow, ncol = image.shape
    r0 = np.floor(row).astype(int)
    c0 = np.floor(col).astype(int)
    fr, fc = row - r0, col - c0
    out = np.zeros(np.shape(row))
    for dr, wr in ((0, 1 - fr), (1, fr)):
        for dc, wc in ((0, 1 - fc), (1, fc)):
            r, c = r0 + dr, c0 + dc
            ok = (r >= 0) & (r < nrow) & (c >= 0) & (c < ncol)
            out += np.where(ok, wr * wc * image[np.clip(r, 0, nrow - 1), np.clip(c, 0, ncol - 1)], 0.0)
    return out


def _voxel_centres(volume) -> np.ndarray:
    """(z, y, x, 3) voxel centres (x, y, z) in mm: (index − (n−1)/2)·size + offset per axis."""
    axes = [(np.arange(n) - (n - 1) / 2) * size + off
            for n, size, off in zip(volume.shape, volume.voxel_size, volume.offset)]
    z, y, x = np.meshgrid(*axes, indexing="ij")
    return np.stack([x, y, z], axis=-1)


def truncated_ends(p: np.ndarray, redundancy: np.ndarray, truncation) -> np.ndarray:
    """(views, rows, 2) booleans: extrapolate this row before its first / after its last column?

    ``"auto"``: the mean line integral of the 4 outermost pixels, times the edge's redundancy
    weight over the view's largest, exceeds both 0.02 and 2 % of the row's largest line integral."""
    if truncation != "auto":
        return np.full(p.shape[:2] + (2,), bool(truncation))
    relative = redundancy[:, [0, -1]] / redundancy.max(axis=1, keepdims=True)  # (views, 2)
    edges = np.stack([p[:, :, :4].mean(axis=2), p[:, :, -4:].mean(axis=2)], axis=2) * relative[:, None, :]
    limit = np.maximum(0.02, 0.02 * p.max(axis=2))[:, :, None]
    return edges > limit


def extrapolated(row: np.ndarray, pad: int, left: bool, right: bool, view, shape, r: int,
                 widths=(None, None)) -> np.ndarray:
    """``row`` (weighted; row ``r`` of ``view``) with ``pad`` columns added on each side; past a
    truncated edge, either the arc: (q/cos γ)² fitted by a parabola in the lines' axis distance t
    over the 12 outermost pixels (numpy.polyfit) and followed until it closes, when it closes
    within ``pad``; or the point mirror about the edge pixel, ``2·q(edge) − q(mirror)`` clamped at 0, times ``cos²(π/2·j/(W + 1))``
    for j ≤ W columns past the edge (Ohnesorge et al. 2000), W the side's entry of ``widths``
    (None: ``pad``). Zeros past an edge that is not truncated."""
    cols = len(row)
    k = min(12, cols)
    j = np.arange(1, pad + 1)

    def past(inner, outer, mirrored, width):
        t_in, cos_in = view.lines(r, inner, shape)
        t_out, cos_out = view.lines(r, outer, shape)
        value = np.polyval(np.polyfit(t_in, (row[inner] / cos_in) ** 2, 2), t_out) if k >= 3 else np.ones(pad)
        closed = np.nonzero(value <= 0)[0]
        if len(closed):
            arc = cos_out * np.sqrt(np.maximum(value, 0.0))
            arc[closed[0]:] = 0.0
            return arc
        width = pad if width is None else width
        roll = np.where(j <= width, np.cos(0.5 * math.pi * j / (width + 1)) ** 2, 0.0)
        return roll * np.maximum(0.0, 2 * row[inner[0]] - row[mirrored])

    before = past(np.arange(k), -j, np.minimum(j, cols - 1), widths[0]) if left else np.zeros(pad)
    after = (past(cols - 1 - np.arange(k), cols - 1 + j, np.maximum(cols - 1 - j, 0), widths[1]) if right
             else np.zeros(pad))
    return np.concatenate([before[::-1], row, after])


def reach_widths(view, shape, reach_mm: float, most: int) -> tuple[int, tuple[float, float]]:
    """The lines through the detector's centre past each edge: the last column (of 1 … ``most``)
    whose line passes within ``reach_mm`` of the axis, and the mirror widths, the reach past the
    left and right edge over the edge's column spacing of t."""
    cols, middle = shape[1], (shape[0] - 1) / 2
    tangent = []
    for outer in (-np.arange(1, most + 1), cols - 1 + np.arange(1, most + 1)):
        beyond = np.nonzero(np.abs(view.lines(middle, outer, shape)[0]) >= reach_mm)[0]
        tangent.append(int(beyond[0]) if len(beyond) else most)
    t = np.abs(view.lines(middle, [0, 1, cols - 2, cols - 1], shape)[0])
    return max(tangent), ((reach_mm - t[0]) / abs(t[0] - t[1]), (reach_mm - t[3]) / abs(t[3] - t[2]))


def filtered_projections(projections, geometry, window="ram-lak", cutoff=1.0, scan="auto", displaced="auto",
                         truncation="auto", truncation_width=0.5, reach_mm: float = math.inf, known_reach=None):
    """(views, rows, before + cols + after) cosine- and redundancy-weighted, ramp-filtered
    projections (float64) on the virtual detector of :func:`virtual_detector`, the per-view
    objects, their angular cells and ``before``. With truncated rows (:func:`truncated_ends`), each
    row is extended by ``round(truncation_width·cols)`` columns on both sides (:func:`extrapolated`)
    before filtering, and cut back after."""
    vec = geometry.to_vec()  # ConeBeam-, ParallelBeam- or VectorGeometry: (views, 12) float64 in .array
    cone = vec.beam == "cone"
    views = [_View(row, cone) for row in vec.array]
    shape = vec.detector_shape
    pitch = float(np.linalg.norm(views[0].u))
    redundancy, cells, full = redundancy_weights(views, shape, scan, displaced, reach_mm)
    before, after = virtual_detector(views, shape, full and not np.all(redundancy == 0.5))
    p = np.asarray(projections, dtype=np.float64)
    ends = truncated_ends(p, redundancy, truncation)
    widths = [(None, None)] * len(views)
    if known_reach is None:
        pad = max(1, round(truncation_width * shape[1])) if ends.any() else 0
    else:  # as far as the object reaches past an edge in any view, each side's mirror over its own reach
        reaches = [reach_widths(view, shape, known_reach, 4 * shape[1]) for view in views]
        pad = min(4 * shape[1], math.ceil(1.1 * max(r[0] for r in reaches)) + 2) if ends.any() else 0
        widths = [tuple(int(np.clip(round(w), 1, max(pad, 1))) for w in r[1]) for r in reaches]
    out = np.empty((p.shape[0], p.shape[1], before + p.shape[2] + after))
    for i, view in enumerate(views):
        weighted = p[i] * view.cosine(shape) * redundancy[i][None, :]
        rows = np.array([extrapolated(row, pad, *ends[i, k], view, shape, k, widths[i])
                         for k, row in enumerate(weighted)])
        rows = np.pad(rows, ((0, 0), (max(0, before - pad), max(0, after - pad))))
        first = max(0, pad - before)  # the column of the virtual detector's first column
        out[i] = ramp_filter_rows(rows, pitch, window, cutoff)[:, first : first + out.shape[2]]
    return out, views, cells, before


def seen_in_every_view(geometry, volume) -> np.ndarray:
    """Bool (z, y, x): the voxels whose centres project within the detector's outer pixel centres'
    half-pixel rims in every view (the field of view RTK's functional tests score in). For upright
    cone-beam views (detector columns parallel to z): along a voxel column the detector column and
    the depth stay put and the row moves linearly, so each (y, x) column is seen over one range of
    heights, found from two planes."""
    vec = geometry.to_vec()
    shape = vec.detector_shape
    x = _voxel_centres(volume)
    nz = volume.shape[0]
    seen = np.ones(volume.shape[1:], bool)
    k_low, k_high = np.full(volume.shape[1:], -np.inf), np.full(volume.shape[1:], np.inf)
    for row in vec.array:
        view = _View(row, vec.beam == "cone")
        row0, col, _ = view.detector_coordinates(x[0], shape)
        step = view.detector_coordinates(x[min(1, nz - 1)], shape)[0] - row0 if nz > 1 else np.ones_like(row0)
        seen &= (col >= -0.5) & (col <= shape[1] - 0.5)
        with np.errstate(divide="ignore"):
            ends = np.sort(np.stack([(-0.5 - row0) / step, (shape[0] - 0.5 - row0) / step]), axis=0)
        k_low, k_high = np.maximum(k_low, ends[0]), np.minimum(k_high, ends[1])
    k = np.arange(nz)[:, None, None]
    return seen & (k >= k_low) & (k <= k_high)


def fdk_reference(projections, geometry, volume, window="ram-lak", cutoff=1.0, scan="auto", displaced="auto",
                  truncation="auto", truncation_width=0.5, object_radius_mm=None) -> np.ndarray:
    """The reconstruction, float64 (z, y, x), mm⁻¹ for line integrals in ``projections``."""
    x = _voxel_centres(volume)
    reach = object_radius_mm
    if reach is None:  # the grid's farthest voxel corner: the outermost centres' x and y plus half a voxel
        reach = float(np.hypot(*(np.abs(x[0, :, :, :2]).max(axis=(0, 1)) + np.array(volume.voxel_size[:0:-1]) / 2)))
    filtered, views, cells, before = filtered_projections(projections, geometry, window, cutoff, scan, displaced,
                                                          truncation, truncation_width, reach, object_radius_mm)
    shape = np.shape(projections)[1:]
    out = np.zeros(volume.shape)
    for q, view, cell in zip(filtered, views, cells):
        row, col, w = view.detector_coordinates(x, shape)
        out += cell * view.S / view.D / w**2 * bilinear(q, row, col + before)
    return out
