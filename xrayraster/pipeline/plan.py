"""A scan's up-front plan (:class:`ScanJob`): its time and memory from the scan file alone, before
the sample is meshed; stages pass it through :func:`~xrayraster.core.estimate.plan`, the key in a
refusal after the file's path.

Memory: the parts that grow with the file's keys (:class:`~xrayraster.core.estimate.Part`): the
views' geometry, the sample's meshes (a weave's triangles estimated from every key that multiplies
them: its yarns a cell, spacings, cells and mesh knobs, :mod:`~xrayraster.weave.size`), one batch of
projections, the filtered views the FDK gathers for a pass over the volume, the volume and the
labels. A preview's frame (:class:`FrameJob`) is the same sample and one view. Time: the sample's meshing, the
projections (:mod:`~xrayraster.simulate.estimate`), the FDK's backprojection (per voxel and view)
and the labels (per voxel). The FDK's and the labels' rates come from the full twin on the
development machine (801 views into 512³ voxels: FDK 119.5 s, labels 1.4 s, docs/twin.md) and are
right to an order of magnitude.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.estimate import Estimate, Part
from ..core.geometry import BYTES_PER_VIEW
from ..io.scan_file import ScanFile
from ..recon.fdk_plan import MAX_BATCH_VIEWS
from ..simulate.estimate import seconds_per_view
from ..weave.size import SECONDS_PER_TRIANGLE as MESH_SECONDS_PER_TRIANGLE
from ..weave.size import estimated_triangles, mesh_part

SECONDS_PER_VOXEL_VIEW = 1.6e-10  # FDK: 15.1-17.9 s / (801 views × 512³ voxels), the twin on 2 cores, 2026-11-27
SECONDS_PER_VOXEL_LABEL = 1.4e-8  # labels: 1.4 s / 512³ (1.9 s in bench_voxelize)
#: Bytes a triangle of the scanned scene holds: the meshes, the scene's placed copies and the GL
#: upload. The twin's 1,260 MiB peak less its volume, labels, one batch and the 347 MiB of a tiny
#: scan (the libraries, GL and OpenCL) leaves ~240 MiB for its 700 k triangles: ~360 B, rounded up.
BYTES_PER_SCENE_TRIANGLE = 400
#: A detector pixel of a view in flight: the line integrals and the radiograph's float64 temporaries.
BYTES_PER_BATCH_PIXEL = 4 + 3 * 8
#: A detector pixel of a filtered view waiting for the backprojection: float32, up to twice as wide
#: (a displaced detector's virtual columns).
BYTES_PER_FILTERED_PIXEL = 2 * 4
#: The filtered views a scan's FDK gathers before each pass over the volume (``FDKStream``'s
#: ``batch_views``): 128 MiB of views (at least a batch of rendered ones; at most the FDK's 256).
#: Each pass reads and writes the whole volume: into the twin's 512³, passes of 128 views
#: backprojected 5.24 G voxel updates/s against 4.19 in passes of 32 (BENCHMARKS.md; 256: no more).
FDK_BATCH_BYTES = 2**27


def fdk_batch_views(detector_shape: tuple[int, int], batch_views: int) -> int:
    """Views per backprojection pass of a scan rendering ``batch_views`` at a time (:data:`FDK_BATCH_BYTES`)."""
    rows, cols = detector_shape
    return min(MAX_BATCH_VIEWS, max(batch_views, FDK_BATCH_BYTES // (rows * cols * 4)))


@dataclass(frozen=True)
class ScanJob:
    """``xr.scan(loaded)``, rendering and filtering ``batch_views`` views at a time: a
    :class:`~xrayraster.core.estimate.Planned` job, sized from the scan file alone."""

    loaded: ScanFile
    batch_views: int

    def estimate(self) -> Estimate:
        loaded, batch_views = self.loaded, self.batch_views
        geometry, volume = loaded.geometry, loaded.volume
        views, (rows, cols) = geometry.num_views, geometry.detector_shape
        nz, ny, nx = volume.shape
        voxels = nz * ny * nx
        shape = f"[volume] shape = {list(volume.shape)}"
        grid_fix = "use a coarser grid (shape, voxel_size) or a part of it (offset)"
        sample, triangles, meshing = _sample_plan(loaded)
        filtered = min(views, fdk_batch_views((rows, cols), batch_views))
        parts = (
            Part("views' geometry", views * BYTES_PER_VIEW, f"[geometry] num_views = {views}", "use fewer views"),
            *sample,
            Part(f"a batch of {batch_views} views", min(views, batch_views) * rows * cols * BYTES_PER_BATCH_PIXEL,
                 f"[geometry] detector_shape = {[rows, cols]}", "use fewer detector pixels"),
            Part(f"{filtered} filtered views", filtered * rows * cols * BYTES_PER_FILTERED_PIXEL,
                 f"[geometry] detector_shape = {[rows, cols]}", "use fewer detector pixels"),
            Part("float32 volume", voxels * 4, shape, grid_fix),
            Part("labels", voxels, shape, grid_fix),
        )
        seconds = (meshing + views * seconds_per_view(rows * cols, triangles)
                   + views * voxels * SECONDS_PER_VOXEL_VIEW + voxels * SECONDS_PER_VOXEL_LABEL)
        return Estimate(f"scan of {views} views into {nz}×{ny}×{nx} voxels", seconds, parts)


@dataclass(frozen=True)
class FrameJob:
    """One view of a scan or scene file (``loaded``: a ScanFile or SceneFile), as the preview renders
    it: the sample meshed (or the objects), and one view's pixels in flight. A
    :class:`~xrayraster.core.estimate.Planned` job."""

    loaded: object

    def estimate(self) -> Estimate:
        rows, cols = self.loaded.geometry.detector_shape
        sample, triangles, meshing = _sample_plan(self.loaded)
        view = Part(f"a view of {rows}×{cols} pixels", rows * cols * BYTES_PER_BATCH_PIXEL,
                    f"[geometry] detector_shape = {[rows, cols]}", "use fewer detector pixels")
        return Estimate(f"frame of {rows}×{cols} pixels", meshing + seconds_per_view(rows * cols, triangles),
                        (*sample, view))


def _sample_plan(loaded) -> tuple[tuple[Part, ...], int, float]:
    """What the sample (a weave's meshes, estimated before meshing, or the objects as loaded) and
    the mount add to a plan: their parts, their triangles, and the seconds to mesh them."""
    weave, mount = getattr(loaded, "weave", None), getattr(loaded, "mount", None)
    if weave is not None:
        triangles = estimated_triangles(weave.sample)
        meshes = mesh_part(weave.sample, BYTES_PER_SCENE_TRIANGLE, tables=True)
        meshing = triangles * MESH_SECONDS_PER_TRIANGLE
    else:
        triangles = loaded.scene.num_triangles
        meshes = Part(f"meshes of {triangles} triangles", triangles * BYTES_PER_SCENE_TRIANGLE, "[[objects]] mesh",
                      "use coarser meshes")
        meshing = 0.0
    mounted = mount.num_triangles if mount is not None else 0
    parts = (meshes, Part(f"mount of {mounted} triangles", mounted * BYTES_PER_SCENE_TRIANGLE, "[[mount]] mesh",
                          "use coarser meshes"))
    return parts, triangles + mounted, meshing
