"""Label volumes: which object owns each voxel centre, on the reconstruction's very voxel grid.

    labels = xr.voxelize(scene, vol.geometry)   # LabelVolume: data uint8/uint16 (z, y, x)

How
---
Each voxel column (x_i, y_j) is a ray along +z: together the columns are a parallel-beam "view"
whose detector pixels are the volume's (x, y) voxel centres. The path-length renderer records
every crossing of those rays with the scene's triangles (the same exact, watertight float32
test that makes the projections, ``shaders/ray.glsl``) in per-column lists, once per volume.
``shaders/voxelize_resolve.comp`` then sorts each column's crossings and sweeps them upward
slice by slice: below a voxel centre each crossing moves its object's winding count by ±1 (the
count a stencil buffer keeps in stencil-based voxelizers), the centre is inside the objects
with a positive count, and takes the label of the highest-priority one (ties: the one added
later), else 0. Overlaps therefore follow exactly the renderer's rule.

Why not the GL stencil buffer and a clip plane per slice, the classic method: rasterised
coverage is the driver's, snapped to sub-pixel precision, so a column passing within ~1/256 of
a voxel of a silhouette can gain or lose a crossing; and every slice re-renders every triangle
above it, O(triangles × slices). Counting the exact crossings once costs O(triangles +
crossings + voxels), and a label voxel is inside an object exactly when the ray through it
crosses that object's surface as the projections saw it.

Labels are uint8 when every label is below 256, else uint16. Slabs of slices are resolved and
read back one at a time (``slab_bytes``), so the output, not the GPU, bounds the volume size.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .geometry import VectorGeometry, VolumeGeometry
from .glcontext import GLContext
from .render import Renderer
from .resources import available_memory
from .scene import Scene

log = logging.getLogger(__name__)

SLAB_BYTES = 64 * 2**20  # label words resolved per pass (GL_MAX_SHADER_STORAGE_BLOCK_SIZE is 128 MiB on llvmpipe)


class VoxelizeError(ValueError):
    """A voxelization request cannot be met; the message says the fix."""


@dataclass(frozen=True)
class LabelVolume:
    """Labels ``data`` (z, y, x) on ``geometry``: 0 background, else the owning object's label."""

    data: np.ndarray
    geometry: VolumeGeometry


def column_geometry(volume: VolumeGeometry) -> VectorGeometry:
    """The parallel "view" along +z whose pixel (row j, col i) is voxel column (j, i)."""
    vz, vy, vx = volume.voxel_size
    oz, oy, ox = volume.offset
    nz, ny, nx = volume.shape
    return VectorGeometry("parallel", (ny, nx), [[0.0, 0.0, 1.0, ox, oy, oz, vx, 0.0, 0.0, 0.0, vy, 0.0]])


def voxelize(scene: Scene, volume: VolumeGeometry, *, context: GLContext | None = None,
             slab_bytes: int = SLAB_BYTES) -> LabelVolume:
    """The label of the object owning each voxel centre of ``volume`` (see the module docstring)."""
    if not isinstance(scene, Scene):
        raise VoxelizeError(f"expected a Scene, got {type(scene).__name__}")
    if not isinstance(volume, VolumeGeometry):
        raise VoxelizeError(f"volume must be a VolumeGeometry, got {type(volume).__name__}")
    scene.require_objects()
    top = max(o.label for o in scene.objects)
    dtype = np.uint8 if top < 256 else np.uint16
    per_word = 4 if dtype == np.uint8 else 2
    nz, ny, nx = volume.shape
    need = nz * ny * nx * np.dtype(dtype).itemsize
    free = available_memory()
    if free is not None and need > free // 2:
        raise VoxelizeError(
            f"a {nz}×{ny}×{nx} {np.dtype(dtype).name} label volume needs {need / 2**30:.2f} GiB, more than half the "
            f"{free / 2**30:.2f} GiB available; voxelize a smaller volume or part of it (VolumeGeometry.offset)")
    slices = max(per_word, (slab_bytes // (4 * ny * nx)) * per_word)  # a multiple of per_word
    out = np.zeros(volume.shape, dtype)
    with Renderer(column_geometry(volume), overlap="resolve", context=context) as renderer:
        with renderer.gl.current():
            buffers = renderer.crossing_lists(scene)
            ctx = renderer.gl.ctx
            z0 = volume.axis_centres(0)[0] - float(buffers.ref[2])  # t of slice 0, mm
            words = ctx.buffer(reserve=4 * ny * nx * (slices // per_word))
            words.bind_to_storage_buffer(7)
            counters = renderer._buffers["counters"]
            for k0 in range(0, nz, slices):
                count = min(slices, nz - k0)
                padded = -(-count // per_word) * per_word
                while True:
                    resolve = renderer.gl.compute("voxelize_resolve.comp", {
                        "MAX_CROSSINGS": renderer._max_crossings, "LABELS_PER_WORD": per_word})
                    resolve["u_size"].value = (nx, ny)
                    resolve["u_t0"].value = z0 + k0 * volume.voxel_size[0]
                    resolve["u_dt"].value = volume.voxel_size[0]
                    resolve["u_slices"].value = padded
                    counters.write(np.zeros(4, np.uint32).tobytes())
                    resolve.run((nx + 7) // 8, (ny + 7) // 8, 1)
                    ctx.memory_barrier()
                    _, overflow, depth, _ = np.frombuffer(counters.read(), np.uint32)
                    if not overflow:
                        break
                    renderer._max_crossings = int(2 ** np.ceil(np.log2(depth)))
                    log.info("voxelize: columns with up to %d crossings; resolving again", depth)
                raw = np.frombuffer(words.read(size=4 * ny * nx * padded // per_word), np.uint32)
                unpacked = raw.view(dtype).reshape(padded // per_word, ny, nx, per_word)
                out[k0 : k0 + count] = unpacked.transpose(0, 3, 1, 2).reshape(padded, ny, nx)[:count]
            words.release()
            renderer.empty_lists()
    return LabelVolume(out, volume)
