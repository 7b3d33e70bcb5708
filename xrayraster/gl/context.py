"""The headless OpenGL context: one object owns all GL state, reused across renders.

Backends, tried in order unless ``XRAYRASTER_GL`` (or the ``backend`` argument) names one:

* ``egl``: moderngl's standalone EGL context (Mesa llvmpipe on a CPU server; the NVIDIA or AMD
  driver on a GPU server).
* ``osmesa``: Mesa's off-screen software renderer through ``libOSMesa``, for machines without
  EGL. It renders into a 1×1 dummy buffer; all our output goes to framebuffer objects.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import re
import threading
from contextlib import contextmanager

import moderngl
import numpy as np

from ..core.errors import GLContextError
from ..core.shader_files import read_shader
from .bindings import binding_defines

REQUIRED_GL = 430  # SSBOs, compute shaders, indirect draws
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast")  # GL_RENDERER names of Mesa's CPU rasterisers

INSTALL_HINT = (
    "xrayraster needs OpenGL 4.3 through EGL or OSMesa. On Debian/Ubuntu install the drivers with "
    "'apt-get install libegl1 libgl1-mesa-dri' (EGL, preferred) or 'apt-get install libosmesa6' "
    "(OSMesa); on a GPU server, the vendor driver's EGL library."
)


class GLContext:
    """A headless OpenGL 4.3+ context plus the compiled programs of ``shaders/``.

    Use as a context manager or call :meth:`release`. Programs are compiled once per context.

    A context belongs to the thread that created it: using it (or a ``Renderer`` or voxelizer
    holding it) from another thread raises :class:`~xrayraster.GLContextError`. Create one per
    thread, in the thread that uses it.
    """

    def __init__(self, backend: str | None = None):
        backend = backend or os.environ.get("XRAYRASTER_GL") or None
        if backend not in (None, "egl", "osmesa"):
            raise GLContextError(f"unknown GL backend {backend!r}: use 'egl' or 'osmesa' (XRAYRASTER_GL)")
        errors = []
        self._depth = 0  # nesting of current()
        self._thread = threading.get_ident()  # GL contexts are current per thread: ours is this one's
        self._thread_name = threading.current_thread().name
        self._osmesa = None
        self.ctx = None
        for name in (backend,) if backend else ("egl", "osmesa"):
            try:
                self.ctx = _create(name, self)
                self.backend = name
                break
            except Exception as exc:  # each backend fails in its own way
                errors.append(f"{name}: {exc}")
        if self.ctx is None:
            raise GLContextError("no OpenGL context could be created (" + "; ".join(errors) + "). " + INSTALL_HINT)
        if self.ctx.version_code < REQUIRED_GL:
            version = self.ctx.info["GL_VERSION"]
            self.release()
            raise GLContextError(f"OpenGL {version} found, 4.3 needed. " + INSTALL_HINT)
        self.ctx.info  # queried (and cached by moderngl) now, while this context is current
        self._programs: dict[tuple, moderngl.Program | moderngl.ComputeShader] = {}
        self._uniforms: dict[int, dict] = {}  # per program (its GL name): the values set last, as bytes
        self._unlocked_gl = None

    @contextmanager
    def current(self):
        """``with gl.current():`` makes this context current in the calling thread, and the
        previous one again on exit. GL calls go to whichever context is current, so every
        public entry point that touches GL state enters this: several contexts (ours, a
        second renderer's, a peer library's) can then live in one process. Re-entrant: only
        the outermost level switches (moderngl's own enter/exit do not nest).

        Raises :class:`~xrayraster.GLContextError` in a thread other than the creating one."""
        if threading.get_ident() != self._thread:
            raise GLContextError(
                f"this OpenGL context belongs to the thread that created it ({self._thread_name!r}) and cannot be used "
                f"from thread {threading.current_thread().name!r}; create the Renderer (or GLContext) in the thread "
                "that uses it, one per thread")
        if self.ctx is None:
            raise GLContextError("this OpenGL context was released; create a new Renderer (or GLContext)")
        if self._depth == 0:
            self.ctx.__enter__()
        self._depth += 1
        try:
            yield self
        finally:
            self._depth -= 1
            if self._depth == 0:
                self.ctx.__exit__(None, None, None)

    @property
    def renderer(self) -> str:
        """Driver name, e.g. 'llvmpipe (LLVM 15.0.6, 256 bits)'."""
        with self.current():
            return self.ctx.info["GL_RENDERER"]

    @property
    def software(self) -> bool:
        """Whether the GL renders on the CPU (one of Mesa's :data:`SOFTWARE_RENDERERS`): its work
        then shares the cores with the rest of the process."""
        renderer = str(self.ctx.info.get("GL_RENDERER", "")).lower()
        return any(name in renderer for name in SOFTWARE_RENDERERS)

    def program(self, vertex: str, fragment: str, defines: dict | None = None) -> moderngl.Program:
        key = (vertex, fragment, tuple(sorted((defines or {}).items())))
        if key not in self._programs:
            with self.current():
                self._programs[key] = self.ctx.program(
                    vertex_shader=shader_source(vertex, defines), fragment_shader=shader_source(fragment, defines)
                )
        return self._programs[key]

    def function(self, name: str, restype, argtypes):
        """A raw GL entry point as a ctypes function, for what moderngl does not wrap (stencil
        operations) or calls holding Python's GIL (:meth:`dispatch` and the rest), or None when the
        driver lacks it. Call it inside :meth:`current`. Through ctypes a call releases the GIL."""
        if self.backend == "osmesa":
            pointer = self._osmesa.load_opengl_function(name)
        else:
            egl = ctypes.CDLL(ctypes.util.find_library("EGL") or "libEGL.so.1")
            egl.eglGetProcAddress.restype = ctypes.c_void_p
            egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
            pointer = egl.eglGetProcAddress(name.encode())
            # EGL before 1.5 need not resolve core functions: then the GL library's own symbol, as
            # moderngl's loader falls back to it.
            for library in () if pointer else ("libOpenGL.so.0", "libGL.so.1"):
                try:
                    pointer = ctypes.cast(getattr(ctypes.CDLL(library), name), ctypes.c_void_p).value
                except (OSError, AttributeError):
                    continue
                break
        return ctypes.CFUNCTYPE(restype, *argtypes)(pointer) if pointer else None

    def dispatch(self, prog: moderngl.ComputeShader, x: int, y: int = 1, z: int = 1) -> None:
        """``prog.run(x, y, z)`` with Python's GIL released (:class:`_UnlockedGL`)."""
        self._unlocked().dispatch(prog.glo, x, y, z)

    def dispatch_indirect(self, prog: moderngl.ComputeShader, buffer: moderngl.Buffer, offset: int = 0) -> None:
        """``prog.run_indirect(buffer, offset)`` with Python's GIL released."""
        self._unlocked().dispatch_indirect(prog.glo, buffer.glo, offset)

    def draw_indirect(self, vao: moderngl.VertexArray, buffer: moderngl.Buffer, mode: int) -> None:
        """``vao.render_indirect(buffer, mode, count=1)`` with Python's GIL released."""
        self._unlocked().draw_indirect(vao.program.glo, vao.glo, buffer.glo, mode)

    def barrier(self) -> None:
        """``ctx.memory_barrier()`` (every bit) with Python's GIL released: on a CPU driver it waits
        for the work queued before it."""
        self._unlocked().barrier()

    def read(self, buffer: moderngl.Buffer, dtype, count: int) -> np.ndarray:
        """The first ``count`` elements of ``buffer`` as a new ``dtype`` array, read with Python's GIL
        released: on a GPU the read is where the CPU waits for the view's work."""
        out = np.empty(count, dtype)
        self._unlocked().read(buffer.glo, out)
        return out

    def _unlocked(self) -> "_UnlockedGL":
        if self._unlocked_gl is None:
            self._unlocked_gl = _UnlockedGL(self)
        return self._unlocked_gl

    def compute(self, name: str, defines: dict | None = None) -> moderngl.ComputeShader:
        key = (name, tuple(sorted((defines or {}).items())))
        if key not in self._programs:
            with self.current():
                self._programs[key] = self.ctx.compute_shader(shader_source(name, defines))
        return self._programs[key]

    def set_uniforms(self, prog, values: dict) -> None:
        """Set the uniforms ``prog`` uses (the compiler drops the ones a stage does not read); arrays as
        float32. A value equal to the one set last is not sent again: a view's passes set some twenty
        uniforms each, of which only the rays change, and each write costs a GL call (~17 µs on llvmpipe).
        Every write to these programs' uniforms must come through here, or the memory would be stale."""
        last = self._uniforms.setdefault(prog.glo, {})
        for name, value in values.items():
            if name not in prog:
                continue
            data = value.astype(np.float32).tobytes() if isinstance(value, np.ndarray) else value
            if name in last and last[name] == data:
                continue
            if isinstance(data, bytes):
                prog[name].write(data)
            else:
                prog[name].value = data
            last[name] = data

    def release(self) -> None:
        if self.ctx is not None:
            with self.current():
                for p in getattr(self, "_programs", {}).values():
                    p.release()
                self._programs = {}
                self._uniforms = {}
            self.ctx.release()
            self.ctx = None
        if self._osmesa is not None:
            self._osmesa.release()
            self._osmesa = None

    def __enter__(self) -> "GLContext":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class _UnlockedGL:
    """The GL calls that do a view's work, through ctypes, which releases Python's GIL around a
    foreign call: moderngl holds it for the whole call, and llvmpipe runs a compute dispatch
    inside the call (6-40 ms a pass), so a thread turning the previous view into a radiograph,
    or filtering the previous batch, could not run a line of Python meanwhile (measured: a thread
    spinning beside a 110 ms dispatch got 4 % of its iterations). Same GL calls as moderngl's."""

    _INDIRECT_DISPATCH, _INDIRECT_DRAW, _COPY_READ, _ALL_BARRIERS = 0x90EE, 0x8F3F, 0x8F36, 0xFFFFFFFF

    def __init__(self, gl: GLContext):
        u, i = ctypes.c_uint, ctypes.c_ssize_t
        names = {"glUseProgram": [u], "glDispatchCompute": [u, u, u], "glDispatchComputeIndirect": [i],
                 "glBindBuffer": [u, u], "glMemoryBarrier": [u], "glBindVertexArray": [u],
                 "glDrawArraysIndirect": [u, ctypes.c_void_p], "glGetBufferSubData": [u, i, i, ctypes.c_void_p]}
        for name, argtypes in names.items():
            function = gl.function(name, None, argtypes)
            if function is None:
                raise GLContextError(f"the GL driver lacks {name}, which OpenGL 4.3 has. " + INSTALL_HINT)
            setattr(self, name[2:], function)

    def dispatch(self, program: int, x: int, y: int, z: int) -> None:
        self.UseProgram(program)
        self.DispatchCompute(x, y, z)

    def dispatch_indirect(self, program: int, buffer: int, offset: int) -> None:
        self.UseProgram(program)
        self.BindBuffer(self._INDIRECT_DISPATCH, buffer)
        self.DispatchComputeIndirect(offset)

    def draw_indirect(self, program: int, vao: int, buffer: int, mode: int) -> None:
        self.UseProgram(program)
        self.BindVertexArray(vao)
        self.BindBuffer(self._INDIRECT_DRAW, buffer)
        self.DrawArraysIndirect(mode, None)

    def barrier(self) -> None:
        self.MemoryBarrier(self._ALL_BARRIERS)

    def read(self, buffer: int, out: np.ndarray) -> None:
        self.BindBuffer(self._COPY_READ, buffer)
        self.GetBufferSubData(self._COPY_READ, 0, out.nbytes, out.ctypes.data)


def _create(name: str, owner: GLContext) -> moderngl.Context:
    if name == "egl":
        return moderngl.create_context(standalone=True, backend="egl", require=REQUIRED_GL)
    owner._osmesa = _OSMesaLoader()
    return moderngl.create_context(context=owner._osmesa, require=REQUIRED_GL)


class _OSMesaLoader:
    """Makes an OSMesa core-profile context current and resolves GL functions for moderngl."""

    def __init__(self):
        path = ctypes.util.find_library("OSMesa")
        if path is None:
            raise OSError("libOSMesa not found")
        lib = ctypes.CDLL(path)
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_int]
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        # OSMESA_FORMAT, OSMESA_RGBA, OSMESA_PROFILE, OSMESA_CORE_PROFILE, major, minor
        attrs = (ctypes.c_int * 11)(0x22, 0x1908, 0x33, 0x34, 0x36, 4, 0x37, 5, 0, 0, 0)
        self._ctx = lib.OSMesaCreateContextAttribs(attrs, None)
        if not self._ctx:
            raise OSError("OSMesaCreateContextAttribs failed (OpenGL 4.5 core profile)")
        self._buffer = (ctypes.c_ubyte * 4)()
        if not lib.OSMesaMakeCurrent(self._ctx, self._buffer, 0x1401, 1, 1):  # GL_UNSIGNED_BYTE
            raise OSError("OSMesaMakeCurrent failed")
        self._lib = lib

    def load_opengl_function(self, name: str) -> int:
        return self._lib.OSMesaGetProcAddress(name.encode()) or 0

    def __enter__(self):  # moderngl's Context.__enter__ calls this: make our context current
        self._lib.OSMesaMakeCurrent(self._ctx, self._buffer, 0x1401, 1, 1)

    def __exit__(self, *exc):  # OSMesa cannot restore another API's context; leave ours current
        pass

    def release(self) -> None:
        if self._ctx:
            self._lib.OSMesaDestroyContext(self._ctx)
            self._ctx = None


_INCLUDE = re.compile(r'^#include "([^"]+)"\s*$', re.MULTILINE)


def shader_source(name: str, defines: dict | None = None) -> str:
    """GLSL text of ``shaders/<name>`` with ``#include "x"`` expanded (nested too, each file once),
    and ``defines`` and the binding slots of :mod:`xrayraster.gl.bindings` inserted."""
    included: set[str] = set()

    def expand(match) -> str:
        if match.group(1) in included:
            return ""
        included.add(match.group(1))
        return _INCLUDE.sub(expand, read_shader(match.group(1)))

    text = _INCLUDE.sub(expand, read_shader(name))
    defines = {**(defines or {}), **binding_defines()}
    head, _, body = text.partition("\n")  # '#version' must stay the first line
    return head + "\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items()) + body
