"""Label volumes: which object owns each voxel centre, on the reconstruction's very voxel grid.

    labels = xr.voxelize(scene, vol.geometry)   # LabelVolume: data uint8/uint16 (z, y, x)

How
---
Each voxel column (x_i, y_j) is a ray along +z: together the columns are a parallel-beam "view"
whose detector pixels are the volume's (x, y) voxel centres. The crossing engine of the path
lengths (:mod:`xrayraster.gl.crossings`) records every crossing of those rays with the scene's
triangles (the same exact, watertight float32 test that makes the projections,
``shaders/ray.glsl``) in per-column lists, once per volume.
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

Labels are uint8 when every label is below 256, else uint16. Memory: the volume is cut into
(x, y) tiles of at most TILE_COLUMNS² columns, whose crossing lists take 16 bytes a crossing,
and each tile's slices are resolved and read back in slabs of ``slab_bytes``; slices the scene
does not reach are left 0, and objects outside a tile's box are not tested, without work. So
the output array, not the GPU, bounds the size.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.choices import VOXELIZE_METHODS, check_choice
from ..core.errors import VoxelizeError
from ..core.geometry import VectorGeometry
from ..core.memory import check_fits
from ..core.tiff import checked_outputs, write_quicklook, write_volume
from ..core.volume import VolumeGeometry
from ..scene.scene import Scene
from .context import GLContext
from .crossings import CrossingEngine
from .voxelize_stencil import voxelize_stencil

SLAB_BYTES = 64 * 2**20  # label words resolved per pass (GL_MAX_SHADER_STORAGE_BLOCK_SIZE is 128 MiB on llvmpipe)
TILE_COLUMNS = 512  # columns per side of an (x, y) tile: bounds the crossing lists (16 bytes a crossing)


@dataclass(frozen=True)
class LabelVolume:
    """Labels ``data`` (z, y, x) on ``geometry``: 0 background, else the owning object's label.

    With ``fractions``: ``data`` holds each voxel's majority label, and ``fractions``
    (len(labels), z, y, x) float32 the share of the voxel owned by each of ``labels`` (label 0,
    the background, first), from k×k×k sub-voxel centres.
    """

    data: np.ndarray
    geometry: VolumeGeometry
    labels: tuple[int, ...] | None = None
    fractions: np.ndarray | None = None
    provenance: dict = field(default_factory=dict, compare=False)  # JSON-ready facts stored by save

    def save(self, path, *, quicklook: bool = True):
        """Write the labels as ``xrayraster voxelize`` does: a uint8/uint16 ImageJ TIFF (z, y, x) at
        ``path`` whose voxel size Fiji reads in mm, with the grid's dict form
        (``volume_geometry``) as JSON metadata; with fractions, ``<stem>_fractions.tif`` beside it
        (float32, z, label, y, x: one channel per label of :attr:`labels`); and, with
        ``quicklook``, a PNG of the central slice with a scale bar. Returns ``path``."""
        fractions = [fractions_path(Path(path)).name] if self.fractions is not None else []
        out, *side = checked_outputs(path, quicklook=quicklook, beside=fractions)
        png = side[0] if quicklook else None
        present = [int(k) for k in np.flatnonzero(np.bincount(self.data.ravel())) if k]
        write_volume(out, self.data, self.geometry, {
            "quantity": "label (0: background; else the label of the highest-priority object at the voxel centre)",
            "labels_present": present, **self.provenance})
        if self.fractions is not None:
            # ImageJ hyperstacks are ordered T Z C Y X: one channel per label.
            write_volume(side[-1], self.fractions.transpose(1, 0, 2, 3), self.geometry, channels="label", info={
                "quantity": "share of each voxel owned by each label, from sub-voxel centres",
                "channel_labels": list(self.labels or ())})
        if png is not None:
            middle = self.data[self.data.shape[0] // 2].astype(np.float32)
            write_quicklook(png, middle, self.geometry.voxel_size[1:])
        return out


def fractions_path(out: Path) -> Path:
    """Where :meth:`LabelVolume.save` puts the fractions of the labels saved at ``out``."""
    return out.with_name(f"{out.stem}_fractions.tif")


def column_geometry(volume: VolumeGeometry) -> VectorGeometry:
    """The parallel "view" along +z whose pixel (row j, col i) is voxel column (j, i)."""
    vz, vy, vx = volume.voxel_size
    oz, oy, ox = volume.offset
    nz, ny, nx = volume.shape
    return VectorGeometry("parallel", (ny, nx), [[0.0, 0.0, 1.0, ox, oy, oz, vx, 0.0, 0.0, 0.0, vy, 0.0]])


def voxelize(scene: Scene, volume: VolumeGeometry, *, fractions: int | None = None, method: str = "exact",
             context: GLContext | None = None, slab_bytes: int = SLAB_BYTES) -> LabelVolume:
    """The label of the object owning each voxel centre of ``volume`` (see the module docstring).

    ``fractions=k``: also the partial-volume share of every label in each voxel, from the k³
    centres of a regular k×k×k sub-grid (soft labels; cost and memory ∝ k³ per slab).
    ``method="stencil"``: the classic slice-by-slice stencil counting instead
    (:mod:`xrayraster.gl.voxelize_stencil`; kept to compare against, no fractions).
    """
    if not isinstance(scene, Scene):
        raise VoxelizeError(f"expected a Scene, got {type(scene).__name__}")
    if not isinstance(volume, VolumeGeometry):
        raise VoxelizeError(f"volume must be a VolumeGeometry, got {type(volume).__name__}")
    if fractions is not None and (int(fractions) != fractions or not 1 <= fractions <= 16):
        raise VoxelizeError(f"fractions must be a sub-voxel count per axis from 1 to 16, got {fractions!r}")
    check_choice(method, VOXELIZE_METHODS, "method", VoxelizeError)
    if method == "stencil" and fractions:
        raise VoxelizeError(f"method must be 'exact' or 'stencil' (the latter without fractions), got {method!r}")
    scene.require_objects()
    labels = sorted({o.label for o in scene.objects})
    dtype = np.uint8 if labels[-1] < 256 else np.uint16
    nz, ny, nx = volume.shape
    itemsize = np.dtype(dtype).itemsize + (4 * (len(labels) + 1) if fractions else 0)
    check_fits(nz * ny * nx * itemsize, f"a {nz}×{ny}×{nx} label volume{' with fractions' if fractions else ''}",
               "voxelize a smaller volume or part of it (VolumeGeometry.offset)", VoxelizeError)
    owns = context is None
    gl = context or GLContext()
    try:
        if method == "stencil":
            return LabelVolume(voxelize_stencil(scene, volume, dtype, gl), volume)
        if fractions:
            return _with_fractions(scene, volume, int(fractions), labels, dtype, gl, slab_bytes)
        out = np.zeros(volume.shape, dtype)
        for rows, cols, tile in _tiles(volume):
            _label_tile(scene, tile, out[:, rows, cols], gl, slab_bytes)
        return LabelVolume(out, volume)
    finally:
        if owns:
            gl.release()


def _with_fractions(scene, volume, k, labels, dtype, gl, slab_bytes) -> LabelVolume:
    """Labels on the k-times finer grid, slab of coarse slices by slab, averaged per label."""
    nz, ny, nx = volume.shape
    classes = [0, *labels]
    lookup = np.zeros(classes[-1] + 1, np.uint16)  # label -> class index, small to map whole slabs
    lookup[classes] = np.arange(len(classes))
    shares = np.zeros((len(classes), nz, ny, nx), np.float32)
    step = max(1, slab_bytes // (k**3 * ny * nx * np.dtype(dtype).itemsize))  # coarse slices at a time
    for k0 in range(0, nz, step):
        count = min(step, nz - k0)
        centre_z = volume.axis_centres(0)[k0 : k0 + count].mean()
        fine = VolumeGeometry((count * k, ny * k, nx * k), tuple(v / k for v in volume.voxel_size),
                              (centre_z, *volume.offset[1:]))
        sub = np.zeros(fine.shape, dtype)
        for rows, cols, tile in _tiles(fine):
            _label_tile(scene, tile, sub[:, rows, cols], gl, slab_bytes)
        index = lookup[sub].reshape(count, k, ny, k, nx, k)
        for c in range(len(classes)):
            shares[c, k0 : k0 + count] = (index == c).mean(axis=(1, 3, 5), dtype=np.float32)
    majority = np.asarray(classes, dtype)[np.argmax(shares, axis=0)]
    return LabelVolume(majority, volume, tuple(classes), shares)


def _tiles(volume: VolumeGeometry):
    """(row slice, column slice, sub-volume) tiles of at most TILE_COLUMNS² voxel columns."""
    nz, ny, nx = volume.shape
    for j0 in range(0, ny, TILE_COLUMNS):
        for i0 in range(0, nx, TILE_COLUMNS):
            tj, ti = min(TILE_COLUMNS, ny - j0), min(TILE_COLUMNS, nx - i0)
            y = volume.axis_centres(1)[j0 : j0 + tj].mean()
            x = volume.axis_centres(2)[i0 : i0 + ti].mean()
            yield slice(j0, j0 + tj), slice(i0, i0 + ti), VolumeGeometry((nz, tj, ti), volume.voxel_size, (volume.offset[0], y, x))


def _label_tile(scene: Scene, volume: VolumeGeometry, out: np.ndarray, gl: GLContext, slab_bytes: int) -> None:
    """Labels of one tile into ``out`` (z, y, x), zero-filled by the caller."""
    nz, ny, nx = volume.shape
    per_word = 4 if out.dtype == np.uint8 else 2
    lo, hi = scene.bounds[:, 2]
    z = volume.axis_centres(0)
    first, last = int(np.searchsorted(z, lo, "left")), int(np.searchsorted(z, hi, "right"))  # slices the scene reaches
    if first >= last:
        return
    slices = max(per_word, (slab_bytes // (4 * ny * nx)) * per_word)  # a multiple of per_word
    box_lo, box_hi = volume.bounds
    # An object beside the tile, or wholly above or below it, adds no crossing that counts.
    def outside(o) -> bool:
        return bool(np.any(o.mesh.bounds[0] > box_hi) or np.any(o.mesh.bounds[1] < box_lo))

    engine = CrossingEngine(column_geometry(volume), gl)
    with gl.current():
        try:
            uploaded = engine.upload(scene)
            words = engine.scratch("output", 4 * ny * nx * (slices // per_word))
            with engine.record_lists(uploaded, 0, engine.object_table(uploaded, 0, skip=outside)) as lists:
                t_first = float(z[0] - lists.ref[2])  # t of slice 0, mm from the rays' origin plane
                for k0 in range(first, last, slices):
                    count = min(slices, last - k0)
                    padded = -(-count // per_word) * per_word
                    lists.resolve("voxelize_resolve.comp", {"LABELS_PER_WORD": per_word}, {
                        "u_size": (nx, ny), "u_t0": t_first + k0 * volume.voxel_size[0], "u_dt": volume.voxel_size[0],
                        "u_slices": padded}, {"output": words})
                    raw = np.frombuffer(words.read(size=4 * ny * nx * padded // per_word), np.uint32)
                    unpacked = raw.view(out.dtype).reshape(padded // per_word, ny, nx, per_word)
                    out[k0 : k0 + count] = unpacked.transpose(0, 3, 1, 2).reshape(padded, ny, nx)[:count]
        finally:
            engine.release()
