"""The crossing engine: every exact crossing of a view's rays with a scene's triangles.

Every crossing of a pixel's ray (source → pixel centre, or the parallel ray) with a triangle is
found by an exact, watertight float32 ray-triangle test (``shaders/ray.glsl``), never by the
rasteriser's coverage rules, so its sub-pixel snapping never decides which triangle a ray hits.
Distances are measured from a point beside the scene, not from the source
(``xrayraster/gl/rays.py``), so the error does not grow with the source distance. The passes
that find the candidate pixels and test them:

1. a compute pass over all triangles (``shaders/pathlength_small.comp``) lists, for a triangle
   whose projected box holds at most ``small_triangle_pixels`` pixel centres, the box's pixels
   within the triangle grown as pass 2 grows it (a superset of those the exact test accepts) as
   candidates, two to an entry, and lists the larger triangles apart;
1b. a compute pass over the candidates (``shaders/pathlength_candidates.comp``) runs the exact
   test of each, every SIMD lane busy whatever the size of the boxes (measured: 1.4-1.5x faster
   on llvmpipe than testing each box in pass 1, BENCHMARKS.md);
2. the rasteriser draws each large triangle grown by a margin (``shaders/grow.glsl``), and the
   fragment stage runs the exact test for every pixel it covers.

Dense meshes of sub-pixel triangles (most real scans) are cheaper in pass 1, whose cost is per
triangle and parallel on every core; large triangles in pass 2, whose cost is per pixel.

What a crossing does is ``shaders/crossing.glsl``'s: it adds its signed distance to a
fixed-point accumulator per channel and pixel (:meth:`CrossingEngine.accumulate`), or it joins
the pixel's list (:meth:`CrossingEngine.record_lists`), which a resolve pass then sorts and
sweeps (:meth:`CrossingLists.resolve`): the path lengths' overlap pass and the voxelizer's label
pass are two such resolve passes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import moderngl
import numpy as np

from ..core.errors import RenderError, SceneError
from ..core.geometry import VectorGeometry
from ..core.memory import available_memory
from ..scene.scene import Scene
from .bindings import BINDINGS, TEXTURES
from .context import GLContext
from .rays import view_rays
from .scene_upload import UploadedScene, texel_rows, upload_scene

log = logging.getLogger("xrayraster")

_END = 0xFFFFFFFF
NODE_BYTES = 16
MIN_CROSSINGS = 16  # list room per pixel a resolve pass starts with; widened on overflow
NODE_STRIPE_BITS = 8  # the node pool's 256 stripes, each with its own counter (shaders/crossing.glsl)
CANDIDATES_HEADER = 16  # bytes before the candidate entries: their count, pass 1b's work groups
ENTRY_BYTES = 16  # a candidate entry: a triangle and up to two of its pixels (shaders/candidates.glsl)
# Measured: 32-128 equally fast on llvmpipe at 256²-2048²; on an NVIDIA H200, a twin view at 512² took
# 6.8-7.7 ms with 64 against 12.5-18.8 with every triangle rasterised (0), the same bytes.
SMALL_TRIANGLE_PIXELS = 64
# Pass 1 takes at most three steps a pixel of a triangle's box (its rows twice, its pixels once),
# within the 65535 loop steps llvmpipe allows a shader invocation (shaders/crossing_lists.glsl).
MAX_SMALL_TRIANGLE_PIXELS = 16384


class CrossingEngine:
    """Records the crossings of one detector's rays (``geometry``, pixel for pixel) on ``gl``.

    It borrows the context (its owner releases it) and keeps the uploaded scene and its scratch
    buffers between views; call :meth:`release` when done. Use it inside ``gl.current()``.
    """

    def __init__(self, geometry: VectorGeometry, gl: GLContext, small_triangle_pixels: int = SMALL_TRIANGLE_PIXELS):
        self.geometry = geometry
        self.gl = gl
        self.small_triangle_pixels = int(small_triangle_pixels)
        # Vertices snap to 2^-bits px; 1/64 px is 8x that on the usual 8 sub-pixel bits.
        self._snap_margin = max(1.0 / 64.0, 4.0 * 2.0 ** -int(gl.ctx.info.get("GL_SUBPIXEL_BITS", 4)))
        self._max_groups = int(gl.ctx.info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"][0])
        self._scene: UploadedScene | None = None
        self._buffers: dict[str, moderngl.Buffer] = {}
        self._stripe_capacity = 0  # crossing nodes each stripe of the node pool holds
        self._candidate_capacity = 0  # candidate entries crossing pass 1 can list (0: sized on the first view)
        self.max_crossings = MIN_CROSSINGS  # list room per pixel of the resolve passes

    @property
    def shape(self) -> tuple[int, int]:
        return self.geometry.detector_shape

    # -- scene ------------------------------------------------------------------------------

    def upload(self, scene: Scene, terms: tuple = ()) -> UploadedScene:
        """The scene on the GPU, with ``terms`` (its :class:`~xrayraster.scene.overlap_terms.OverlapTerm`
        list) after its objects; uploaded again only when either changed (:attr:`Scene.revision`)."""
        cached = self._scene
        if cached is not None and cached.scene is scene and cached.revision == scene.revision and cached.terms is terms:
            return cached
        if cached is not None:
            cached.release()
            self._scene = None
        self._scene = upload_scene(self.gl, scene, terms)
        return self._scene

    def object_table(self, uploaded: UploadedScene, view: int, skip=None) -> np.ndarray:
        """``(objects + terms, 4)`` uint32 by rank: channel, drawn (0 when wholly behind the source or
        ``skip(object)`` is true; a term as its first member), 0 (a container's channel + 1, set by
        nested path lengths), label (0 for a term)."""
        n = len(uploaded.ranked)
        table = np.zeros((n + len(uploaded.terms), 4), np.uint32)
        table[:, 0] = uploaded.channels
        table[:n, 1] = self._in_front_of_source(uploaded, view)
        if skip is not None:
            table[:n, 1] *= [not skip(o) for o in uploaded.ranked]
        table[:n, 3] = uploaded.labels
        table[n:, 1] = table[uploaded.term_rows, 1]  # inside its members: drawn when they are
        return table

    def _in_front_of_source(self, uploaded: UploadedScene, view: int) -> np.ndarray:
        """Per object (by rank): 0 when wholly behind a cone-beam source, which no ray reaches.

        An object that straddles the source plane is refused: its path lengths are undefined.
        """
        active = np.ones(len(uploaded.ranked), np.uint32)
        if self.geometry.beam != "cone":
            return active
        src, det, u, v = np.split(self.geometry.array[view], 4)
        normal = np.cross(u, v)
        normal *= np.sign(normal @ (det - src))
        offset = (uploaded.ref - src) @ normal  # depth of X is (X - ref)·normal + offset
        if np.all(uploaded.corners @ normal + offset > 0):
            return active
        for number, o in enumerate(uploaded.ranked):
            depth = (o.mesh.vertices - uploaded.ref) @ normal + offset
            if np.all(depth <= 0):
                active[number] = 0
            elif np.any(depth <= 0):
                raise SceneError(
                    f"object {o.name!r} crosses the source plane in view {view}: the source would sit inside "
                    "or beside it. Move the object or the source (source_to_origin) so the object is in front of it."
                )
        if active.any() and np.allclose(uploaded.ref, src, rtol=0, atol=1e-9 * (1 + np.abs(src).max())):
            raise SceneError(f"view {view}: the source sits at the centre of the scene's bounding box; move it")
        return active

    # -- the candidate passes ----------------------------------------------------------------

    def _record(self, uploaded: UploadedScene, view: int, table: np.ndarray, defines: dict, uniforms: dict,
                reset) -> None:
        """Pass 1 (compute: the small triangles' candidate pixels), 1b (compute: their exact
        tests), then pass 2 (rasteriser: the large triangles pass 1 listed). When pass 1 listed
        more candidate entries than the buffer holds, the buffer grows and the view runs again
        after ``reset()``, which must undo what the crossings of the cut-short run recorded."""
        texels = texel_rows(len(table), 4, np.uint32)
        texels[:len(table)] = table
        uploaded.objects.write(texels)
        rays = view_rays(self.geometry, view, uploaded.ref)
        rows, cols = self.shape
        defines = {**defines, "MAX_SMALL_PIXELS": self.small_triangle_pixels}
        small = self.gl.compute("pathlength_small.comp", defines)
        groups = self.gl.compute("candidate_groups.comp", defines)
        tests = self.gl.compute("pathlength_candidates.comp", defines)
        large = self.gl.program("pathlength_large.vert", "pathlength_large.frag", defines)
        uniforms = {
            **uniforms,
            "u_origin_num": rays.origin_num,
            "u_origin_den": rays.origin_den,
            "u_direction": rays.direction,
            "u_world_to_pixel": rays.world_to_pixel,
            "u_half_detector": (cols / 2.0, rows / 2.0),
            "u_size": (cols, rows),
            "u_num_triangles": uploaded.num_triangles,
            "u_snap_margin": self._snap_margin,
            "u_max_groups": self._max_groups,
        }
        for name in ("triangles", "objects"):
            getattr(uploaded, name).use(TEXTURES[name])
        for name in ("large", "large_corners"):
            getattr(uploaded, name).bind_to_storage_buffer(BINDINGS[name])
        triangle_groups = (uploaded.num_triangles + 63) // 64
        wide = min(triangle_groups, self._max_groups)
        if not self._candidate_capacity:
            self._candidate_capacity = uploaded.num_triangles + 1024  # about an entry a triangle, measured
        while True:
            capacity = self._candidate_capacity
            candidates = self.scratch("candidates", CANDIDATES_HEADER + ENTRY_BYTES * capacity)
            candidates.write(bytes(CANDIDATES_HEADER))
            candidates.bind_to_storage_buffer(BINDINGS["candidates"])
            uploaded.large.write(np.array([0, 1, 0, 0], np.uint32).tobytes())  # empty draw command
            for prog in (small, groups, tests, large):
                self.gl.set_uniforms(prog, {**uniforms, "u_candidate_capacity": capacity})
            self.gl.dispatch(small, wide, (triangle_groups + wide - 1) // wide)
            self.gl.barrier()
            self.gl.dispatch(groups, 1)
            self.gl.barrier()
            self.gl.dispatch_indirect(tests, candidates, offset=4)
            self.gl.barrier()
            self._empty_framebuffer().use()
            self.gl.draw_indirect(self._vao(large), uploaded.large, moderngl.TRIANGLES)
            self.gl.barrier()
            found = int(self.gl.read(candidates, np.uint32, 1)[0])
            if found <= capacity:
                return
            self._grow_candidates(found)
            reset()

    def _grow_candidates(self, found: int) -> None:
        """Room for ``found`` candidate entries and a quarter more (kept for the later views)."""
        capacity = int(found * 1.25) + 1024
        size = CANDIDATES_HEADER + ENTRY_BYTES * capacity
        self._refuse_unless_room(size, f"the scene's triangles cover up to {2 * found} pixel centres in one view",
                                 2 * found, "listing them")
        self._candidate_capacity = capacity

    def _refuse_unless_room(self, size: int, what: str, count: int, doing: str, fix: str = "") -> None:
        """RenderError naming ``what`` (``count`` of them in a view) unless ``size`` bytes fit in half
        the free memory: a view's lists grow with the scene, and the other half stays for the rest."""
        free = available_memory()
        if free is not None and size > free // 2:
            rows, cols = self.shape
            raise RenderError(f"{what} ({count / (rows * cols):.0f} per pixel); {doing} needs {size / 2**30:.1f} GiB. "
                              f"Reduce the detector size or supersampling{fix}")

    # -- single pass: signed distances summed per pixel ------------------------------------------

    def accumulate(self, uploaded: UploadedScene, view: int, table: np.ndarray, subtract: tuple = ()) -> np.ndarray:
        """Float32 ``(channels, rows, cols)``: per channel and pixel, the sum of each crossing's
        signed distance (exits +t, entries −t; a nested object's also off its container's channel,
        by the shader or, for the ``(container, channel)`` pairs of ``subtract``, here: the container
        channel less the whole channel, in the same wrapping integers, so the same bits)."""
        rows, cols = self.shape
        size = 4 * uploaded.num_channels * rows * cols
        acc = self.scratch("accumulators", size)
        acc.clear(size)
        acc.bind_to_storage_buffer(BINDINGS["accumulators"])
        uniforms = {"u_fixed_scale": uploaded.fixed_scale, "u_containers": bool(table[:, 2].any())}
        self._record(uploaded, view, table, {}, uniforms, lambda: acc.clear(size))
        units = self.gl.read(acc, np.int32, size // 4).reshape(uploaded.num_channels, rows * cols)
        if subtract:
            raw = units.copy()  # a container channel may itself be subtracted from another
            for container, channel in subtract:
                units[container] -= raw[channel]
        # The scale is a power of two: rounding the units to float32 first gives the bits of dividing
        # in float64 and rounding once, a sixth of the time (0.09 against 0.54 ms at 512²).
        out = units.astype(np.float32)
        out *= np.float32(1.0 / uploaded.fixed_scale)
        return out.reshape(uploaded.num_channels, rows, cols)

    # -- per-pixel crossing lists ------------------------------------------------------------------

    def record_lists(self, uploaded: UploadedScene, view: int, table: np.ndarray) -> CrossingLists:
        """Every crossing of ``view`` into per-pixel lists, growing the node pool until they fit.
        Resolve passes read them through the returned handle; release it to empty them."""
        rows, cols = self.shape
        heads = self._buffers.get("heads")
        if heads is None:
            heads = self._buffers["heads"] = self.gl.ctx.buffer(np.full(rows * cols, _END, np.uint32).tobytes())
            self._grow_node_pool(4 * rows * cols >> NODE_STRIPE_BITS)
        stripes = self.scratch("stripes", 4 << NODE_STRIPE_BITS)
        unused = bytes(4 << NODE_STRIPE_BITS)  # no node taken in any stripe
        while True:
            heads.bind_to_storage_buffer(BINDINGS["heads"])
            self._buffers["nodes"].bind_to_storage_buffer(BINDINGS["nodes"])
            stripes.write(unused)
            stripes.bind_to_storage_buffer(BINDINGS["stripes"])
            self._record(uploaded, view, table, {"RESOLVE": 1, "NODE_STRIPE_BITS": NODE_STRIPE_BITS},
                         {"u_stripe_capacity": self._stripe_capacity},
                         lambda: (self._empty_lists(), stripes.write(unused)))
            used = self.gl.read(stripes, np.uint32, 1 << NODE_STRIPE_BITS)
            if used.max() <= self._stripe_capacity:
                return CrossingLists(self, uploaded)
            self._grow_node_pool(int(used.max()), int(used.sum()))

    def _resolve(self, uploaded: UploadedScene, shader: str, defines: dict, uniforms: dict, outputs: dict) -> None:
        """The one overflow loop: run compute pass ``shader`` over the pixels with room for
        MAX_CROSSINGS crossings a pixel; where a list holds more, the pass counts an overflow and
        skips the pixel, and it runs again with room for the deepest list (kept for later views).
        RenderError when the driver cut a pixel's loops short (``shaders/crossing_lists.glsl``)."""
        rows, cols = self.shape
        counters = self.scratch("counters", 12)
        while True:
            prog = self.gl.compute(shader, {**defines, "MAX_CROSSINGS": self.max_crossings})
            self.gl.set_uniforms(prog, uniforms)
            uploaded.objects.use(TEXTURES["objects"])
            for name in ("heads", "nodes"):
                self._buffers[name].bind_to_storage_buffer(BINDINGS[name])
            counters.bind_to_storage_buffer(BINDINGS["counters"])
            for name, buffer in outputs.items():
                buffer.bind_to_storage_buffer(BINDINGS[name])
            counters.write(bytes(12))
            self.gl.dispatch(prog, (cols + 7) // 8, (rows + 7) // 8, 1)
            self.gl.barrier()
            overflow, depth, truncated = self.gl.read(counters, np.uint32, 3)
            if truncated and not overflow:
                raise RenderError(
                    f"{shader}: the rays of {truncated} pixels cross up to {self.max_crossings} surfaces, more than "
                    f"this GL driver ({self.gl.ctx.info['GL_RENDERER']}) sorts in one shader invocation (llvmpipe "
                    "stops an invocation's loops after 65535 steps in all), so their results would be wrong. Use a "
                    "GPU's driver, or passes without the per-pixel sort: path lengths with overlap='sum' or 'nested' "
                    "where no objects overlap partly, labels with method='stencil'")
            if not overflow:
                return
            self.max_crossings = int(2 ** np.ceil(np.log2(depth)))
            log.info("%s: %d pixels with up to %d crossings; running again", shader, overflow, depth)

    def _empty_lists(self) -> None:
        rows, cols = self.shape
        self._buffers["heads"].write(np.full(rows * cols, _END, np.uint32).tobytes())

    def _grow_node_pool(self, per_stripe: int, crossings: int = 0) -> None:
        """Room for ``per_stripe`` nodes in every stripe, with a quarter to spare (``crossings``: the
        view's total, for the message when that cannot fit in memory)."""
        capacity = int(per_stripe * 1.25) + 64
        size = (capacity << NODE_STRIPE_BITS) * NODE_BYTES
        self._refuse_unless_room(size, f"the scene has {crossings} ray-surface crossings in one view",
                                 crossings, "storing them", " or render without overlap resolution (overlap='sum') "
                                 "if the objects do not really overlap")
        self.scratch("nodes", size)
        self._stripe_capacity = capacity
        self._empty_lists()  # a list cut short by the overflow is in the heads buffer

    # -- GL objects kept between views -----------------------------------------------------------

    def scratch(self, name: str, size: int) -> moderngl.Buffer:
        """A buffer of at least ``size`` bytes, kept between views under ``name``."""
        buffer = self._buffers.get(name)
        if buffer is None or buffer.size < size:
            if buffer is not None:
                buffer.release()
            buffer = self._buffers[name] = self.gl.ctx.buffer(reserve=size)
        return buffer

    def _empty_framebuffer(self) -> moderngl.Framebuffer:
        if "framebuffer" not in self._buffers:
            rows, cols = self.shape
            self._buffers["framebuffer"] = self.gl.ctx.empty_framebuffer((cols, rows))
        return self._buffers["framebuffer"]

    def _vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        key = f"vao{prog.glo}"
        if key not in self._buffers:
            self._buffers[key] = self.gl.ctx.vertex_array(prog, [])
        return self._buffers[key]

    def release(self) -> None:
        with self.gl.current():
            if self._scene is not None:
                self._scene.release()
                self._scene = None
            if "framebuffer" in self._buffers:
                # moderngl rebinds the framebuffer bound last after making one (empty_framebuffer): bound
                # and then deleted, ours would be a name GL refuses (GL_INVALID_OPERATION) to the next engine.
                self.gl.ctx.detect_framebuffer(0).use()
            for buffer in self._buffers.values():
                buffer.release()
            self._buffers = {}


@dataclass
class CrossingLists:
    """The per-pixel crossing lists of one view, as :meth:`CrossingEngine.record_lists` left them.

    ``resolve`` runs a resolve pass over them (any number of times: the lists stay), and
    ``release`` (or leaving a ``with`` block) empties them for the next view.
    """

    engine: CrossingEngine
    scene: UploadedScene

    @property
    def ref(self) -> np.ndarray:
        """(3,) mm: crossing distances ``t`` are measured from this point's rays' origin plane."""
        return self.scene.ref

    def resolve(self, shader: str, defines: dict, uniforms: dict, outputs: dict[str, moderngl.Buffer]) -> None:
        """Run ``shader`` (8×8 groups over the pixels; it includes ``crossing_lists.glsl``) with
        ``outputs`` bound by their names in :data:`~xrayraster.gl.bindings.BINDINGS`."""
        self.engine._resolve(self.scene, shader, defines, uniforms, outputs)

    def release(self) -> None:
        self.engine._empty_lists()

    def __enter__(self) -> CrossingLists:
        return self

    def __exit__(self, *exc) -> None:
        self.release()
