"""FDK cone-beam reconstruction (and parallel-beam FBP by the same path) in OpenCL.

    vol = xr.fdk(line_integrals, geometry, xr.VolumeGeometry(shape=(256,) * 3, voxel_size=0.05))
    vol.data      # float32 (z, y, x), cm⁻¹ (the CT convention; docs/reconstruction.md)
    vol.geometry  # the VolumeGeometry: voxel (k, j, i) is where xr.voxelize puts label (k, j, i)

The algorithm and its weights are in :mod:`xrayraster.recon.fdk_weights`, the filter in
:mod:`xrayraster.recon.ramp_filter`, the kernels in ``shaders/fdk_filter.cl`` and
``shaders/fdk_backproject.cl``. ``references/fdk.py`` is the same algorithm in float64
NumPy, against which the kernels are tested.

Memory: the volume is reconstructed in z-slabs that fit the device next to one batch of filtered
views; filtered projections stay on the device when they all fit, else they wait in host memory
and are uploaded again for each slab. Both needs are estimated before any work starts, and a
request that cannot fit is refused with the sizes.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.choices import RECONSTRUCTION_INPUTS, check_choice
from ..core.errors import ReconstructionError
from ..core.geometry import as_vector_geometry
from ..core.memory import available_memory
from ..core.projections import Projections
from ..core.tiff import write_quicklook, write_volume
from ..core.volume import VolumeGeometry
from .fdk_weights import FDKViews, fdk_views
from .opencl import CLContext
from .ramp_filter import ramp_response

log = logging.getLogger(__name__)

MM_TO_CM = 10.0  # μ in mm⁻¹ × 10 = cm⁻¹
ZCHUNK = 16  # voxels along z per work-item of the scalar backprojection (shaders/fdk_backproject.cl)
MAX_GROUPS = 8  # float8s along z per work-item of backproject_windowed: up to 64 voxels
SLAB_MULTIPLE = 64  # slabs are cut at multiples of both
TILE = (16, 16, 1)  # work-group: a 16×16 column of voxels reads a compact patch of every view
MAX_BATCH_VIEWS = 256  # views per backprojection launch: 48 bytes each of constant memory
# Kernel choices, normally automatic; the tests set them to check every path on one device.
LAYOUT = "auto"  # filtered views by "rows" (GPUs), by "columns" (CPUs), or "auto" by device type
VECTORISED = True  # backproject_windowed where it applies (x86 CPUs with AVX2, upright detectors)
DEVICE_SHARE = 0.8  # of the device's global memory we plan to use
WINDOW_PAD = 32 * 4  # bytes after each batch of filtered views: backproject_windowed reads past the last column


@dataclass(frozen=True)
class Volume:
    """A reconstructed volume: ``data`` float32 (z, y, x) in ``unit`` on ``geometry``.

    ``unit`` is ``"1/cm"``: reconstructions are linear attenuation coefficients in cm⁻¹ (the
    path-length physics works in mm⁻¹; see :mod:`xrayraster`). ``provenance``: JSON-ready facts
    about how it was made (scan geometry, filter, ...), stored by :meth:`save`.
    """

    data: np.ndarray
    geometry: VolumeGeometry
    unit: str = "1/cm"
    provenance: dict = field(default_factory=dict, compare=False)

    def save(self, path, *, quicklook: bool = True):
        """Write the volume as ``xrayraster reconstruct`` does: a float32 ImageJ TIFF (z, y, x) at
        ``path`` whose voxel size Fiji reads in mm, with the unit, the grid's dict form
        (``volume_geometry``) and :attr:`provenance` as JSON metadata, and, with ``quicklook``, a
        PNG of the central slice (negative values shown as 0, with a scale bar) beside it.
        Returns ``path``."""
        info = {"quantity": "linear attenuation coefficient", "units": self.unit, **self.provenance}
        out = write_volume(path, self.data, self.geometry, info)
        if quicklook:
            middle = np.clip(self.data[self.data.shape[0] // 2], 0, None)
            write_quicklook(out.with_suffix(".png"), middle, self.geometry.voxel_size[1:])
        return out


def fdk(projections, geometry=None, volume: VolumeGeometry | None = None, *, filter: str = "ram-lak",
        cutoff: float = 1.0, scan: str = "auto", input: str | None = None, context: CLContext | None = None,
        device: str | None = None, memory_limit: int | None = None) -> Volume:
    """Reconstruct ``volume`` from ``projections`` (views, rows, cols) taken with ``geometry``.

    * ``projections``: an array with its ``geometry``, or a
      :class:`~xrayraster.core.projections.Projections`, which carries its geometry and what it
      holds (``fdk(p, volume=grid)``; a ``geometry`` or ``input`` given as well must agree).
    * ``input``: ``"lineint"`` (the default for arrays: −ln of the transmission, dimensionless:
      ∫μ dl with μ in mm⁻¹) or ``"transmission"`` (I/I₀, logged here; every value must be > 0).
    * ``filter``: ``ram-lak``, ``shepp-logan``, ``cosine``, ``hamming`` or ``hann``; ``cutoff``
      as a fraction of the Nyquist frequency (:mod:`xrayraster.recon.ramp_filter`).
    * ``scan``: ``auto``, ``full`` or ``short`` (Parker weights), see :mod:`xrayraster.recon.fdk_weights`.
    * ``context``: a :class:`~xrayraster.recon.opencl.CLContext` to reuse (kernels stay compiled),
      else one is made on ``device`` (or ``XRAYRASTER_CL_DEVICE``, or the fastest device).
    * ``memory_limit``: bytes of device memory to plan with (default 80 % of the device's).

    Returns a :class:`Volume` in cm⁻¹.
    """
    projections, geometry, input = _unpack(projections, geometry, input)
    if not isinstance(volume, VolumeGeometry):
        raise ReconstructionError(f"volume must be a VolumeGeometry (the grid to reconstruct), got {type(volume).__name__}")
    vec = as_vector_geometry(geometry)
    stack = line_integrals(projections, vec, input)
    views = fdk_views(vec, volume, scan)
    response = ramp_response(vec.detector_shape[1], views.pixel_pitch, filter, cutoff)
    ctx = context or CLContext(device)
    try:
        data = _reconstruct(ctx, stack, views, response, volume, memory_limit)
    finally:
        if context is None:
            ctx.release()
    data *= MM_TO_CM
    return Volume(data, volume, provenance={
        "method": "FDK" if vec.beam == "cone" else "FBP", "geometry": geometry.to_dict(), "filter": filter,
        "cutoff": cutoff, "scan": scan, "input": input})


def _unpack(projections, geometry, input):
    """(array, geometry, input) from an array and its geometry, or from a Projections."""
    if not isinstance(projections, Projections):
        if geometry is None:
            raise ReconstructionError("give the scan geometry of the projections (or pass an xr.Projections)")
        return projections, geometry, input or "lineint"
    if geometry is not None and geometry != projections.geometry:
        raise ReconstructionError("the geometry given differs from the one the Projections carry; pass one of them")
    if projections.quantity not in RECONSTRUCTION_INPUTS:
        raise ReconstructionError(f"these projections hold {projections.quantity!r}; reconstruct line integrals or "
                                  "transmissions (a radiograph rendered with output='lineint' or 'transmission')")
    if input is not None and input != projections.quantity:
        raise ReconstructionError(f"input={input!r} but the Projections hold {projections.quantity!r}; drop input")
    return projections.data, projections.geometry, projections.quantity


def line_integrals(projections, geometry, input: str = "lineint") -> np.ndarray:
    """The projections as float32 line integrals, checked against ``geometry``."""
    check_choice(input, RECONSTRUCTION_INPUTS, "input", ReconstructionError)
    vec = as_vector_geometry(geometry)
    p = np.asarray(projections)
    expected = (vec.num_views, *vec.detector_shape)
    if p.ndim != 3 or p.shape[0] == 0:
        raise ReconstructionError(
            f"projections must be a (views, rows, cols) stack with at least one view, got shape {p.shape}")
    if p.shape != expected:
        raise ReconstructionError(
            f"projections have shape {p.shape} but the geometry has {expected[0]} views of "
            f"{expected[1]}×{expected[2]} pixels {expected}: pass the geometry the projections were taken with "
            "(or select its views: geometry[indices])")
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


@dataclass(frozen=True)
class _Plan:
    batch: int  # views per launch
    slab: int  # z-planes per slab
    resident: bool  # all filtered views stay on the device
    global_scratch: bool  # a padded row pair does not fit in local memory


def plan_memory(views: FDKViews, volume: VolumeGeometry, n_fft: int, device_bytes: int, max_alloc: int,
                local_bytes: int, host_bytes: int | None) -> _Plan:
    """View batches and z-slabs that fit ``device_bytes``; refuses what cannot fit, before any work."""
    num_views = len(views.scale)
    rows, cols = views.detector_shape
    nz, ny, nx = volume.shape
    filtered = (rows + 2) * (cols + 2) * 4
    plane = ny * nx * 4
    global_scratch = n_fft * 8 > local_bytes // 2
    pairs = (rows + 1) // 2
    per_view = rows * cols * 4 + filtered + (pairs * n_fft * 8 if global_scratch else 0)  # while filtering
    min_slab = min(nz, SLAB_MULTIPLE)
    fit = (device_bytes - min_slab * plane) // per_view
    batch = int(min(num_views, MAX_BATCH_VIEWS, max(1, max_alloc // filtered), fit))
    if batch < 1 or plane > max_alloc:
        raise ReconstructionError(
            f"the reconstruction does not fit the OpenCL device: one view of {rows}×{cols} pixels and {min_slab} plane(s) "
            f"of {ny}×{nx} voxels need {_size(per_view + min_slab * plane)}, the plan allows {_size(device_bytes)} "
            f"(one buffer at most {_size(max_alloc)}); use fewer detector pixels or voxels per plane, or a device with "
            "more memory")
    resident = num_views * filtered + batch * per_view + min_slab * plane <= device_bytes
    room = device_bytes - (num_views * filtered if resident else batch * filtered)
    slab = int(min(nz, room // plane, max_alloc // plane))
    if SLAB_MULTIPLE <= slab < nz:
        slab -= slab % SLAB_MULTIPLE
    host_need = nz * ny * nx * 4 + (0 if resident else num_views * filtered)
    if host_bytes is not None and host_need > host_bytes:
        raise ReconstructionError(
            f"the reconstruction needs {_size(host_need)} of host memory (the {nz}×{ny}×{nx} float32 volume"
            f"{'' if resident else ' and the filtered projections'}) but {_size(host_bytes)} is available; "
            "reconstruct a smaller volume (or a part of it with VolumeGeometry.offset)")
    return _Plan(batch, slab, bool(resident), bool(global_scratch))


def _size(nbytes: int) -> str:
    return f"{nbytes / 2**30:.2f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


def _reconstruct(ctx: CLContext, stack, views: FDKViews, response, volume: VolumeGeometry, memory_limit) -> np.ndarray:
    info = ctx.info
    device_bytes = int(info.global_mem * DEVICE_SHARE) if memory_limit is None else int(memory_limit)
    plan = plan_memory(views, volume, len(response), device_bytes, info.max_alloc, info.local_mem, available_memory())
    rows, cols = views.detector_shape
    log.info("FDK on %s: %d views of %d×%d, volume %s, %d-view batches, %d-plane slabs, filtered views %s",
             info.name, len(views.scale), rows, cols, volume.shape, plan.batch, plan.slab,
             "on the device" if plan.resident else "in host memory")
    layout = {"COLUMN_MAJOR": 1} if _column_major(info, LAYOUT) else {}
    batches = [range(start, min(start + plan.batch, len(views.scale))) for start in range(0, len(views.scale), plan.batch)]
    filtered = _filter(ctx, stack, views, response, plan, layout, batches)
    try:
        return _backproject(ctx, filtered, views, volume, plan, layout, batches)
    finally:
        for buffer in filtered if plan.resident else ():
            buffer.release()


def _filter(ctx: CLContext, stack, views: FDKViews, response, plan: _Plan, layout: dict, batches):
    """Stage 1, batch by batch: pre-weight and ramp-filter every row. Returns one device buffer
    per batch (``plan.resident``), else a host array (views, rows + 2, cols + 2)."""
    import pyopencl as cl

    n = len(response)
    rows, cols = views.detector_shape
    defines = {**layout, **({"BUF": "__global", "GLOBAL_SCRATCH": 1} if plan.global_scratch else {})}
    kernel = ctx.kernel("fdk_filter.cl", "filter_rows", defines)
    bits = int(math.log2(n))
    reverse = np.array([int(f"{k:0{bits}b}"[::-1], 2) for k in range(n)])
    response_dev = ctx.buffer((response[reverse] / n).astype(np.float32), "r")
    twiddle_dev = ctx.buffer(np.exp(-2j * np.pi * np.arange(n // 2) / n).astype(np.complex64), "r")
    geo = _view_geometry(views)
    pairs = (rows + 1) // 2
    lsize = int(min(ctx.info.max_work_group, n // 2, 256))
    view_bytes = (rows + 2) * (cols + 2) * 4
    out = [] if plan.resident else np.empty((len(views.scale), rows + 2, cols + 2), np.float32)
    for batch in batches:
        count = len(batch)
        raw_dev = ctx.buffer(stack[batch.start : batch.stop], "r")
        # The pad lets backproject_windowed read its row window past the last column.
        out_dev = ctx.buffer(count * view_bytes + WINDOW_PAD)
        cl.enqueue_fill_buffer(ctx.queue, out_dev, np.float32(0), 0, count * view_bytes + WINDOW_PAD)
        red_dev = ctx.buffer(views.redundancy[batch.start : batch.stop].astype(np.float32), "r")
        geo_dev = ctx.buffer(geo[batch.start : batch.stop], "r")
        scratch = ctx.buffer(count * pairs * n * 8) if plan.global_scratch else cl.LocalMemory(n * 8)
        kernel(ctx.queue, (count * pairs * lsize,), (lsize,), raw_dev, out_dev, red_dev, geo_dev, response_dev,
               twiddle_dev, scratch, np.int32(rows), np.int32(cols), np.int32(n), np.int32(views.beam == "cone"))
        if plan.resident:
            out.append(out_dev)
        else:
            cl.enqueue_copy(ctx.queue, out[batch.start : batch.stop], out_dev)
            out_dev.release()
    return out


def _backproject(ctx: CLContext, filtered, views: FDKViews, volume: VolumeGeometry, plan: _Plan, layout: dict,
                 batches) -> np.ndarray:
    """Stage 2, slab by slab: every view's filtered rows into the voxels. Returns (z, y, x) mm⁻¹."""
    import pyopencl as cl

    rows, cols = views.detector_shape
    nz, ny, nx = volume.shape
    matrices = views.matrices
    upright = not np.any(matrices[:, :, 2][:, [0, 2]])  # column and depth constant along z
    # As many float8s per work-item as the slab fills, up to MAX_GROUPS (measured best on 2 cores).
    groups = min(MAX_GROUPS, 1 << max(0, math.ceil(math.log2(-(-plan.slab // 8)))))
    defines = {"ZCHUNK": ZCHUNK, "GROUPS": groups, **layout, **({"UPRIGHT": 1} if upright else {})}
    kernel = None
    if VECTORISED and upright and layout:  # compiled only where the device has AVX2
        kernel = ctx.kernel("fdk_backproject.cl", "backproject_windowed", defines, optional=True)
    zchunk = 8 * groups if kernel is not None else ZCHUNK
    kernel = kernel or ctx.kernel("fdk_backproject.cl", "backproject", defines)
    fits = kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, ctx.device)
    tile = TILE if fits >= TILE[0] * TILE[1] else None  # else the driver picks
    view_bytes = (rows + 2) * (cols + 2) * 4
    out = np.empty(volume.shape, np.float32)
    for z0 in range(0, nz, plan.slab):
        depth = min(plan.slab, nz - z0)
        slab_dev = ctx.buffer(depth * ny * nx * 4)
        cl.enqueue_fill_buffer(ctx.queue, slab_dev, np.float32(0), 0, depth * ny * nx * 4)
        shifted = matrices.copy()
        shifted[:, :, 3] += z0 * matrices[:, :, 2]  # slab-local k
        for number, batch in enumerate(batches):
            if plan.resident:
                q_dev = filtered[number]
            else:
                q_dev = ctx.buffer(len(batch) * view_bytes + WINDOW_PAD, "r")
                cl.enqueue_copy(ctx.queue, q_dev, filtered[batch.start : batch.stop])
            m_dev = ctx.buffer(shifted[batch.start : batch.stop].reshape(-1, 12).astype(np.float32), "r")
            s_dev = ctx.buffer(views.scale[batch.start : batch.stop].astype(np.float32), "r")
            size = (_round_up(nx, TILE[0]), _round_up(ny, TILE[1]), -(-depth // zchunk))
            kernel(ctx.queue, size, tile, slab_dev, q_dev, m_dev, s_dev, np.int32(len(batch)), np.int32(rows),
                   np.int32(cols), np.int32(nx), np.int32(ny), np.int32(depth))
            if not plan.resident:
                q_dev.release()
        cl.enqueue_copy(ctx.queue, out[z0 : z0 + depth], slab_dev)
        slab_dev.release()
    ctx.queue.finish()
    return out


def _view_geometry(views: FDKViews) -> np.ndarray:
    """(views, 4, 4) float32 per view: s.xyz D, d.xyz 0, u.xyz 0, v.xyz 0 (for cosine weights)."""
    a = views.vectors
    s, d, u, v = a[:, 0:3], a[:, 3:6], a[:, 6:9], a[:, 9:12]
    geo = np.zeros((len(a), 4, 4), np.float32)
    geo[:, 0, :3], geo[:, 0, 3] = s, views.depth
    geo[:, 1, :3], geo[:, 2, :3], geo[:, 3, :3] = d, u, v
    return geo


def _column_major(info, layout: str) -> bool:
    """Filtered views stored column by column: on CPUs (cache lines), not on GPUs (coalescing)."""
    return layout == "columns" or (layout == "auto" and "CPU" in info.kind)


def _round_up(x: int, multiple: int) -> int:
    return -(-x // multiple) * multiple
