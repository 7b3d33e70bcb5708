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

gvxr.computeLBuffer(label) returns a (nrow, ncol) image whose row index increases
along -v (row 0 is the TOP of the detector) and whose column index increases along +u;
its unit is cm, whatever units were used for the input. We therefore return
``10 * lbuffer[::-1, :]`` so that element [r, c] is the path length in mm along the ray
from the source to our pixel centre  det_centre + (c-(ncol-1)/2)*pixel*u + (r-(nrow-1)/2)*pixel*v.
(Verified against an exact float64 slab ray/box computation: ``python3 scripts/gvxr_peer.py``.)

gvxr keeps one OpenGL context (EGL, headless) per process; it is created lazily on first
use and reused for every call, and destroyed (quietly) at exit.  gvxr's C++ logging (it
writes a lot to stdout/stderr) is silenced by redirecting file descriptors 1 and 2 to
/dev/null around gvxr calls.  gvxr assumes its context stays current, which breaks (segfault)
once another EGL context (e.g. moderngl standalone) has been made current in this thread; so
every call makes gvxr's EGL context current first and restores the caller's context after.
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
_sys_egl = None        # system libEGL (the one moderngl/glcontext use), if loadable
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


@contextlib.contextmanager
def _gvxr_context():
    """Make gvxr's EGL context current; afterwards restore whatever was current before.

    gvxr ships its own copy of libEGL (gvxr.libs/libEGL-*.so); both copies report the same
    current context, but each only accepts the EGLDisplays it created itself, so the
    previous context is restored through whichever copy accepts it."""
    if _egl is None or not _egl[1][3]:
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
        if switch:
            if prev[3] is None:  # nothing was current: release gvxr's context
                lib.eglMakeCurrent(mine[0], None, None, None)
            elif not any(l is not None and l.eglMakeCurrent(*prev) for l in (_sys_egl, lib)):
                raise RuntimeError("could not restore the previous EGL context")


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
            libs = glob.glob(os.path.join(os.path.dirname(gvxrPython3.__file__), "..",
                                          "gvxr.libs", "libEGL*.so*"))
            egl = _load_egl(libs[0] if libs else "libEGL.so.1")
            prev = _current(egl)
            gvxr.createOpenGLContext()       # hidden EGL context, created once per process
            _egl = (egl, _current(egl))
            try:
                _sys_egl = _load_egl("libEGL.so.1")
            except OSError:
                pass
            gvxr.usePointSource()            # cone beam
            gvxr.setMonoChromatic(0.08, "MeV", 1000)  # required, otherwise computeLBuffer returns ()
            gvxr.disableArtefactFiltering()  # raw L-buffer (default is GPU artefact filtering)
            if prev[3] is not None:           # give the caller its context back
                (_sys_egl and _sys_egl.eglMakeCurrent(*prev)) or egl.eglMakeCurrent(*prev)
        _gvxr = gvxr
        atexit.register(_destroy)
    except Exception as exc:  # ImportError (missing libxcb-*), no EGL, ...
        _init_error = f"{type(exc).__name__}: {exc}"


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


def gvxr_path_lengths(meshes_by_material, sod_mm, sdd_mm, shape, pixel_mm,
                      angle_rad=0.0, repeats=3):
    """Path length through each material's meshes for one cone-beam view, computed by gvxr.

    meshes_by_material: {material: [(vertices (n,3) mm, faces (m,3) int), ...]} in our frame.
    shape: (rows, cols) of the detector.

    Returns ({material: float64 (rows, cols) path length in mm}, seconds) in our orientation
    (see module docstring).  ``seconds`` is the best, over ``repeats`` timed renders run after
    one untimed warm-up, of the wall time to: set the view's source/detector position and
    orientation, and, for every material, gvxr.computeLBuffer (GPU render + readback into a
    Python tuple) followed by conversion to a float64 numpy array, cm->mm scaling and row flip.
    Not timed: context creation, mesh upload (done once while the same meshes are passed),
    detector resolution set-up.
    """
    _init()
    if _init_error is not None:
        raise RuntimeError(f"gvxr unavailable: {_init_error}")
    g = _gvxr
    nrow, ncol = (int(s) for s in shape)
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    src = (float(sod_mm * s), float(-sod_mm * c), 0.0)          # R_z(theta) @ (0, -SOD, 0)
    odd = float(sdd_mm - sod_mm)
    det = (float(-odd * s), float(odd * c), 0.0)                 # R_z(theta) @ (0, SDD-SOD, 0)
    right = (float(c), float(s), 0.0)                            # R_z(theta) @ (1, 0, 0)

    def render():
        g.setSourcePosition(*src, "mm")
        g.setDetectorPosition(*det, "mm")
        g.setDetectorUpVector(0.0, 0.0, 1.0)
        g.setDetectorRightVector(*right)
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
