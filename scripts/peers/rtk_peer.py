"""RTK's CPU FDK (``itk-rtk`` on PyPI) as a benchmark peer for xrayraster's FDK.

``rtk_fdk(projections, geometry, volume)`` reconstructs our line-integral projections with
``rtk.FDKConeBeamReconstructionFilter`` on exactly our voxel grid, so its output can be
compared voxel by voxel (and timed) against our own FDK run on the same inputs.

Geometry mapping (our scanner frame -> RTK's fixed frame, mm)
-------------------------------------------------------------
Ours: rotation axis z; at view angle θ the source is at R_z(θ)·(0, −SOD, 0), the detector
centre at R_z(θ)·(0, SDD − SOD, 0) + ou·û + ov·v̂, columns step along û = R_z(θ)·(1, 0, 0) and
rows along v̂ = (0, 0, 1) (see xrayraster/core/geometry.py).

RTK (ThreeDCircularProjectionGeometry, documentation/docs/Geometry.md and
rtkFDKWeightProjectionFilter.hxx): rotation axis y; with gantry angle g the source is at
R_y(g)·(0, 0, SID) and a detector point with projection-image coordinates (pu, pv) (from the
projection image's origin/spacing, identity direction) is at
R_y(g)·(pu + ProjectionOffsetX, pv + ProjectionOffsetY, SID − SDD), so the detector's
x axis is R_y(g)·(1, 0, 0) and its y axis (0, 1, 0).

The proper rotation P: (x, y, z)_ours -> (x, z, −y)_RTK maps one onto the other exactly:

    P·source_ours(θ)   = (SOD sin θ, 0, SOD cos θ)  = RTK source with g = θ
    P·û(θ)             = (cos θ, 0, −sin θ)         = RTK detector x axis, g = θ
    P·v̂                = (0, 1, 0)                  = RTK detector y axis

hence ``AddProjection(SID=SOD, SDD=SDD, gantryAngle=degrees(θ), ProjectionOffsetX=ou,
ProjectionOffsetY=ov, 0, 0, SourceOffsetX=su, SourceOffsetY=sv)`` (our source offset (sv, su)
moves the source along v̂ and û as RTK's moves it along its detector's y and x axes) with no flip
of detector rows or columns and no change of rotation direction. Projection stack: our (views, rows, cols) array is used as is (ITK index (col, row,
view)), spacing (pixel_col, pixel_row, 1), origin (−(ncol−1)/2·pixel_col, −(nrow−1)/2·pixel_row,
0), identity direction (the FDK weighting reads detector coordinates straight from the image
origin/spacing, so the projection direction must stay identity); the detector offset goes into
ProjectionOffsetX/Y, where RTK's cosine weight expects it.

Volume: RTK's grid (identity direction, ITK axes X, Y, Z = our x, z, −y) has ITK size
(nx, nz, ny), spacing (vx, vz, vy) and origin (the centre of the first voxel)
(−(nx−1)/2·vx + ox, −(nz−1)/2·vz + oz, −(ny−1)/2·vy − oy). Its numpy array (ny, nz, nx) is
turned into ours (z, y, x) by ``transpose(1, 0, 2)[:, ::-1, :]`` (RTK's Z index k is our y
index ny − 1 − k).

Units: projections are ∫μ dl (dimensionless, μ in mm⁻¹, lengths in mm), so RTK's FDK returns
μ in mm⁻¹. Filtering: RTK's ramp filter (FFTRampImageFilter) with no window ("ram-lak") or a
Hann window along each detector row (the column index, u) only, ``SetHannCutFrequency(cutoff)``
(RTK's second window, SetHannCutFrequencyY across rows, is left off): the gain
0.5·(1 + cos(π·i/ncut)) over the first ncut = round(n·cutoff) of the n half-spectrum bins,
i.e. cutoff is a fraction of the Nyquist frequency, zero above it. RTK's FDK applies no short
scan (Parker) weights: give it a full circle (its angular weights are the gaps between
neighbouring views, so uneven full-circle sampling is fine).

Threads: ITK's global thread settings (itk.MultiThreaderBase) are process-wide; rtk_fdk sets
them to ``threads`` before building its filters, and they stay so afterwards.

Verified by ``python -m scripts.peers.rtk_peer`` (exits non-zero on any failure):
* RTK's own source positions and pixel positions (GetSourcePosition,
  GetProjectionCoordinatesToFixedSystemMatrix), mapped back through Pᵀ, equal ours to ~1e-13 mm
  for several views with and without a detector offset;
* FDK of exact float64 chord-length projections of a centred uniform sphere: mean over the
  inner half radius within 0.5 % of the true μ;
* FDK of an off-centre sphere at (x, y, z) = (3, −2, 1.5) mm: centroid within 0.25 voxel of the
  truth (a wrong flip, axis order or rotation direction moves it by many voxels);
* the same two checks with the detector shifted along columns (and along rows); with the
  offset's sign reversed nothing is left above μ/2 (checked by hand), with the angle's sign
  reversed the sphere lands at y = +2 mm;
* the off-centre sphere on a shifted, non-cubic grid of anisotropic voxels (axis order and
  grid origin);
* window="hann" keeps the interior value; an unknown window raises ValueError.
The same script prints RTK's timings for 128³ voxels from 180 views of 128² pixels.

RTK pipeline used: FDKConeBeamReconstructionFilter alone (cosine/angular weighting, ramp filter,
voxel-driven backprojection), 16 projections per pass as in RTK's rtkfdk application, no
truncation padding; none of rtkfdk's DisplacedDetectorImageFilter or Parker short-scan
weighting, so keep the object inside every projection (an offset detector that does not
cover the whole object would need RTK's displaced-detector weights).
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from xrayraster import ConeBeamGeometry, VolumeGeometry

_itk = None            # the itk module once RTK imported
_rtk = None            # itk.RTK
_import_error = None   # reason string if the import failed

# Rotation from our frame to RTK's fixed frame: (x, y, z) -> (x, z, -y) (see module docstring).
_P = np.array([[1.0, 0.0, 0.0],
               [0.0, 0.0, 1.0],
               [0.0, -1.0, 0.0]])


def _init():
    global _itk, _rtk, _import_error
    if _itk is not None or _import_error is not None:
        return
    try:
        import itk
        from itk import RTK as rtk
        rtk.ThreeDCircularProjectionGeometry.New()   # forces itk's lazy loader to load RTK
        _itk, _rtk = itk, rtk
    except Exception as exc:  # ImportError, missing wheel for this platform, ...
        _import_error = f"{type(exc).__name__}: {exc}"


def rtk_available() -> str | None:
    """None if ``itk`` with RTK (pip ``itk-rtk``) imports, else the reason (first call ~15 s)."""
    _init()
    return _import_error


def _rtk_geometry(geometry: ConeBeamGeometry):
    """RTK ThreeDCircularProjectionGeometry equal to our circular cone-beam geometry."""
    g = _rtk.ThreeDCircularProjectionGeometry.New()
    (ov, ou), (sv, su) = geometry.detector_offset, geometry.source_offset
    for theta in geometry.angles:
        g.AddProjection(float(geometry.source_to_origin), float(geometry.source_to_detector),
                        math.degrees(theta), float(ou), float(ov), 0.0, 0.0, float(su), float(sv))
    return g


def rtk_fov_mask(geometry: ConeBeamGeometry, volume: VolumeGeometry) -> np.ndarray:
    """RTK's field of view on our grid, bool ``(z, y, x)``: the voxels ``rtk.FieldOfViewImageFilter``
    keeps (those its geometry says every projection sees), as RTK's functional tests mask their
    reconstructions before scoring them."""
    _init()
    if _import_error is not None:
        raise RuntimeError(f"RTK unavailable: {_import_error}")
    image_type = _itk.Image[_itk.F, 3]
    size, origin, spacing = _volume_origin_spacing(volume)
    ones = _image(np.ones(size[::-1], np.float32), origin, spacing)
    stack = _image(np.zeros((geometry.num_views, *geometry.detector_shape), np.float32),
                   *_projection_origin_spacing(geometry))
    fov = _rtk.FieldOfViewImageFilter[image_type, image_type].New()
    fov.SetInput(0, ones)
    fov.SetProjectionsStack(stack)
    fov.SetGeometry(_rtk_geometry(geometry))
    fov.Update()
    out = _itk.array_view_from_image(fov.GetOutput())  # (ny, nz, nx): RTK (Z, Y, X)
    return np.ascontiguousarray(out.transpose(1, 0, 2)[:, ::-1, :]) > 0.5


def _projection_origin_spacing(geometry: ConeBeamGeometry):
    """ITK (x=col, y=row, z=view) origin and spacing (mm) of the projection stack, offset excluded."""
    (nr, nc), (pv, pu) = geometry.detector_shape, geometry.pixel_size
    return (-(nc - 1) / 2 * pu, -(nr - 1) / 2 * pv, 0.0), (pu, pv, 1.0)


def _volume_origin_spacing(volume: VolumeGeometry):
    """ITK size, origin (first voxel centre) and spacing (mm) of RTK's grid: ITK axes = our (x, z, −y)."""
    (nz, ny, nx), (vz, vy, vx), (oz, oy, ox) = volume.shape, volume.voxel_size, volume.offset
    size = (nx, nz, ny)
    origin = (-(nx - 1) / 2 * vx + ox, -(nz - 1) / 2 * vz + oz, -(ny - 1) / 2 * vy - oy)
    return size, origin, (vx, vz, vy)


def _image(array: np.ndarray, origin, spacing):
    img = _itk.image_from_array(np.ascontiguousarray(array, dtype=np.float32))
    img.SetOrigin([float(o) for o in origin])
    img.SetSpacing([float(s) for s in spacing])
    return img


def rtk_fdk(projections: np.ndarray, geometry: ConeBeamGeometry, volume: VolumeGeometry, *,
            threads: int = 2, window: str = "ram-lak", cutoff: float = 1.0, displaced: bool = False,
            truncation: float = 0.0) -> dict:
    """Reconstruct with RTK's CPU FDK on our voxel grid.

    projections: float32 ``(views, rows, cols)`` line integrals ∫μ dl (dimensionless, μ in mm⁻¹).
    geometry: our circular cone-beam geometry (mm, radians), a full circle of views.
    volume: our voxel grid.
    threads: ITK thread count (process-wide global setting, see module docstring).
    window: "ram-lak" (plain ramp) or "hann" (Hann window along each detector row, cut off at
        ``cutoff`` × Nyquist, 0 < cutoff ≤ 1).
    displaced: weight the projections with RTK's DisplacedDetectorImageFilter first (Wang's
        weights on a virtual detector padded on the short side), as RTK's own
        rtkdisplaceddetectortest does; it leaves a detector off-centre by < 10 % of its width alone.
    truncation: RTK's ramp-filter truncation correction (``SetTruncationCorrection``): rows are
        extended by this share of their width on each side with Ohnesorge's mirrored
        extrapolation; 0 = off (RTK's default).

    Returns {"volume": float32 ``(z, y, x)`` μ in mm⁻¹ on ``volume``'s grid, "seconds": wall time
    of the FDK filter's Update() (weighting, ramp filter, backprojection), "setup_seconds": wall
    time of everything else in this call (RTK geometry, ITK images from numpy, filter set-up,
    copy of the result back to our numpy layout)}.
    """
    if window not in ("ram-lak", "hann"):
        raise ValueError(f"window must be 'ram-lak' or 'hann', got {window!r}")
    if window == "hann" and not 0.0 < cutoff <= 1.0:
        raise ValueError(f"cutoff must be in (0, 1] (fraction of Nyquist), got {cutoff!r}")
    if not isinstance(geometry, ConeBeamGeometry):
        raise TypeError(f"geometry must be a ConeBeamGeometry, got {type(geometry).__name__}")
    shape = (geometry.num_views, *geometry.detector_shape)
    if np.shape(projections) != shape:
        raise ValueError(f"projections must have shape (views, rows, cols) = {shape}, "
                         f"got {np.shape(projections)}")
    _init()
    if _import_error is not None:
        raise RuntimeError(f"RTK unavailable: {_import_error}")
    itk, rtk = _itk, _rtk

    t0 = time.perf_counter()
    # Maximum first: ITK clamps the default to the maximum. Set before the filters are
    # created, since each filter takes its threader settings when it is constructed.
    itk.MultiThreaderBase.SetGlobalMaximumNumberOfThreads(int(threads))
    itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(int(threads))
    image_type = itk.Image[itk.F, 3]
    proj = _image(projections, *_projection_origin_spacing(geometry))
    size, origin, spacing = _volume_origin_spacing(volume)
    vol = _image(np.zeros(size[::-1], np.float32), origin, spacing)   # grid only, values unused
    rtk_geometry = _rtk_geometry(geometry)
    if displaced:
        weighted = rtk.DisplacedDetectorImageFilter[image_type].New()
        weighted.SetInput(proj)
        weighted.SetGeometry(rtk_geometry)
        proj = weighted.GetOutput()
    fdk = rtk.FDKConeBeamReconstructionFilter[image_type].New()
    fdk.SetInput(0, vol)
    fdk.SetInput(1, proj)
    fdk.SetGeometry(rtk_geometry)
    if truncation:
        fdk.GetRampFilter().SetTruncationCorrection(float(truncation))
    # 16 projections filtered and backprojected per pass, as RTK's own rtkfdk application does
    # (the filter's default here is 2; 128³ from 180 views: 1.4 s instead of 1.8 s on 2 threads).
    fdk.SetProjectionSubsetSize(16)
    if window == "hann":
        fdk.GetRampFilter().SetHannCutFrequency(float(cutoff))   # along u only
    setup = time.perf_counter() - t0

    t0 = time.perf_counter()
    fdk.Update()
    seconds = time.perf_counter() - t0

    t0 = time.perf_counter()
    out = itk.array_view_from_image(fdk.GetOutput())          # (ny, nz, nx): RTK (Z, Y, X)
    out = np.ascontiguousarray(out.transpose(1, 0, 2)[:, ::-1, :], dtype=np.float32)
    setup += time.perf_counter() - t0
    return {"volume": out, "seconds": seconds, "setup_seconds": setup}


# ----------------------------------------------------------------------------- self-check

def _source_and_pixels(geometry: ConeBeamGeometry, theta: float):
    """Our source (3,) and pixel centres (rows, cols, 3) in mm, written out from the convention."""
    (nr, nc), (pv, pu), (ov, ou) = geometry.detector_shape, geometry.pixel_size, geometry.detector_offset
    from references.chords import rot_z

    rot = rot_z(theta)
    sod, sdd = geometry.source_to_origin, geometry.source_to_detector
    u, v = rot @ (1.0, 0.0, 0.0), np.array([0.0, 0.0, 1.0])
    src = rot @ (0.0, -sod, 0.0) + geometry.source_offset[1] * u + geometry.source_offset[0] * v
    centre = rot @ (0.0, sdd - sod, 0.0) + ou * u + ov * v
    r = (np.arange(nr) - (nr - 1) / 2) * pv
    c = (np.arange(nc) - (nc - 1) / 2) * pu
    return src, centre + r[:, None, None] * v + c[None, :, None] * u


def _sphere_projections(geometry: ConeBeamGeometry, spheres) -> np.ndarray:
    """Exact float64 ∫μ dl of uniform spheres [(centre (x, y, z) mm, radius mm, μ mm⁻¹)]."""
    out = np.zeros((geometry.num_views, *geometry.detector_shape))
    for k, theta in enumerate(geometry.angles):
        src, pix = _source_and_pixels(geometry, theta)
        d = pix - src
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        for centre, radius, mu in spheres:
            w = np.asarray(centre, float) - src
            along = d @ w                                   # distance to the closest approach
            miss2 = w @ w - along ** 2                      # squared ray-centre distance
            out[k] += mu * 2.0 * np.sqrt(np.clip(radius ** 2 - miss2, 0.0, None))
    return out


def _check_mapping(geometry: ConeBeamGeometry) -> float:
    """Max distance (mm) between RTK's source/pixel positions (mapped to our frame) and ours."""
    g = _rtk_geometry(geometry)
    (nr, nc) = geometry.detector_shape
    origin, spacing = _projection_origin_spacing(geometry)
    cols, rows = np.meshgrid(np.arange(nc), np.arange(nr))
    pts = np.stack([origin[0] + cols * spacing[0], origin[1] + rows * spacing[1],
                    np.zeros_like(cols, float), np.ones_like(cols, float)], axis=-1)
    worst = 0.0
    for k, theta in enumerate(geometry.angles):
        src, pix = _source_and_pixels(geometry, theta)
        rtk_src = np.array(g.GetSourcePosition(k))[:3]
        m = _itk.array_from_matrix(g.GetProjectionCoordinatesToFixedSystemMatrix(k))
        rtk_pix = (pts @ m.T)[..., :3]
        worst = max(worst, np.abs(_P.T @ rtk_src - src).max(), np.abs(rtk_pix @ _P - pix).max())
    return worst


def _centroid(vol: np.ndarray, volume: VolumeGeometry, threshold: float) -> np.ndarray:
    """Value-weighted centroid (x, y, z) mm of the voxels above ``threshold``."""
    w = np.where(vol > threshold, vol, 0.0).astype(np.float64)
    z, y, x = (volume.axis_centres(a) for a in range(3))
    total = w.sum()
    if total <= 0:                 # nothing above threshold: a badly wrong reconstruction
        return np.full(3, np.nan)
    return np.array([(w.sum(axis=(0, 1)) @ x), (w.sum(axis=(0, 2)) @ y), (w.sum(axis=(1, 2)) @ z)]) / total


def _inner_mean(vol: np.ndarray, volume: VolumeGeometry, centre, radius: float) -> float:
    z, y, x = np.meshgrid(*(volume.axis_centres(a) for a in range(3)), indexing="ij")
    r2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
    return float(vol[r2 < radius ** 2].mean())


def _self_check() -> bool:
    ok = True

    def report(name, passed, text):
        nonlocal ok
        ok &= bool(passed)
        print(f"[{'PASS' if passed else 'FAIL'}] {name}: {text}")

    volume = VolumeGeometry(shape=(64, 64, 64), voxel_size=0.5)
    voxel = 0.5
    big = ((0.0, 0.0, 0.0), 10.0, 0.02)        # centred uniform sphere, μ = 0.02 mm⁻¹
    small = ((3.0, -2.0, 1.5), 4.0, 0.05)      # off-centre sphere (x, y, z) mm
    cases = [("no offset", 180, (0.0, 0.0)),
             ("col offset +12 mm", 180, (0.0, 12.0)),
             ("col offset -9 mm, row offset +3 mm", 90, (3.0, -9.0)),
             ("source offset (row +2, col +5) mm", 180, (0.0, 0.0), (2.0, 5.0))]
    for label, views, offset, *source in cases:
        geo = ConeBeamGeometry(source_to_origin=100.0, source_to_detector=200.0,
                               detector_shape=(64, 96), pixel_size=0.8,
                               angles=np.arange(views) * 2 * np.pi / views, detector_offset=offset,
                               source_offset=source[0] if source else (0.0, 0.0))
        err = _check_mapping(geo)
        report(f"{label}: geometry", err < 1e-9,
               f"RTK source/pixel positions vs ours, max |diff| = {err:.2e} mm")

        res = rtk_fdk(_sphere_projections(geo, [big]).astype(np.float32), geo, volume)
        mean = _inner_mean(res["volume"], volume, big[0], big[1] / 2)
        rel = mean / big[2] - 1
        report(f"{label}: centred sphere, {views} views", abs(rel) < 0.005,
               f"inner-half-radius mean {mean:.6f} vs μ {big[2]} mm⁻¹ ({100 * rel:+.3f} %), "
               f"FDK {res['seconds']:.2f} s + setup {res['setup_seconds']:.2f} s")

        res = rtk_fdk(_sphere_projections(geo, [small]).astype(np.float32), geo, volume)
        c = _centroid(res["volume"], volume, small[2] / 2)
        dev = np.abs(c - small[0]).max() / voxel
        report(f"{label}: off-centre sphere", dev < 0.25,
               f"centroid (x, y, z) = ({c[0]:+.4f}, {c[1]:+.4f}, {c[2]:+.4f}) mm vs "
               f"{small[0]} mm (max |diff| {dev:.3f} voxel)")

    # Shifted, non-cubic, anisotropic grid: catches a swapped axis or a wrong grid origin.
    volume = VolumeGeometry(shape=(40, 56, 72), voxel_size=(0.5, 0.45, 0.4), offset=(1.0, -1.5, 2.0))
    geo = ConeBeamGeometry(100.0, 200.0, (64, 96), 0.8, np.arange(180) * 2 * np.pi / 180,
                           detector_offset=(0.0, 12.0))
    res = rtk_fdk(_sphere_projections(geo, [small]).astype(np.float32), geo, volume)
    c = _centroid(res["volume"], volume, small[2] / 2)
    dev = np.abs(c - small[0]) / np.array(volume.voxel_size[::-1])
    report("grid (z, y, x) = 40x56x72 of (0.5, 0.45, 0.4) mm, offset (1, -1.5, 2) mm: off-centre sphere",
           dev.max() < 0.25,
           f"centroid (x, y, z) = ({c[0]:+.4f}, {c[1]:+.4f}, {c[2]:+.4f}) mm vs {small[0]} mm "
           f"(max |diff| {dev.max():.3f} voxel)")

    # Hann window: keeps the DC gain, so the flat interior keeps its value.
    volume = VolumeGeometry(shape=(64, 64, 64), voxel_size=0.5)
    geo = ConeBeamGeometry(100.0, 200.0, (64, 96), 0.8, np.arange(180) * 2 * np.pi / 180)
    res = rtk_fdk(_sphere_projections(geo, [big]).astype(np.float32), geo, volume,
                  window="hann", cutoff=0.5)
    mean = _inner_mean(res["volume"], volume, big[0], big[1] / 2)
    report("hann cutoff 0.5: centred sphere", abs(mean / big[2] - 1) < 0.005,
           f"inner-half-radius mean {mean:.6f} vs μ {big[2]} mm⁻¹ ({100 * (mean / big[2] - 1):+.3f} %)")
    try:
        rtk_fdk(np.zeros((180, 64, 96), np.float32), geo, volume, window="shepp-logan")
        report("unknown window", False, "no ValueError")
    except ValueError as exc:
        report("unknown window", True, f"ValueError: {exc}")

    # Timing: 128³ voxels of 0.25 mm from 180 views of 128² pixels of 0.4 mm.
    volume = VolumeGeometry(shape=(128, 128, 128), voxel_size=0.25)
    geo = ConeBeamGeometry(100.0, 200.0, (128, 128), 0.4, np.arange(180) * 2 * np.pi / 180)
    proj = _sphere_projections(geo, [big, small]).astype(np.float32)
    for threads in (1, 2):
        best = min((rtk_fdk(proj, geo, volume, threads=threads) for _ in range(3)),
                   key=lambda r: r["seconds"])
        print(f"timing 128^3 from 180x128x128, {threads} thread(s): FDK Update() "
              f"{best['seconds']:.3f} s (best of 3), setup {best['setup_seconds']:.3f} s")
    return ok


if __name__ == "__main__":
    reason = rtk_available()
    if reason:
        sys.exit(f"RTK unavailable: {reason}")
    sys.exit(0 if _self_check() else 1)
