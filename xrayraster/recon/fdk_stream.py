"""FDK with the views fed in batches (:class:`FDKStream`): weights, ramp filter and
backprojection on an OpenCL device, following the memory plan (:mod:`~xrayraster.recon.fdk_plan`)
that decides where volume and views live.

The algorithm and its weights are in :mod:`xrayraster.recon.fdk_weights`, the filter in
:mod:`xrayraster.recon.ramp_filter`, the kernels in ``shaders/fdk_filter.cl`` and
``shaders/fdk_backproject.cl``. ``references/fdk.py`` is the same algorithm in float64
NumPy, against which the kernels are tested.

Memory: when the volume fits the device next to one batch of views, it stays there; views are
filtered as they arrive and backprojected once a batch of them is waiting (``batch_views``, in
whatever sizes they came), so views can be streamed from a simulation without ever holding them
all, and the volume is read and written once a batch. Otherwise the volume is reconstructed in
z-slabs that fit the device next to one batch of filtered views; filtered projections stay on the device when they
all fit, else they wait in host memory and are uploaded again for each slab. Both needs are
estimated before any work starts, and a request that cannot fit is refused with the sizes.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..core.choices import RECONSTRUCTION_INPUTS, check_choice
from ..core.errors import ReconstructionError
from ..core.geometry import as_vector_geometry
from ..core.memory import available_memory
from ..core.volume import VolumeGeometry
from .fdk_plan import MAX_BATCH_VIEWS, plan_memory
from .fdk_weights import FDKViews, fdk_views
from .host_filter import filter_rows_host, kernel_extensions
from .opencl import CLContext
from .ramp_filter import padded_length, ramp_response
from .truncation import DEFAULT_WIDTH, LEFT, RIGHT, check_truncation, padding, truncated_row_ends
from .volume import MM_TO_CM, Volume

log = logging.getLogger(__name__)

ZCHUNK = 16  # voxels along z per work-item of the scalar backprojection (shaders/fdk_backproject.cl)
WINDOW_VOXELS = 64  # voxels along z per work-item of backproject_windowed, at most (measured best on 2 cores)
TILE = (16, 16, 1)  # work-group: a 16×16 column of voxels reads a compact patch of every view
# Kernel choices, normally automatic; the tests set them to check every path on one device.
LAYOUT = "auto"  # filtered views by "rows" (GPUs), by "columns" (CPUs), or "auto" by device type
WINDOW_LANES = "auto"  # backproject_windowed's vector width where it applies (x86 CPUs, upright detectors):
# "auto" 16 with AVX-512, else 8 with AVX2; 16 or 8 (if the device has it); 0: the scalar kernel
COLUMNS = True  # with WINDOW_LANES "auto": backproject_columns first, where it applies and the device builds it
# (AVX-512); False: backproject_windowed as above
COLUMN_TILE = 16  # backproject_columns: voxel columns along x per work-item (fixed: the kernel's vector width)
COLUMN_VIEWS = 4  # backproject_columns: views per pass over a work-item's columns (L1; measured best on 2 cores)
COLUMN_BLOCK = 32  # backproject_columns: views per pass of a whole work-group (L2), a barrier between passes
COLUMN_GROUP = (1, 16, 1)  # backproject_columns' work-group: small (PoCL keeps its private arrays on the stack)
UPRIGHT = "auto"  # the upright-detector kernels where the detector's columns are parallel to z (every circular
# orbit; "auto"), or the general kernel everywhere (False)
HOST_FILTER = "auto"  # rows filtered on the host (host_filter.py): "auto" on CPU devices, True, False
DEVICE_SHARE = 0.8  # of the device's global memory we plan to use
WINDOW_PAD = 32 * 4  # bytes after each batch of filtered views: backproject_windowed reads past the last column


def check_shape(projections, geometry) -> None:
    """Refuse a stack that is not (views, rows, cols) of ``geometry``."""
    vec = as_vector_geometry(geometry)
    shape = np.shape(projections)
    expected = (vec.num_views, *vec.detector_shape)
    if len(shape) != 3 or shape[0] == 0:
        raise ReconstructionError(
            f"projections must be a (views, rows, cols) stack with at least one view, got shape {shape}")
    if shape != expected:
        raise ReconstructionError(
            f"projections have shape {shape} but the geometry has {expected[0]} views of "
            f"{expected[1]}×{expected[2]} pixels {expected}: pass the geometry the projections were taken with "
            "(or select its views: geometry[indices])")


def line_integrals(projections, geometry, input: str = "lineint") -> np.ndarray:
    """The projections as float32 line integrals, checked against ``geometry``."""
    check_choice(input, RECONSTRUCTION_INPUTS, "input", ReconstructionError)
    p = np.asarray(projections)
    check_shape(p, geometry)
    if not np.issubdtype(p.dtype, np.number) or np.iscomplexobj(p):
        raise ReconstructionError(f"projections must be real numbers, got dtype {p.dtype}")
    p = p.astype(np.float32, copy=False)
    bad = ~np.isfinite(p)
    if input == "transmission":
        bad |= p <= 0
    if bad.any():
        v, r, c = np.argwhere(bad)[0]
        what = "not finite or ≤ 0" if input == "transmission" else "not finite"
        fix = ("clamp starved pixels to a small positive transmission before −log, as xrayraster's radiographs do"
               if input == "transmission" else "find where the NaN/inf came from (a −log of values ≤ 0?)")
        raise ReconstructionError(
            f"projections: {int(bad.sum())} value(s) are {what} (first at view {v}, row {r}, col {c}: "
            f"{p[v, r, c]!r}); {fix}")
    if input == "transmission":
        p = -np.log(p)
    return np.ascontiguousarray(p, dtype=np.float32)


class FDKStream:
    """FDK with the views fed in batches, as a simulation renders them: each batch is filtered
    and backprojected when it arrives, so only the volume and one batch of views are in memory.

        with FDKStream(geometry, grid) as stream:
            for first in range(0, geometry.num_views, stream.batch_views):
                stream.add(first, render(first, first + stream.batch_views))  # line integrals
            volume = stream.result()  # a Volume in cm⁻¹, once every view was added

    Options as :func:`fdk`. Views may come in any order and batch size (backprojection is a sum);
    :meth:`result` refuses to run until each view came exactly once.

    On a CPU device the rows are filtered on the host (:mod:`~xrayraster.recon.host_filter`:
    SciPy's FFT, ``threads`` of them, None for every core), on other devices by the kernel.

    Memory plan (checked before any work, a request that cannot fit is refused with the sizes):
    when the whole volume fits the device next to one batch, it stays there and each batch is
    backprojected on arrival; on CPU devices it lives in the very array returned (no copy).
    Otherwise the filtered views wait (on the device when they all fit, else in host memory)
    and :meth:`result` backprojects them slab by slab.
    """

    def __init__(self, geometry, volume: VolumeGeometry, *, filter: str = "ram-lak", cutoff: float = 1.0,
                 scan: str = "auto", displaced="auto", object_radius_mm: float | None = None, truncation="auto",
                 truncation_width: float = DEFAULT_WIDTH, context: CLContext | None = None, device: str | None = None,
                 memory_limit: int | None = None, batch_views: int = MAX_BATCH_VIEWS, threads: int | None = None):
        if not isinstance(volume, VolumeGeometry):
            raise ReconstructionError(
                f"volume must be a VolumeGeometry (the grid to reconstruct), got {type(volume).__name__}")
        self.geometry, self.volume = geometry, volume
        self.vector_geometry = vec = as_vector_geometry(geometry)
        self.views = fdk_views(vec, volume, scan, displaced, object_radius_mm)
        check_truncation(truncation, truncation_width)
        self._window = (filter, cutoff)
        self._truncation = truncation
        self._pad, self._widths = padding(self.views, truncation, truncation_width, object_radius_mm)
        self._provenance = {"method": "FDK" if vec.beam == "cone" else "FBP", "geometry": geometry.to_dict(),
                            "filter": filter, "cutoff": cutoff, "scan": self.views.scan,
                            "displaced": self.views.displaced, "truncation": truncation,
                            "truncation_width": truncation_width}
        red = self.views.redundancy
        self._edge_weights = red[:, [0, -1]] / np.maximum(red.max(axis=1, keepdims=True), 1e-12)
        self._row_ends = [0, 0]  # extrapolated, seen
        self.ctx = context or CLContext(device)
        self._owns_context = context is None
        info = self.ctx.info
        device_bytes = int(info.global_mem * DEVICE_SHARE) if memory_limit is None else int(memory_limit)
        self.plan = plan_memory(self.views, volume, padded_length(self.views.filtered_cols + 2 * self._pad),
                                device_bytes, info.max_alloc, info.local_mem, available_memory(), batch_views)
        rows, cols = self.views.detector_shape
        log.info("FDK on %s: %d views of %d×%d, volume %s, %d-view batches, %d-plane slabs, %s", info.name,
                 len(self.views.scale), rows, cols, volume.shape, self.plan.batch, self.plan.slab,
                 "backprojected as they arrive" if self.plan.streamed
                 else f"filtered views kept {'on the device' if self.plan.resident else 'in host memory'}")
        self._layout = {"COLUMN_MAJOR": 1} if _column_major(info, LAYOUT) else {}
        self._host_filter = HOST_FILTER is True or (HOST_FILTER == "auto" and "CPU" in info.kind)
        self._threads = threads
        self._filter_setup()
        self._backproject_setup()
        self._added = np.zeros(len(self.views.scale), bool)
        self._kept = []  # (views, filtered batch on the device or in host memory) until result(), unless streamed
        self._group = None  # (device buffer, its views so far): the batch being filtered, until it is full
        self._out = np.zeros(volume.shape, np.float32)  # zeros: the slabs on a CPU device accumulate into it
        self._slabs = [self._slab_buffer(z0) for z0 in self._slab_starts()] if self.plan.streamed else None

    @property
    def batch_views(self) -> int:
        """Views per backprojection launch. Views may be added in batches of any size: each is filtered
        as it comes, and backprojected once this many are waiting (or by :meth:`result`), so a caller
        feeding small batches (a scan checks each for starved pixels) passes over the volume as
        seldom as one feeding large ones."""
        return self.plan.batch

    def add(self, first: int, projections, input: str = "lineint") -> None:
        """Filter views ``first … first + len(projections) − 1`` of the geometry, to be backprojected
        :attr:`batch_views` at a time: ``projections`` (views, rows, cols) are line integrals (or
        ``input="transmission"``)."""
        n = len(self._added)
        count = len(projections) if np.ndim(projections) == 3 else 0
        if isinstance(first, bool) or not isinstance(first, (int, np.integer)) or not 0 <= first < n:
            raise ReconstructionError(f"first must be a view index in 0…{n - 1}, got {first!r}")
        if first + max(count, 1) > n:
            raise ReconstructionError(f"views {first}…{first + count - 1} run past the geometry's {n} views")
        stack = line_integrals(projections, self.vector_geometry[first : first + max(count, 1)], input)
        if self._added[first : first + count].any():
            raise ReconstructionError(
                f"views {first}…{first + count - 1}: some were added already; add each view once")
        start = 0
        while start < count:
            if self._group is None:
                self._group = (self.ctx.buffer(self.plan.batch * self._view_bytes + WINDOW_PAD), [])
            buffer, views = self._group
            batch = range(first + start, first + min(start + self.plan.batch - len(views), count))
            self._filter(batch, stack[start : start + len(batch)], buffer, len(views) * self._view_bytes)
            views.extend(batch)
            start += len(batch)
            if len(views) == self.plan.batch:
                self._close_group()
        self._added[first : first + count] = True
        # Wait for the kernels: the caller's next batch then starts on free cores (a CPU device shares
        # them with the renderer), and the time add() takes is the reconstruction's own.
        self.ctx.queue.finish()

    def result(self) -> Volume:
        """The reconstruction (:class:`Volume`, cm⁻¹) once every view has been added; frees the device memory."""
        import pyopencl as cl

        missing = np.flatnonzero(~self._added)
        if len(missing):
            raise ReconstructionError(f"{len(missing)} view(s) not added yet (first: {missing[0]}); "
                                      "add every view before asking for the result")
        if self._group is not None:
            self._close_group()
        nz = self.volume.shape[0]
        for number, z0 in enumerate(self._slab_starts()):
            slab = self._slabs[number] if self.plan.streamed else self._slab_buffer(z0)
            for batch, filtered in () if self.plan.streamed else self._kept:
                q_dev = filtered if self.plan.resident else self.ctx.buffer(filtered, "r")
                self._backproject(batch, q_dev, slab, z0)
                if not self.plan.resident:
                    q_dev.release()
            depth = min(self.plan.slab, nz - z0)
            if self._zero_copy:
                mapped, _ = cl.enqueue_map_buffer(self.ctx.queue, slab, cl.map_flags.READ, 0, depth * self._plane, np.uint8)
                mapped.base.release()  # mapping makes the device's writes visible in the array
            else:
                cl.enqueue_copy(self.ctx.queue, self._out[z0 : z0 + depth], slab)
            slab.release()
        self._slabs = None
        self.ctx.queue.finish()
        data, self._out = self._out, None
        self.release()
        data *= MM_TO_CM
        corrected, seen = self._row_ends
        provenance = {**self._provenance, "truncation_corrected_row_ends": corrected / max(seen, 1)}
        return Volume(data, self.volume, provenance=provenance)

    def release(self) -> None:
        """Free the device buffers (and the context, if this stream made it)."""
        for buffer in (self._slabs or []) + ([self._group[0]] if self._group is not None else []):
            buffer.release()
        self._group = None
        for _, filtered in self._kept:
            if self.plan.resident:
                filtered.release()
        self._slabs, self._kept = None, []
        if self._owns_context and self.ctx is not None:
            self.ctx.release()
        self.ctx = None

    def __enter__(self) -> "FDKStream":
        return self

    def __exit__(self, *exc) -> None:
        if self.ctx is not None:
            self.release()

    def _close_group(self) -> None:
        """The filtered batch being gathered, backprojected (streamed) or kept until :meth:`result`."""
        import pyopencl as cl

        buffer, views = self._group
        self._group = None
        views = np.asarray(views)
        size = len(views) * self._view_bytes
        cl.enqueue_fill_buffer(self.ctx.queue, buffer, np.float32(0), size, WINDOW_PAD)  # read past the last column
        if self.plan.streamed:
            for z0, slab in zip(self._slab_starts(), self._slabs):
                self._backproject(views, buffer, slab, z0)
            buffer.release()
        elif self.plan.resident:
            self._kept.append((views, buffer))
        else:
            host = np.empty(size // 4, np.float32)
            cl.enqueue_copy(self.ctx.queue, host, buffer)  # its views alone
            buffer.release()
            self._kept.append((views, host))

    # -- stage 1: pre-weight and ramp-filter every row of a batch --------------------------------

    def _filter_setup(self) -> None:
        rows = self.views.detector_shape[0]
        self._view_bytes = (rows + 2) * (self.views.filtered_cols + 2) * 4
        if not self._host_filter:  # the kernel and what it reads (the host filter needs neither)
            defines = {**self._layout, **({"BUF": "__global", "GLOBAL_SCRATCH": 1} if self.plan.global_scratch else {})}
            self._filter_kernel = self.ctx.kernel("fdk_filter.cl", "filter_rows", defines)
            self._geo = _view_geometry(self.views)
        self._set_fft(extended=self._truncation is True)

    def _set_fft(self, extended: bool) -> None:
        """The ramp response for rows padded to fit the filtered columns, and the extrapolated ones
        too when ``extended`` (a longer FFT, made only once a row needs it); for the kernel, also
        on the device in bit-reversed order, with its twiddles."""
        import pyopencl as cl

        self._extended = extended
        response = ramp_response(self.views.filtered_cols + (2 * self._pad if extended else 0), self.views.pixel_pitch,
                                 *self._window)
        n = len(response)
        self._response_host = response
        self._n_fft = n
        if self._host_filter:
            return
        bits = int(math.log2(n))
        reverse = np.array([int(f"{k:0{bits}b}"[::-1], 2) for k in range(n)])
        self._response = self.ctx.buffer((response[reverse] / n).astype(np.float32), "r")
        self._twiddle = self.ctx.buffer(np.exp(-2j * np.pi * np.arange(n // 2) / n).astype(np.complex64), "r")
        self._local_size = int(min(self.ctx.info.max_work_group, n // 2, 256))
        self._local_scratch = cl.LocalMemory(n * 8)

    def _filter(self, batch: range, raw: np.ndarray, out=None, offset: int = 0):
        """The batch's filtered views, (views, rows + 2, filtered_cols + 2) float32, written into the
        device buffer ``out`` from byte ``offset``; without ``out``, into a new buffer, returned."""
        import pyopencl as cl

        ctx, n, count = self.ctx, self._n_fft, len(batch)
        rows, cols = self.views.detector_shape
        pairs = (rows + 1) // 2
        ends = truncated_row_ends(raw, self._edge_weights[batch.start : batch.stop], self._truncation)
        if ends.any() and not self._extended:
            self._set_fft(extended=True)  # the batches before had no truncated row: the same either way
            n = self._n_fft
        self._row_ends[0] += int(np.count_nonzero(ends & LEFT)) + int(np.count_nonzero(ends & RIGHT))
        self._row_ends[1] += 2 * ends.size
        # The pad lets backproject_windowed read its row window past the last column.
        size = count * self._view_bytes
        pad = self._pad if self._extended else 0
        if self._host_filter:
            views = self.views
            host = filter_rows_host(raw, views.vectors[batch.start : batch.stop], views.toward_axis[batch.start : batch.stop],
                                    views.redundancy[batch.start : batch.stop], ends, self._response_host, views.lead,
                                    views.filtered_cols, pad, views.beam == "cone", "COLUMN_MAJOR" in self._layout,
                                    self._widths[batch.start : batch.stop], self._threads)
            if out is None:
                out = ctx.buffer(size + WINDOW_PAD)
                cl.enqueue_fill_buffer(ctx.queue, out, np.float32(0), size, WINDOW_PAD)
            cl.enqueue_copy(ctx.queue, out, host, dst_offset=offset)  # the views with their rings of zeros
            return out
        out_dev = ctx.buffer(size + WINDOW_PAD)
        cl.enqueue_fill_buffer(ctx.queue, out_dev, np.float32(0), 0, size + WINDOW_PAD)
        raw_dev = ctx.buffer(raw, "r")
        part = slice(batch.start, batch.stop)
        extension_dev = ctx.buffer(kernel_extensions(raw, self.views, part, ends, pad, self._widths[part]), "r")
        red_dev = ctx.buffer(self.views.redundancy[batch.start : batch.stop].astype(np.float32), "r")
        geo_dev = ctx.buffer(self._geo[batch.start : batch.stop], "r")
        scratch = ctx.buffer(count * pairs * n * 8) if self.plan.global_scratch else self._local_scratch
        self._filter_kernel(ctx.queue, (count * pairs * self._local_size,), (self._local_size,), raw_dev, out_dev,
                            red_dev, geo_dev, extension_dev, self._response, self._twiddle, scratch, np.int32(rows),
                            np.int32(cols), np.int32(self.views.lead), np.int32(self.views.filtered_cols),
                            np.int32(pad), np.int32(n),
                            np.int32(self.views.beam == "cone"))
        for buffer in (raw_dev, red_dev, geo_dev, extension_dev) + ((scratch,) if self.plan.global_scratch else ()):
            buffer.release()  # after the kernel: OpenCL keeps them alive until it has run
        if out is None:
            return out_dev
        # The kernel writes from a buffer's start: into the gathered batch by a device-side copy
        # (a GPU's, where this path runs, copies a 512² batch of 32 views in well under a millisecond).
        cl.enqueue_copy(ctx.queue, out, out_dev, dst_offset=offset, byte_count=size)
        out_dev.release()
        return out

    # -- stage 2: a batch's filtered views into the voxels of one z-slab -------------------------

    def _backproject_setup(self) -> None:
        import pyopencl as cl

        matrices = self.views.matrices
        # The test for the upright kernels: a voxel's detector column and depth do not change along z
        # (P's third column has zeros in its first and last rows), as on every circular orbit.
        upright = UPRIGHT == "auto" and not np.any(matrices[:, :, 2][:, [0, 2]])
        defines = {"ZCHUNK": ZCHUNK, **self._layout, **({"UPRIGHT": 1} if upright else {})}
        kernel, self._zchunk, self._columns = None, ZCHUNK, False
        widths = {"auto": (16, 8), 16: (16,), 8: (8,), 0: ()}[WINDOW_LANES] if upright and self._layout else ()
        # backproject_columns first where it may apply (upright, column-major, automatic choice), then
        # backproject_windowed: each compiled only where the device has AVX-512 (16 lanes) or AVX2 (8).
        kinds = ([("backproject_columns", 16)] if COLUMNS and WINDOW_LANES == "auto" and widths else [])
        for name, width in kinds + [("backproject_windowed", width) for width in widths]:
            # As many vectors per work-item as the slab fills, up to WINDOW_VOXELS.
            groups = min(WINDOW_VOXELS // width, 1 << max(0, math.ceil(math.log2(-(-self.plan.slab // width)))))
            extra = {"TILE_VIEWS": COLUMN_VIEWS, "TILE_BLOCK": COLUMN_BLOCK} if name == "backproject_columns" else {}
            kernel = self.ctx.kernel("fdk_backproject.cl", name, {**defines, "WIDTH": width, "GROUPS": groups, **extra},
                                     optional=True)
            if kernel is not None:
                self._zchunk, self._columns = width * groups, name == "backproject_columns"
                break
        self._bp_kernel = kernel or self.ctx.kernel("fdk_backproject.cl", "backproject", defines)
        fits = self._bp_kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, self.ctx.device)
        if self._columns:
            self._tile = COLUMN_GROUP if fits >= math.prod(COLUMN_GROUP) else (1, 1, 1)
        else:
            self._tile = TILE if fits >= TILE[0] * TILE[1] else None  # else the driver picks
        _, ny, nx = self.volume.shape
        self._plane = ny * nx * 4
        # On a CPU device a buffer over the result array itself saves a copy of the volume.
        self._zero_copy = "CPU" in self.ctx.info.kind

    def _slab_starts(self) -> range:
        return range(0, self.volume.shape[0], self.plan.slab)

    def _slab_buffer(self, z0: int):
        import pyopencl as cl

        depth = min(self.plan.slab, self.volume.shape[0] - z0)
        if self._zero_copy:
            flags = cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR
            return cl.Buffer(self.ctx.ctx, flags, hostbuf=self._out[z0 : z0 + depth])
        slab = self.ctx.buffer(depth * self._plane)
        cl.enqueue_fill_buffer(self.ctx.queue, slab, np.float32(0), 0, depth * self._plane)
        return slab

    def _backproject(self, batch, filtered, slab, z0: int) -> None:
        """The filtered views of ``batch`` (view indices, in the order ``filtered`` holds them) into one slab."""
        rows, cols = self.views.detector_shape[0], self.views.filtered_cols
        nz, ny, nx = self.volume.shape
        depth = min(self.plan.slab, nz - z0)
        batch = np.asarray(batch)
        matrices = self.views.matrices[batch]
        matrices[:, :, 3] += z0 * matrices[:, :, 2]  # slab-local k
        matrices[:, 0] += self.views.lead * matrices[:, 2]  # column of the filtered row: virtual ones first
        # backproject_columns projects in double (its setup per voxel column and view), the others in float
        m_dev = self.ctx.buffer(matrices.reshape(-1, 12).astype(np.float64 if self._columns else np.float32), "r")
        s_dev = self.ctx.buffer(self.views.scale[batch].astype(np.float32), "r")
        if self._columns:  # a work-item per COLUMN_TILE columns along x
            size = (-(-nx // COLUMN_TILE), _round_up(ny, self._tile[1]), -(-depth // self._zchunk))
        else:
            size = (_round_up(nx, TILE[0]), _round_up(ny, TILE[1]), -(-depth // self._zchunk))
        self._bp_kernel(self.ctx.queue, size, self._tile, slab, filtered, m_dev, s_dev, np.int32(len(batch)),
                        np.int32(rows), np.int32(cols), np.int32(nx), np.int32(ny), np.int32(depth))
        m_dev.release()
        s_dev.release()


def _view_geometry(views: FDKViews) -> np.ndarray:
    """(views, 5, 4) float32 per view: s, d, u, v and ŝ (toward the axis), each xyz 0 (for cosine weights)."""
    a = views.vectors
    geo = np.zeros((len(a), 5, 4), np.float32)
    geo[:, :4, :3] = a.reshape(-1, 4, 3)
    geo[:, 4, :3] = views.toward_axis
    return geo


def _column_major(info, layout: str) -> bool:
    """Filtered views stored column by column: on CPUs (cache lines), not on GPUs (coalescing)."""
    return layout == "columns" or (layout == "auto" and "CPU" in info.kind)


def _round_up(x: int, multiple: int) -> int:
    return -(-x // multiple) * multiple
