"""VTK's stencil voxelizer (``vtkPolyDataToImageStencil``) as a benchmark peer for ``xr.voxelize``.

``vtk_voxelize(scene, volume)`` turns every object of a scene into a binary mask on exactly our
voxel grid with VTK, then combines the masks into a label volume with our overlap rule, so its
output can be compared voxel by voxel (and timed) against ``xr.voxelize(scene, volume)``.

Grid mapping (our VolumeGeometry -> VTK's image / stencil geometry, mm)
---------------------------------------------------------------------
Ours: array (z, y, x), shape (nz, ny, nx), voxel_size (vz, vy, vx), offset (oz, oy, ox); the
centre of voxel (k, j, i) is ((i − (nx−1)/2)·vx + ox, (j − (ny−1)/2)·vy + oy, (k − (nz−1)/2)·vz + oz)
in the scanner frame (xrayraster/core/geometry.py).

VTK (vtkImageStencilSource / vtkImageData, identity direction): point (i, j, k) of the image is
at origin + (i·sx, j·sy, k·sz), indices over the whole extent (i0, i1, j0, j1, k0, k1). So

    SetOutputOrigin(−(nx−1)/2·vx + ox, −(ny−1)/2·vy + oy, −(nz−1)/2·vz + oz)   # centre of voxel (0, 0, 0)
    SetOutputSpacing(vx, vy, vz)
    SetOutputWholeExtent(0, nx−1, 0, ny−1, 0, nz−1)

and VTK's point (i, j, k) *is* our voxel centre (k, j, i). The mesh goes in as it is (placed
vertices in mm, same frame, float64 points, no axis swap). vtkImageData stores its scalars with
x fastest, then y, then z, so the flat scalar array reshaped to (nz, ny, nx) is our (z, y, x)
array with no transpose or flip.

What VTK's stencil does (read from VTK's sources and docstrings, Imaging/Stencil/
vtkPolyDataToImageStencil.cxx and Imaging/Core/vtkImageStencilData.cxx, vtkImageStencilRaster)
-----------------------------------------------------------------------------------------------
For every z slice of the extent (single-threaded: ``RequestData`` calls ``ThreadedExecute``
from one thread, and every slice loops over *all* triangles, so the cost is
O(triangles × slices)):

1. cut the surface with the plane z = slice centre: each triangle with vertices on both sides
   (a vertex counts as above when z_vertex − z > 0) gives one segment; the segments form the
   cross-section contours, in continuous voxel-index coordinates;
2. join loose ends (there are none for a closed mesh);
3. rasterise every contour edge at the integer y rows it spans (voxel-centre rows), storing the
   x crossing of each row, a scan-line polygon fill;
4. per row, sort the x crossings and pair them (even–odd rule): the voxels whose x index lies
   in each span [x1 − tol, x2 + tol] are inside.

The tolerance (``SetTolerance``, a fraction of a voxel, clamped to [0, 1]) is "the tolerance
for including a voxel inside the stencil ... only applied in the x and y directions, not in z.
Setting the tolerance to zero disables all tolerance checks": each span is widened by ``tol``
at both ends, and each edge is rasterised twice, with its y end points moved by −tol and +tol
(a "double pattern" whose spans are merged), so voxel centres within ``tol`` voxels of the
contour in x or y are counted inside: a bias towards inside, not a symmetric rounding. VTK
9.x defaults to 2⁻¹⁷ ≈ 7.6e-6 voxel (VTK 5.x used 1e-3). ``vtk_voxelize`` keeps VTK's default
unless ``tolerance`` is given. Differences from ``xr.voxelize`` are therefore confined to voxel
centres within ~tol of a surface (and to exact ties on a surface, where the two codes use
different conventions): VTK intersects in float64, our renderer in float32.

Overlaps: VTK has no priorities. Each object gets its own stencil and mask; masks are painted
into the label volume in increasing (priority, insertion order), later ones overwriting, which
is our rule (highest priority owns the space, ties go to the object added later).

Timing: ``seconds`` is the wall time of the VTK work for all objects: building the vtkPolyData
(numpy -> VTK copies included), the stencil, vtkImageStencilToImage and the numpy view of its
scalars. ``combine_seconds`` is the painting of the masks into the label volume (numpy), and
``total_seconds`` the sum: the end-to-end label volume, what ``xr.voxelize`` returns.

Self-check: ``python -m scripts.peers.vtk_peer`` voxelizes a small off-centre scene (a rotated box and
a higher-priority sphere overlapping it) on an anisotropic, offset grid with both codes, prints
the fraction of voxels that agree and how far from a surface the disagreeing voxel centres are,
and exits non-zero if fewer than 99 % agree, if any disagreement lies more than a voxel from a
surface, or if the objects' centroids differ by more than 0.1 voxel (a wrong axis order or
flip moves them by many voxels). Controls: VTK's labels mirrored along each axis must agree
less (they do: ~90 %), and with the tolerance raised to 0.3 voxel every disagreement must lie
within 0.3·hypot(vx, vy) of a surface (the reach of VTK's x/y tolerance).
"""

from __future__ import annotations

import sys
import time

import numpy as np

import xrayraster as xr

__all__ = ["vtk_available", "vtk_voxelize", "vtk_grid"]


def vtk_available() -> str | None:
    """None if VTK (``pip install vtk``) imports with the stencil modules we use, else the reason."""
    try:
        import vtkmodules.vtkCommonCore  # noqa: F401
        import vtkmodules.vtkCommonDataModel  # noqa: F401
        import vtkmodules.vtkImagingStencil  # noqa: F401
        from vtkmodules.util import numpy_support  # noqa: F401
    except Exception as exc:  # ImportError, or a broken binary wheel (OSError)
        return f"vtk not importable ({type(exc).__name__}: {exc}); pip install vtk"
    return None


def vtk_version() -> str | None:
    try:
        from vtkmodules.vtkCommonCore import vtkVersion

        return vtkVersion.GetVTKVersion()
    except Exception:
        return None


def vtk_grid(volume: xr.VolumeGeometry) -> dict:
    """VTK origin (x, y, z) mm, spacing (x, y, z) mm and whole extent of our voxel grid.

    The origin is the centre of voxel (0, 0, 0), so VTK's point (i, j, k) is our voxel (k, j, i).
    """
    nz, ny, nx = volume.shape
    vz, vy, vx = volume.voxel_size
    origin = tuple(float(volume.axis_centres(axis)[0]) for axis in (2, 1, 0))
    return {"origin": origin, "spacing": (float(vx), float(vy), float(vz)), "extent": (0, nx - 1, 0, ny - 1, 0, nz - 1)}


def _polydata(vertices: np.ndarray, faces: np.ndarray):
    """A vtkPolyData of triangles from (n, 3) mm vertices and (m, 3) faces (float64 points: no rounding)."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    points = vtkPoints()
    points.SetDataTypeToDouble()
    points.SetData(numpy_support.numpy_to_vtk(np.ascontiguousarray(vertices, np.float64), deep=True))
    ids = np.dtype(numpy_support.get_vtk_to_numpy_typemap()[numpy_support.VTK_ID_TYPE])  # int64 in 64-bit builds
    offsets = np.arange(0, 3 * len(faces) + 1, 3, dtype=ids)  # VTK ≥ 9 cell array: offsets + connectivity
    connectivity = np.ascontiguousarray(faces, dtype=ids).ravel()
    cells = vtkCellArray()
    cells.SetData(numpy_support.numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_support.numpy_to_vtkIdTypeArray(connectivity, deep=True))
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(cells)
    return poly


def vtk_mask(vertices: np.ndarray, faces: np.ndarray, volume: xr.VolumeGeometry, *,
             tolerance: float | None = None) -> np.ndarray:
    """(z, y, x) bool: voxel centres of ``volume`` inside the closed mesh, by VTK's stencil."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkImagingStencil import vtkImageStencilToImage, vtkPolyDataToImageStencil

    grid = vtk_grid(volume)
    stencil = vtkPolyDataToImageStencil()
    stencil.SetInputData(_polydata(vertices, faces))
    stencil.SetOutputOrigin(*grid["origin"])
    stencil.SetOutputSpacing(*grid["spacing"])
    stencil.SetOutputWholeExtent(*grid["extent"])
    if tolerance is not None:
        stencil.SetTolerance(tolerance)
    image = vtkImageStencilToImage()
    image.SetInputConnection(stencil.GetOutputPort())
    image.SetInsideValue(1)
    image.SetOutsideValue(0)
    image.SetOutputScalarTypeToUnsignedChar()
    image.Update()
    out = image.GetOutput()
    dims = out.GetDimensions()  # (nx, ny, nz)
    if tuple(dims) != tuple(volume.shape[::-1]):
        raise RuntimeError(f"VTK stencil image has dimensions {dims}, expected {volume.shape[::-1]} (x, y, z)")
    flat = numpy_support.vtk_to_numpy(out.GetPointData().GetScalars())
    # x fastest, then y, then z: reshaped C-order (z, y, x) is our array. view(bool) keeps it a
    # view of VTK's buffer; the copy makes it independent of the VTK objects that die here.
    return flat.reshape(volume.shape).view(bool).copy()


def vtk_voxelize(scene: xr.Scene, volume: xr.VolumeGeometry, *, tolerance: float | None = None) -> dict:
    """Label volume of ``scene`` on ``volume`` by VTK's stencil, combined by our priority rule.

    Returns {"labels": uint8/uint16 (z, y, x), "seconds": VTK wall time for all objects (polydata
    built, stencils, stencil-to-image, numpy conversion), "per_object_seconds": [s per object,
    insertion order], "combine_seconds": s to paint the masks by priority, "total_seconds": the
    sum, "tolerance": the stencil tolerance used (fraction of a voxel)}.
    """
    scene.require_objects()
    top = max(o.label for o in scene.objects)
    labels = np.zeros(volume.shape, np.uint8 if top < 256 else np.uint16)
    per_object, combine = [0.0] * len(scene.objects), 0.0
    used = tolerance
    for obj in sorted(scene.objects, key=lambda o: o.rank):  # lowest first: later paint wins
        t0 = time.perf_counter()
        mask = vtk_mask(obj.mesh.vertices, obj.mesh.faces, volume, tolerance=tolerance)
        t1 = time.perf_counter()
        np.copyto(labels, labels.dtype.type(obj.label), where=mask)
        combine += time.perf_counter() - t1
        per_object[obj.order] = t1 - t0
        del mask
    if used is None:
        from vtkmodules.vtkImagingStencil import vtkPolyDataToImageStencil

        used = vtkPolyDataToImageStencil().GetTolerance()
    seconds = sum(per_object)
    return {"labels": labels, "seconds": seconds, "per_object_seconds": per_object,
            "combine_seconds": combine, "total_seconds": seconds + combine, "tolerance": used}


# ---------------------------------------------------------------------------------------------
# Self-check
# ---------------------------------------------------------------------------------------------


def _compare(scene, volume, ours, theirs, title: str, *, max_mm: float, check_agreement: bool = True) -> bool:
    """Print agreement, label centroids and how far (mm) from a surface disagreements lie; False on failure."""
    import trimesh

    ok = True
    agree = float(np.mean(ours == theirs))
    occupied = (ours > 0) | (theirs > 0)
    agree_occ = float(np.mean(ours[occupied] == theirs[occupied]))
    labels = sorted({o.label for o in scene.objects})
    counts = {lab: (int((ours == lab).sum()), int((theirs == lab).sum())) for lab in labels}
    print(f"[{title}] agreement: {agree:.4%} of {ours.size} voxels; {agree_occ:.4%} of the {int(occupied.sum())} "
          f"voxels either code labels; voxels per label (ours, VTK): {counts}")
    if check_agreement and agree < 0.99:
        print("FAIL: fewer than 99 % of voxels agree")
        ok = False

    # Centroids per label in mm: the mapping check that does not depend on surface conventions.
    axes = [volume.axis_centres(a) for a in range(3)]
    for lab in labels:
        cz = [np.array([np.mean(axes[a][np.nonzero(vol == lab)[a]]) for a in range(3)]) for vol in (ours, theirs)]
        shift = np.abs(cz[0] - cz[1]) / np.array(volume.voxel_size)
        print(f"[{title}] label {lab}: centroid (z, y, x) ours {np.round(cz[0], 4)} mm, VTK {np.round(cz[1], 4)} mm, "
              f"|Δ| {np.round(shift, 4)} voxels")
        if np.any(shift > 0.1):
            print(f"FAIL: label {lab} centroids differ by more than 0.1 voxel")
            ok = False

    # Every disagreement must be a voxel centre at a surface.
    bad = np.argwhere(ours != theirs)
    if len(bad):
        centres = np.stack([axes[2][bad[:, 2]], axes[1][bad[:, 1]], axes[0][bad[:, 0]]], axis=1)
        dist = np.full(len(bad), np.inf)
        for obj in scene.objects:
            mesh = trimesh.Trimesh(obj.mesh.vertices, obj.mesh.faces, process=False)
            dist = np.minimum(dist, np.abs(trimesh.proximity.signed_distance(mesh, centres)))
        print(f"[{title}] {len(bad)} disagreeing voxels; their centres lie within {dist.max():.3e} mm of a surface "
              f"(allowed {max_mm:.3e} mm); median {np.median(dist):.3e} mm")
        if dist.max() > max_mm:
            print(f"FAIL: a disagreement lies more than {max_mm:.3e} mm from every surface")
            ok = False
    else:
        print(f"[{title}] no disagreeing voxels")
    return ok


def _self_check() -> int:
    import trimesh

    reason = vtk_available()
    if reason:
        print(f"VTK unavailable: {reason}")
        return 2
    # Anisotropic voxels, a non-cubic grid and an offset on every axis: a swapped axis, a flip or
    # a half-voxel shift of the origin all show as thousands of disagreeing voxels.
    volume = xr.VolumeGeometry((40, 48, 56), (0.25, 0.2, 0.15), offset=(0.3, -0.4, 0.2))
    rot = (xr.Transform.rotation((0, 0, 1), np.radians(50)) @ xr.Transform.rotation((0, 1, 0), np.radians(35))
           @ xr.Transform.rotation((1, 0, 0), np.radians(20)))
    box_place = xr.Transform.translation((1.1, -0.9, 0.6)) @ rot
    ball_place = xr.Transform.translation((2.4, 0.3, 1.8))
    box = trimesh.creation.box((4.5, 3.0, 2.2))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=1.8)
    scene = xr.Scene()
    scene.add(box, "a", label=1, priority=0, transform=box_place, name="box")
    scene.add(ball, "b", label=2, priority=1, transform=ball_place, name="ball")

    print(f"VTK {vtk_version()}; grid {volume.shape} (z, y, x), voxel {volume.voxel_size} mm, offset {volume.offset} mm")
    print(f"VTK grid: {vtk_grid(volume)}")
    peer = vtk_voxelize(scene, volume)
    ours = xr.voxelize(scene, volume).data
    theirs = peer["labels"]
    print(f"VTK: {peer['total_seconds']:.3f} s (stencils {peer['seconds']:.3f} s, per object "
          f"{', '.join(f'{s:.3f}' for s in peer['per_object_seconds'])}; combine {peer['combine_seconds']:.4f} s), "
          f"tolerance {peer['tolerance']:.3g} voxel")

    ok = _compare(scene, volume, ours, peer["labels"], "default tolerance", max_mm=min(volume.voxel_size))

    # Negative controls: the same comparison with VTK's array mirrored along one axis must fail
    # clearly, or the agreement above would prove nothing about the mapping.
    theirs = peer["labels"]
    for axis, name in enumerate("zyx"):
        mirrored = float(np.mean(ours == np.flip(theirs, axis)))
        print(f"control: VTK mirrored along {name}: agreement {mirrored:.2%}")
        if mirrored >= 0.99:
            print(f"FAIL: a mirror along {name} still agrees: the scene does not test the mapping")
            ok = False
    # A large tolerance: VTK then counts voxel centres up to `tol` voxels outside a contour in x
    # and in y as inside, so every disagreement must lie within tol·hypot(vx, vy) of a surface.
    tol = 0.3
    wide = vtk_voxelize(scene, volume, tolerance=tol)
    reach = tol * float(np.hypot(volume.voxel_size[2], volume.voxel_size[1]))
    ok &= _compare(scene, volume, ours, wide["labels"], f"tolerance {tol}", max_mm=reach * 1.001, check_agreement=False)
    print("self-check:", "PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(_self_check())
