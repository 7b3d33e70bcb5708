"""The FDK's memory plan: view batches and z-slabs that fit an OpenCL device and the host, refused
before any work when nothing fits (:class:`~xrayraster.recon.fdk_stream.FDKStream` follows it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import ReconstructionError
from ..core.volume import VolumeGeometry
from .fdk_weights import FDKViews

SLAB_MULTIPLE = 64  # slabs are cut at multiples of both kernels' voxels along z a work-item
MAX_BATCH_VIEWS = 256  # views per backprojection launch: 48 bytes each of constant memory (96: backproject_columns)


@dataclass(frozen=True)
class FDKPlan:
    """How :func:`plan_memory` cuts a reconstruction."""


    batch: int  # views per launch
    slab: int  # z-planes per slab
    streamed: bool  # the whole volume stays on the device: each batch is backprojected on arrival
    resident: bool  # else: all filtered views wait on the device (True) or in host memory (False)
    global_scratch: bool  # a padded row pair does not fit in local memory


def plan_memory(views: FDKViews, volume: VolumeGeometry, n_fft: int, device_bytes: int, max_alloc: int,
                local_bytes: int, host_bytes: int | None, batch_views: int = MAX_BATCH_VIEWS) -> FDKPlan:
    """View batches and z-slabs that fit ``device_bytes``; refuses what cannot fit, before any work."""
    if isinstance(batch_views, bool) or not isinstance(batch_views, (int, np.integer)) or batch_views < 1:
        raise ReconstructionError(f"batch_views must be a positive integer, got {batch_views!r}")
    num_views = len(views.scale)
    rows, cols = views.detector_shape
    nz, ny, nx = volume.shape
    filtered = (rows + 2) * (views.filtered_cols + 2) * 4
    plane = ny * nx * 4
    global_scratch = n_fft * 8 > local_bytes // 2
    pairs = (rows + 1) // 2
    per_view = rows * cols * 4 + filtered + (pairs * n_fft * 8 if global_scratch else 0)  # while filtering
    most = int(min(num_views, batch_views, MAX_BATCH_VIEWS, max(1, max_alloc // filtered)))
    max_slab = max_alloc // plane
    streamed_fit = (device_bytes - nz * plane) // per_view
    if streamed_fit >= 1 and max_slab >= 1:
        slab = int(min(nz, max_slab))
        if SLAB_MULTIPLE <= slab < nz:
            slab -= slab % SLAB_MULTIPLE
        plan = FDKPlan(int(min(most, streamed_fit)), slab, True, False, bool(global_scratch))
    else:
        min_slab = min(nz, SLAB_MULTIPLE)
        batch = int(min(most, (device_bytes - min_slab * plane) // per_view))
        if batch < 1 or max_slab < 1:
            raise ReconstructionError(
                f"the reconstruction does not fit the OpenCL device: one view of {rows}×{cols} pixels and {min_slab} "
                f"plane(s) of {ny}×{nx} voxels need {_size(per_view + min_slab * plane)}, the plan allows "
                f"{_size(device_bytes)} (one buffer at most {_size(max_alloc)}); use fewer detector pixels or voxels "
                "per plane, or a device with more memory")
        resident = num_views * filtered + batch * per_view + min_slab * plane <= device_bytes
        room = device_bytes - (num_views * filtered if resident else batch * filtered)
        slab = int(min(nz, room // plane, max_slab))
        if SLAB_MULTIPLE <= slab < nz:
            slab -= slab % SLAB_MULTIPLE
        plan = FDKPlan(batch, slab, False, bool(resident), bool(global_scratch))
    host_need = nz * ny * nx * 4 + (0 if plan.streamed or plan.resident else num_views * filtered)
    if host_bytes is not None and host_need > host_bytes:
        raise ReconstructionError(
            f"the reconstruction needs {_size(host_need)} of host memory (the {nz}×{ny}×{nx} float32 volume"
            f"{'' if plan.streamed or plan.resident else ' and the filtered projections'}) but {_size(host_bytes)} "
            "is available; reconstruct a smaller volume (or a part of it with VolumeGeometry.offset)")
    return plan


def _size(nbytes: int) -> str:
    return f"{nbytes / 2**30:.2f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"
