"""gVirtualXRay (``gvxr`` 2.1.0 on PyPI) as a benchmark peer: per-material path-length images.

Geometry mapping (our scanner frame, mm; rotation axis z through the origin)
--------------------------------------------------------------------------
Meshes are uploaded once, unchanged, in our frame (gvxr's world frame == ours, unit "mm").
For view angle theta we move the source and detector instead of rotating the object:

    source          = R_z(theta) @ (0, -SOD, 0)       -> gvxr.setSourcePosition(..., "mm")
    detector centre = R_z(theta) @ (0, SDD - SOD, 0)  -> gvxr.setDetectorPosition(..., "mm")
    up vector  v    = (0, 0, 1)                       -> gvxr.setDetectorUpVector
    right vector u  = R_z(theta) @ (1, 0, 0)          -> gvxr.setDetectorRightVector
    point source (cone beam), detector (ncol, nrow) pixels of pixel_mm x pixel_mm.

gvxr.computeLBuffer(label) returns a (nrow, ncol) image (a tuple of tuples) whose row index
increases along +v and column index along +u, with pixel centres exactly at our pixel
centres, so no flip/transpose is needed; its unit is cm whatever unit the mesh was given in
(checked: mm/cm/um meshes give the same values).  We return ``10 * lbuffer`` so that [r, c]
is the path length in mm along the ray from the source to our pixel centre
det_centre + (c-(ncol-1)/2)*pixel*u + (r-(nrow-1)/2)*pixel*v.  Self-check against an exact
float64 slab ray/box computation: ``python -m scripts.peers.gvxr_peer``.  With a near source
gvxr's error grows with triangle size (it interpolates the depth across each triangle in
screen space: ~0.2 mm max on a 12-triangle 10 mm cube at SOD=100, <1e-3 mm once subdivided);
with a far source it is ~1e-4 mm (float32).

All meshes of one material are concatenated into one gvxr mesh (an L-buffer sums over closed
surfaces, so this equals the sum of per-mesh L-buffers; overlapping meshes count twice).
The scene is re-uploaded only when the meshes passed change (content fingerprint).

gvxr keeps one OpenGL context (EGL, headless) per process; it is created lazily on first
use (importing gvxr takes ~4 s) and reused for every call, and destroyed at exit.  gvxr's
logger is sent to /dev/null (gvxr.useLogFile), and the stray stdout/stderr lines of its
windowing fall-back are silenced by redirecting fds 1 and 2 to /dev/null around gvxr calls.
gvxr assumes its context stays current: a gvxr call after another EGL context (e.g. a
moderngl standalone one) was made current in the thread segfaults.  So every call makes
gvxr's EGL context current first and restores the caller's current context afterwards
(gvxr must be used from one thread only).
"""
from __future__ import annotations

import atexit
import contextlib
import ctypes
import glob
import hashlib
import os
import sys
import time

import numpy as np

_gvxr = None           # the gvxrPython3.gvxr module once the context exists
_init_error = None     # reason string if initialisation failed
_scene_key = None      # fingerprint of the meshes currently uploaded
_labels: dict[str, str] = {}   # material -> gvxr mesh label
_egl = None            # (libEGL bundled with gvxr, (display, draw, read, context) of gvxr)
_sys_egl = None        # system libEGL (the one moderngl/xrayraster.gl.context use), if loadable
_EGL_DRAW, _EGL_READ = 0x3059, 0x305A


@contextlib.contextmanager
def _quiet():
    """Redirect the process-level stdout/stderr (fd 1 and 2) to /dev/null."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def _load_egl(path):
    lib = ctypes.CDLL(path)
    lib.eglGetCurrentDisplay.restype = ctypes.c_void_p
    lib.eglGetCurrentContext.restype = ctypes.c_void_p
    lib.eglGetCurrentSurface.restype = ctypes.c_void_p
    lib.eglGetCurrentSurface.argtypes = [ctypes.c_int]
    lib.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    lib.eglMakeCurrent.restype = ctypes.c_uint
    return lib


def _current(lib):
    return (lib.eglGetCurrentDisplay(), lib.eglGetCurrentSurface(_EGL_DRAW),
            lib.eglGetCurrentSurface(_EGL_READ), lib.eglGetCurrentContext())


def _make_current(state):
    """Make (display, draw, read, context) current through whichever libEGL accepts it."""
    lib, mine = _egl
    if state[3] is None:                 # nothing was current: release gvxr's context
        return lib.eglMakeCurrent(mine[0], None, None, None)
    return any(l is not None and l.eglMakeCurrent(*state) for l in (_sys_egl, lib))


@contextlib.contextmanager
def _gvxr_context():
    """Make gvxr's EGL context current; afterwards restore whatever was current before.

    gvxr ships its own copy of libEGL (gvxr.libs/libEGL-*.so); both copies report the same
    current context, but each only accepts the EGLDisplays it created itself, so the
    previous context is restored through whichever copy accepts it."""
    if _egl is None or _egl[1][3] is None:
        yield
        return
    lib, mine = _egl
    prev = _current(lib)
    switch = prev[3] != mine[3]
    if switch:
        lib.eglMakeCurrent(*mine)
    try:
        yield
    finally:
        if switch and not _make_current(prev):
            raise RuntimeError("gvxr_peer: could not restore the previous EGL context")


def _destroy():
    with _quiet(), _gvxr_context():
        _gvxr.destroy()


def _init():
    global _gvxr, _init_error, _egl, _sys_egl
    if _gvxr is not None or _init_error is not None:
        return
    try:
        with _quiet():
            import gvxrPython3
            from gvxrPython3 import gvxr
            gvxr.useLogFile(os.devnull)      # gvxr's logger, otherwise on stdout (even at exit)
            try:
                libs = glob.glob(os.path.join(os.path.dirname(gvxrPython3.__file__), "..",
                                              "gvxr.libs", "libEGL*.so*"))
                egl = _load_egl(libs[0] if libs else "libEGL.so.1")
                _sys_egl = _load_egl("libEGL.so.1")
            except OSError:
                egl = None
            prev = _current(egl) if egl else None
            gvxr.createOpenGLContext()       # hidden EGL context, created once per process
            if egl:
                _egl = (egl, _current(egl))
            gvxr.usePointSource()            # cone beam
            gvxr.setMonoChromatic(0.08, "MeV", 1000)  # required, else computeLBuffer returns ()
            gvxr.disableArtefactFiltering()  # raw L-buffer (no effect on L-buffers seen here)
            if _egl and _egl[1][3] is not None and prev[3] is not None:
                _make_current(prev)          # give the caller its context back
        _gvxr = gvxr
        atexit.register(_destroy)
    except Exception as exc:  # ImportError (missing libxcb-*), no EGL, ...
        _init_error = f"{type(exc).__name__}: {exc}"


def _require():
    """The gvxr module, initialised; RuntimeError with the reason if it cannot be."""
    _init()
    if _init_error is not None:
        raise RuntimeError(f"gvxr unavailable: {_init_error}")
    return _gvxr


def gvxr_available() -> str | None:
    """None if gvxr can be imported and its headless OpenGL context created, else a reason."""
    _init()
    return _init_error


def _upload(meshes_by_material):
    """(Re)build gvxr's scene, one gvxr mesh per material, unless the same meshes are loaded."""
    global _scene_key
    h = hashlib.blake2b(digest_size=16)
    for mat in sorted(meshes_by_material):
        h.update(mat.encode() + b"\0")
        for v, f in meshes_by_material[mat]:
            for a in (np.ascontiguousarray(v, np.float64), np.ascontiguousarray(f, np.int64)):
                h.update(repr(a.shape).encode())
                h.update(a.data)
    key = h.hexdigest()
    if key == _scene_key:
        return
    g = _gvxr
    g.removePolygonMeshesFromSceneGraph()
    _labels.clear()
    for i, mat in enumerate(sorted(meshes_by_material)):
        parts = meshes_by_material[mat]
        if not parts:
            continue
        # Concatenate all meshes of a material: the L-buffer of a set of disjoint closed
        # meshes is the sum of their L-buffers (overlaps would be counted twice, as in a sum).
        offs = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
        verts = np.concatenate([np.asarray(v, np.float64).reshape(-1, 3) for v, _ in parts])
        faces = np.concatenate([np.asarray(f, np.int64).reshape(-1, 3) + o
                                for (_, f), o in zip(parts, offs)])
        label = f"mat{i}"
        g.makeTriangularMesh(label, verts.ravel().tolist(), faces.ravel().tolist(), "mm")
        g.addPolygonMeshAsInnerSurface(label)
        g.setElement(label, "H")   # any material; the L-buffer does not depend on it
        _labels[mat] = label
    _scene_key = key


def _placement(sod_mm: float, sdd_mm: float, angle_rad: float):
    """A call that moves gvxr's source and detector to our view at ``angle_rad`` (see the module docstring)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    src = (float(sod_mm * s), float(-sod_mm * c), 0.0)          # R_z(theta) @ (0, -SOD, 0)
    odd = float(sdd_mm - sod_mm)
    det = (float(-odd * s), float(odd * c), 0.0)                 # R_z(theta) @ (0, SDD-SOD, 0)
    right = (float(c), float(s), 0.0)                            # R_z(theta) @ (1, 0, 0)

    def place():
        _gvxr.setSourcePosition(*src, "mm")
        _gvxr.setDetectorPosition(*det, "mm")
        _gvxr.setDetectorUpVector(0.0, 0.0, 1.0)
        _gvxr.setDetectorRightVector(*right)

    return place


def gvxr_path_lengths(meshes_by_material: dict[str, list[tuple[np.ndarray, np.ndarray]]],
                      sod_mm: float, sdd_mm: float, shape: tuple[int, int], pixel_mm: float,
                      angle_rad: float = 0.0, repeats: int = 3
                      ) -> tuple[dict[str, np.ndarray], float]:
    """Path length through each material's meshes for one cone-beam view, computed by gvxr.

    meshes_by_material: {material: [(vertices (n,3) mm, faces (m,3) int), ...]} in our frame.
    shape: (rows, cols) of the detector.

    Returns ({material: float64 (rows, cols) path length in mm}, seconds) in our orientation
    (see module docstring).  ``seconds`` is the best, over ``repeats`` timed renders run after
    one untimed warm-up, of the wall time to: set the view's source/detector position and
    orientation, and, for every material, gvxr.computeLBuffer (GPU render + readback into a
    Python tuple) followed by conversion to a float64 numpy array and cm->mm scaling.
    Not timed: gvxr import and context creation, mesh fingerprint and upload (skipped while
    the same meshes are passed), detector resolution/pixel-size set-up, EGL context switch.
    """
    g = _require()
    nrow, ncol = (int(s) for s in shape)
    place = _placement(sod_mm, sdd_mm, angle_rad)

    def render():
        place()
        return {mat: 10.0 * np.asarray(g.computeLBuffer(lab), dtype=np.float64)
                for mat, lab in _labels.items()}

    best = float("inf")
    with _quiet(), _gvxr_context():
        _upload(meshes_by_material)
        g.setDetectorNumberOfPixels(ncol, nrow)
        g.setDetectorPixelSize(float(pixel_mm), float(pixel_mm), "mm")
        out = render()                          # warm-up (shader/texture/VBO setup)
        for _ in range(max(1, int(repeats))):
            t0 = time.perf_counter()
            out = render()
            best = min(best, time.perf_counter() - t0)
    for mat in meshes_by_material:              # materials with no meshes -> zeros
        out.setdefault(mat, np.zeros((nrow, ncol)))
    return out, best


def gvxr_set_materials(meshes_by_material, materials):
    """Give each material's gvxr mesh its composition and density.

    ``materials``: {material: (symbols, mass fractions, density g/cm³)}, e.g.
    ``{"warp": (["C"], [1.0], 1.8)}``; set with gvxr.setMixture (mass fractions, as
    gvxr's "weights") + gvxr.setDensity(..., "g/cm3").  Uploads the meshes first if needed.
    Returns {material: gvxr label}."""
    g = _require()
    with _quiet(), _gvxr_context():
        _upload(meshes_by_material)
        for mat, label in _labels.items():
            symbols, weights, density = materials[mat]
            g.setMixture(label, [str(s) for s in symbols], [float(w) for w in weights])
            g.setDensity(label, float(density), "g/cm3")
    return dict(_labels)


def gvxr_linear_attenuation(label: str, energies_kev) -> np.ndarray:
    """gvxr's own μ (mm⁻¹) of a mesh's material at ``energies_kev`` (getLinearAttenuationCoefficient, cm⁻¹ / 10)."""
    g = _gvxr
    with _quiet(), _gvxr_context():
        return np.array([g.getLinearAttenuationCoefficient(label, float(e), "keV") for e in energies_kev]) / 10.0


def _set_beam_and_detector(energies_kev, photons, shape, pixel_mm: float, bin_cutoff_kev: float | None) -> None:
    """gvxr's spectrum (one bin per energy with photons > 0), no detector energy response, the
    detector's (rows, cols) and square pixel (mm); inside ``_quiet`` and ``_gvxr_context``."""
    g = _gvxr
    g.clearDetectorEnergyResponse()
    if bin_cutoff_kev is not None:
        g.setBinTotalEnergyCutoff(float(bin_cutoff_kev), "keV")
    g.resetBeamSpectrum()
    for e, n in zip(energies_kev, photons):
        if n > 0:
            g.addEnergyBinToSpectrum(float(e), "keV", float(n))
    g.setDetectorNumberOfPixels(int(shape[1]), int(shape[0]))
    g.setDetectorPixelSize(float(pixel_mm), float(pixel_mm), "mm")


def gvxr_xray_image(meshes_by_material, materials, energies_kev, photons, sod_mm: float, sdd_mm: float,
                    shape: tuple[int, int], pixel_mm: float, angle_rad: float = 0.0, repeats: int = 3,
                    bin_cutoff_kev: float | None = None) -> dict:
    """gvxr's polychromatic radiograph of one cone-beam view, as transmission (image / flat).

    ``materials``: see :func:`gvxr_set_materials`; ``energies_kev`` / ``photons``: the beam
    spectrum, one gvxr.addEnergyBinToSpectrum(E, "keV", N) per bin with N > 0 (gvxr takes N as
    photons *per pixel*, uniform over the detector: no inverse square or obliquity).
    ``bin_cutoff_kev``: None leaves gvxr's bin cut-off as it is (its default drops the weakest
    bins; gvxr has no getter for the default, so once set it cannot be restored in this
    process), a number calls gvxr.setBinTotalEnergyCutoff(value, "keV") (0 keeps every bin).

    gvxr.computeXRayImage() (default anIntegrateEnergyFlag=True) returns the energy fluence per
    pixel, Σ_b N_b·E_b·exp(−Σ μ·L) in MeV (float32 values), with no detector energy response
    unless one was loaded (none is here: clearDetectorEnergyResponse).  The flat is gvxr's
    getTotalEnergyWithDetectorResponse() (Σ N_b·E_b over the bins it kept, MeV): the value of
    an unattenuated pixel.

    Returns {"transmission": float64 (rows, cols) in our orientation (see the module
    docstring), "flat": MeV, "seconds": best of ``repeats`` after one warm-up of (set the view's
    source/detector, computeXRayImage, numpy conversion, ÷ flat), "bins_given", "bins_kept",
    "energies_kept_kev"}.  Not timed: upload, materials, spectrum, detector size set-up.
    """
    gvxr_set_materials(meshes_by_material, materials)
    g = _gvxr
    nrow, ncol = (int(s) for s in shape)
    place = _placement(sod_mm, sdd_mm, angle_rad)
    energies = np.asarray(energies_kev, np.float64)
    photons = np.asarray(photons, np.float64)
    given = int(np.count_nonzero(photons > 0))

    def render(flat):
        place()
        return np.asarray(g.computeXRayImage(), dtype=np.float64) / flat

    best = float("inf")
    with _quiet(), _gvxr_context():
        _set_beam_and_detector(energies, photons, (nrow, ncol), pixel_mm, bin_cutoff_kev)
        out = render(1.0)                         # warm-up; gvxr applies its bin cut-off here
        flat = float(g.getTotalEnergyWithDetectorResponse())
        kept = np.asarray(g.getEnergyBins("keV"), np.float64)
        for _ in range(max(1, int(repeats))):
            t0 = time.perf_counter()
            out = render(flat)
            best = min(best, time.perf_counter() - t0)
    return {"transmission": out, "flat": flat, "seconds": best, "bins_given": given,
            "bins_kept": int(len(kept)), "energies_kept_kev": kept}


def gvxr_scan_images(meshes_by_material, materials, energies_kev, photons, sod_mm: float, sdd_mm: float,
                     shape: tuple[int, int], pixel_mm: float, angles_rad, *,
                     bin_cutoff_kev: float | None = None) -> dict:
    """gvxr's polychromatic radiographs of a whole circular cone-beam scan, as transmission (image / flat).

    The radiograph of :func:`gvxr_xray_image` (same arguments: materials, spectrum, energy-fluence
    image, no detector energy response, gvxr's flat), once per angle of ``angles_rad`` (radians,
    our convention), with no warm-up and no repeats: what a user's scan loop does.

    Returns {"transmission": float32 (views, rows, cols) in our orientation, "flat": MeV,
    "setup_seconds": wall time of the mesh upload (skipped while the same meshes are loaded), the
    materials, the spectrum and the detector size, "seconds": wall time of the loop (per view:
    placement, computeXRayImage, numpy conversion, ÷ flat), "bins_given", "bins_kept"}.
    """
    t0 = time.perf_counter()
    gvxr_set_materials(meshes_by_material, materials)
    g = _gvxr
    nrow, ncol = (int(s) for s in shape)
    photons = np.asarray(photons, np.float64)
    with _quiet(), _gvxr_context():
        _set_beam_and_detector(np.asarray(energies_kev, np.float64), photons, (nrow, ncol), pixel_mm, bin_cutoff_kev)
    setup = time.perf_counter() - t0

    t0 = time.perf_counter()
    angles = np.asarray(angles_rad, np.float64)
    out = np.empty((len(angles), nrow, ncol), np.float32)
    flat = None
    for k, angle in enumerate(angles):
        with _quiet(), _gvxr_context():
            _placement(sod_mm, sdd_mm, float(angle))()
            image = np.asarray(g.computeXRayImage(), dtype=np.float64)
            if flat is None:  # gvxr applies its bin cut-off at the first image: the flat is known from then on
                flat = float(g.getTotalEnergyWithDetectorResponse())
                kept = len(g.getEnergyBins("keV"))
        out[k] = image / flat
    return {"transmission": out, "flat": flat, "setup_seconds": setup, "seconds": time.perf_counter() - t0,
            "bins_given": int(np.count_nonzero(photons > 0)), "bins_kept": int(kept)}


def _box(centre, size):
    """Closed, outward-CCW triangulated axis-aligned cube (for the self-check)."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v * size / 2 + np.asarray(centre, float), f


def _self_check() -> int:
    """Orientation / unit self-check against exact float64 ray-box lengths (slab method)."""
    from references.chords import box_chord, cone_rays

    reason = gvxr_available()
    if reason:
        print(f"gvxr unavailable: {reason}")
        return 2
    boxes = {"a": [((5.0, 0.0, 8.0), 10.0), ((-6.0, 3.0, -5.0), 4.0)],  # two meshes, one material
             "b": [((-4.0, -2.0, 4.0), 3.0)]}
    meshes = {m: [_box(*b) for b in bs] for m, bs in boxes.items()}
    shape, pixel = (128, 96), 0.2
    for sod, sdd in ((100.0, 200.0), (10000.0, 10100.0)):
        for angle in (0.0, 0.7):
            out, sec = gvxr_path_lengths(meshes, sod, sdd, shape, pixel, angle)
            origins, dirs = cone_rays(sod, sdd, shape, pixel, angle)
            for m, bs in boxes.items():
                exact = sum(box_chord(origins, dirs, np.asarray(c), np.eye(3), (size / 2,) * 3) for c, size in bs)
                err = np.abs(out[m] - exact)
                print(f"SOD={sod:g} SDD={sdd:g} angle={angle} material={m}: "
                      f"max|err|={err.max():.3g} mm mean|err|={err.mean():.3g} mm "
                      f"({sec * 1e3:.1f} ms/view)")
    return 0


if __name__ == "__main__":
    sys.exit(_self_check())
