"""The classic stencil voxelizer, ``xr.voxelize(..., method="stencil")``: kept to compare with the
default exact method of :mod:`xrayraster.gl.voxelize`.

For every slice and every object (in rank order, so the highest priority is drawn last): clear
the stencil, draw the object's triangles seen along +z and clipped to the half-space above the
slice plane, front faces incrementing the stencil and back faces decrementing it, then write the
object's label wherever the count is not zero. Which pixels a triangle covers is the
rasteriser's decision (coverage of snapped vertices), so columns that graze a silhouette can
gain or lose a crossing; every slice draws every triangle that reaches above it. The exact
crossing sweep of :mod:`xrayraster.gl.voxelize` avoids both; this module exists to measure the
difference (scripts/bench_voxelize.py, tests/gl/test_voxelize.py).

moderngl has no stencil API, so the few stencil calls go to the driver directly.
"""

from __future__ import annotations

import ctypes

import numpy as np

from ..core.errors import VoxelizeError
from ..core.volume import VolumeGeometry
from ..scene.scene import Scene
from .context import GLContext

_GL_STENCIL_TEST, _GL_CLIP_DISTANCE0 = 0x0B90, 0x3000
_GL_ALWAYS, _GL_NOTEQUAL, _GL_KEEP, _GL_INCR_WRAP, _GL_DECR_WRAP = 0x0207, 0x0205, 0x1E00, 0x8507, 0x8508
_GL_FRONT, _GL_BACK = 0x0404, 0x0405
_GL_FRAMEBUFFER, _GL_RENDERBUFFER, _GL_STENCIL_ATTACHMENT, _GL_STENCIL_INDEX8 = 0x8D40, 0x8D41, 0x8D20, 0x8D48
_GL_STENCIL_BUFFER_BIT, _GL_FRAMEBUFFER_COMPLETE = 0x0400, 0x8CD5
_U = ctypes.c_uint
_SIGNATURES = {
    "glEnable": [_U], "glDisable": [_U], "glStencilFunc": [_U, ctypes.c_int, _U], "glStencilOpSeparate": [_U, _U, _U, _U],
    "glClearStencil": [ctypes.c_int], "glClear": [_U], "glGenRenderbuffers": [ctypes.c_int, ctypes.POINTER(_U)],
    "glBindRenderbuffer": [_U, _U], "glRenderbufferStorage": [_U, _U, ctypes.c_int, ctypes.c_int],
    "glBindFramebuffer": [_U, _U], "glFramebufferRenderbuffer": [_U, _U, _U, _U],
    "glDeleteRenderbuffers": [ctypes.c_int, ctypes.POINTER(_U)], "glCheckFramebufferStatus": [_U],
}


def _gl_functions(gl: GLContext) -> dict:
    """The raw GL entry points above (moderngl has no stencil API)."""
    out = {}
    for name, argtypes in _SIGNATURES.items():
        out[name] = gl.function(name, _U if name == "glCheckFramebufferStatus" else None, argtypes)
        if out[name] is None:
            raise VoxelizeError(f"the GL driver has no {name}: the stencil voxelizer cannot run here; use method='exact'")
    return out


def voxelize_stencil(scene: Scene, volume: VolumeGeometry, dtype, gl: GLContext) -> np.ndarray:
    """Labels (z, y, x) by stencil counting, slice by slice (module docstring), as ``dtype`` (uint8/16).
    Called by :func:`xrayraster.voxelize`, which checks the arguments."""
    out = np.zeros(volume.shape, dtype)
    with gl.current():
        stencil = _StencilPass(scene, volume, gl)
        try:
            for k, z in enumerate(volume.axis_centres(0)):
                out[k] = stencil.slice_labels(z)
        finally:
            stencil.release()
    return out


class _StencilPass:
    """The GL objects of the stencil method for one scene and grid (made inside ``gl.current()``)."""

    def __init__(self, scene: Scene, volume: VolumeGeometry, gl: GLContext):
        self.ranked = sorted(scene.objects, key=lambda o: o.rank)
        self.ref = scene.bounds.mean(axis=0)
        # One vertex buffer: each object's triangles sorted by their top z, highest first, so
        # the triangles reaching above a slice plane are a prefix of the object's range.
        soups, self.firsts, self.tops, start = [], [], [], 0
        for o in self.ranked:
            tri = o.mesh.vertices[o.mesh.faces] - self.ref  # (n, 3, 3), float64
            top = tri[:, :, 2].max(axis=1)
            order = np.argsort(-top, kind="stable")
            soups.append(tri[order].astype(np.float32))
            self.tops.append(-top[order])  # ascending, for searchsorted
            self.firsts.append(start)
            start += len(tri)
        _, ny, nx = volume.shape
        self.f = f = _gl_functions(gl)
        ctx = self.ctx = gl.ctx
        self.vbo = ctx.buffer(np.concatenate(soups).tobytes())
        self.count_prog = gl.program("stencil_count.vert", "stencil_count.frag")
        self.label_prog = gl.program("stencil_label.vert", "stencil_label.frag")
        self.count_vao = ctx.vertex_array(self.count_prog, [(self.vbo, "3f", "in_position")])
        self.label_vao = ctx.vertex_array(self.label_prog, [])
        self.colour = ctx.texture((nx, ny), 1, dtype="u2")
        self.fbo = ctx.framebuffer(color_attachments=[self.colour])
        self.blank = np.zeros((ny, nx), np.uint16).tobytes()  # fbo.clear() leaves integer textures undefined
        self.shape = (ny, nx)
        self.rb = _U()
        f["glGenRenderbuffers"](1, ctypes.byref(self.rb))
        f["glBindRenderbuffer"](_GL_RENDERBUFFER, self.rb.value)
        f["glRenderbufferStorage"](_GL_RENDERBUFFER, _GL_STENCIL_INDEX8, nx, ny)
        f["glBindFramebuffer"](_GL_FRAMEBUFFER, self.fbo.glo)
        f["glFramebufferRenderbuffer"](_GL_FRAMEBUFFER, _GL_STENCIL_ATTACHMENT, _GL_RENDERBUFFER, self.rb.value)
        complete = f["glCheckFramebufferStatus"](_GL_FRAMEBUFFER) == _GL_FRAMEBUFFER_COMPLETE
        _, vy, vx = volume.voxel_size
        first_centre = (volume.axis_centres(2)[0] - self.ref[0], volume.axis_centres(1)[0] - self.ref[1])
        for name, value in (("u_first_centre", first_centre), ("u_voxel", (vx, vy)), ("u_columns", (nx, ny))):
            self.count_prog[name].value = value
        ctx.disable(ctx.CULL_FACE | ctx.DEPTH_TEST | ctx.BLEND)
        f["glEnable"](_GL_CLIP_DISTANCE0)
        f["glEnable"](_GL_STENCIL_TEST)
        if not complete:
            self.release()
            raise VoxelizeError("the GL driver refused a stencil framebuffer; use method='exact'")

    def slice_labels(self, z: float) -> np.ndarray:
        """(ny, nx) uint16 labels of the slice whose voxel centres are at height ``z`` (mm)."""
        f = self.f
        self.colour.write(self.blank)
        z -= self.ref[2]
        self.count_prog["u_slice_z"].value = float(z)
        for o, first, top in zip(self.ranked, self.firsts, self.tops):
            reach = int(np.searchsorted(top, -z, side="right"))  # triangles reaching above z
            if reach == 0:
                continue
            f["glClearStencil"](0)
            f["glClear"](_GL_STENCIL_BUFFER_BIT)
            self.fbo.color_mask = (False, False, False, False)
            self.fbo.use()  # moderngl applies a framebuffer's colour mask when it is bound
            f["glStencilFunc"](_GL_ALWAYS, 0, 0xFF)
            f["glStencilOpSeparate"](_GL_FRONT, _GL_KEEP, _GL_KEEP, _GL_INCR_WRAP)
            f["glStencilOpSeparate"](_GL_BACK, _GL_KEEP, _GL_KEEP, _GL_DECR_WRAP)
            self.count_vao.render(vertices=3 * reach, first=3 * first)
            self.fbo.color_mask = (True, True, True, True)
            self.fbo.use()
            f["glStencilFunc"](_GL_NOTEQUAL, 0, 0xFF)
            f["glStencilOpSeparate"](_GL_FRONT, _GL_KEEP, _GL_KEEP, _GL_KEEP)
            f["glStencilOpSeparate"](_GL_BACK, _GL_KEEP, _GL_KEEP, _GL_KEEP)
            self.label_prog["u_label"].value = o.label
            self.label_vao.render(vertices=3)
        return np.frombuffer(self.colour.read(), np.uint16).reshape(self.shape)

    def release(self) -> None:
        self.f["glDisable"](_GL_STENCIL_TEST)
        self.f["glDisable"](_GL_CLIP_DISTANCE0)
        self.f["glDeleteRenderbuffers"](1, ctypes.byref(self.rb))
        for obj in (self.count_vao, self.label_vao, self.fbo, self.colour, self.vbo):
            obj.release()
