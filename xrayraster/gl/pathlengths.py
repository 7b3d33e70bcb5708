"""Path lengths through closed meshes, per material, for every detector pixel (OpenGL).

How a view is rendered
----------------------
Every crossing of a pixel's ray (source → pixel centre, or the parallel ray) with a triangle is
found by an exact, watertight float32 ray-triangle test (``shaders/ray.glsl``), never by the
rasteriser's coverage rules, so its sub-pixel snapping never decides which triangle a ray hits.
Distances are measured from a point beside the scene, not from the source (``xrayraster/gl/rays.py``),
so the error does not grow with the source distance. Two passes find the candidate pixels:

1. a compute pass over all triangles (``shaders/pathlength_small.comp``) tests a triangle whose
   projected box holds at most ``small_triangle_pixels`` pixel centres against each of them,
   and lists the larger triangles;
2. the rasteriser draws each listed triangle grown by a margin (``shaders/grow.glsl``), and the
   fragment stage runs the exact test for every pixel it covers.

Dense meshes of sub-pixel triangles (most real scans) are cheaper in pass 1, whose cost is per
triangle and parallel on every core; large triangles in pass 2, whose cost is per pixel.

Crossings are recorded by one of two methods (``shaders/crossing.glsl``):

* ``method="sum"``: an exit adds its distance ``t`` and an entry subtracts it, in a 32-bit
  fixed-point accumulator per material and pixel: exact, order-independent, so a view renders to
  the same bytes every time. For scenes whose objects do not overlap.
* ``method="nested"``: the same single pass when every overlap is one object wholly inside
  another (yarns in a matrix block, inclusions): each object also takes its length off its
  container's channel (:meth:`Scene.nesting`), which is the priority rule without sorting.
* ``method="resolve"``: every crossing goes into a per-pixel list, which a compute pass sorts
  and sweeps: between two crossings the highest-priority object the ray is inside owns the
  length. Used when objects overlap partially.

``overlap="auto"`` (default) picks ``sum`` when :meth:`Scene.overlaps` finds no overlapping
objects, ``nested`` when all overlaps are containments, else ``resolve``; the choice is logged
and kept in :attr:`PathLengthRenderer.last_method`, and any method can be forced.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import moderngl
import numpy as np

from ..core.choices import OVERLAP_MODES, check_choice
from ..core.errors import RenderError, SceneError
from ..core.geometry import VectorGeometry, as_vector_geometry
from ..core.memory import available_memory
from ..scene.scene import Scene
from .context import GLContext
from .rays import view_rays

log = logging.getLogger("xrayraster")

_END = 0xFFFFFFFF
_NODE_BYTES = 16
_MIN_CROSSINGS = 16
_SMALL_TRIANGLE_PIXELS = 64  # measured: 32-128 equally fast on llvmpipe at 256²-2048²


@dataclass
class _SceneBuffers:
    """A scene uploaded once (vertices relative to ``ref``) and reused for every view.

    Objects are numbered by rank (priority, then insertion), so the overlap pass can compare
    owners by index; every triangle carries its object's number.
    """

    scene: Scene
    revision: int
    ref: np.ndarray
    triangles: moderngl.Buffer  # 3 vec4 per triangle: corners (mm, relative to ref), object in w
    objects: moderngl.Buffer  # uvec4 per object: channel, drawn in this view, container channel + 1, label
    large: moderngl.Buffer  # indirect draw command + indices of the triangles pass 2 draws
    large_corners: moderngl.Buffer  # the six window-space corners pass 2 draws for each
    ranked: list  # SceneObjects by rank
    channels: np.ndarray  # channel of each object, by rank
    num_channels: int
    num_triangles: int
    fixed_scale: float  # fixed-point units per mm of the sum accumulators
    corners: np.ndarray  # (8, 3) bounding-box corners relative to ref

    def release(self) -> None:
        for buffer in (self.triangles, self.objects, self.large, self.large_corners):
            buffer.release()


class PathLengthRenderer:
    """Renders path lengths for a scan geometry; owns (or borrows) one :class:`GLContext`.

    :class:`xrayraster.Renderer` adds radiographs on top (:mod:`xrayraster.simulate`).

    ``supersampling=k`` averages k×k rays per pixel (sub-pixel centres on a regular grid):
    a time-versus-error knob at silhouettes, cost ∝ k².

    ``small_triangle_pixels``: a triangle whose pixel box holds at most this many pixel centres
    is tested pixel by pixel in a compute pass; larger ones go through the rasteriser. It only
    moves work between two exact paths (the result is the same); 0 rasterises everything.
    """

    def __init__(
        self,
        geometry,
        *,
        supersampling: int = 1,
        overlap: str = "auto",
        small_triangle_pixels: int = _SMALL_TRIANGLE_PIXELS,
        context: GLContext | None = None,
    ):
        self.geometry = geometry
        self.vector_geometry = as_vector_geometry(geometry)
        if int(supersampling) != supersampling or supersampling < 1:
            raise RenderError(f"supersampling must be a positive integer, got {supersampling!r}")
        check_choice(overlap, OVERLAP_MODES, "overlap", RenderError)
        if int(small_triangle_pixels) != small_triangle_pixels or small_triangle_pixels < 0:
            raise RenderError(f"small_triangle_pixels must be an integer >= 0, got {small_triangle_pixels!r}")
        self.supersampling = int(supersampling)
        self.overlap = overlap
        self.small_triangle_pixels = int(small_triangle_pixels)
        self._render_vec = _refine(self.vector_geometry, self.supersampling)
        self._owns_context = context is None
        self.gl = context or GLContext()
        self._check_size()
        # Vertices snap to 2^-bits px; 1/64 px is 8x that on the usual 8 sub-pixel bits.
        self._snap_margin = max(1.0 / 64.0, 4.0 * 2.0 ** -int(self.gl.ctx.info.get("GL_SUBPIXEL_BITS", 4)))
        self._max_groups = int(self.gl.ctx.info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"][0])
        self._scene: _SceneBuffers | None = None
        self._buffers: dict[str, moderngl.Buffer] = {}
        self._capacity = 0  # crossing nodes the node pool holds
        self._max_crossings = _MIN_CROSSINGS
        self.last_method: str | None = None

    # -- public API -------------------------------------------------------------------------

    def path_lengths(self, scene: Scene, view: int = 0) -> np.ndarray:
        """Float32 ``(materials, rows, cols)`` path lengths in mm for one view.

        Channels follow ``scene.materials``. Lengths are clamped at 0 (float rounding can leave
        −1e-7 mm where a ray grazes a silhouette).
        """
        if not isinstance(scene, Scene):
            raise RenderError(f"expected a Scene, got {type(scene).__name__}")
        scene.require_objects()
        if not -self.vector_geometry.num_views <= view < self.vector_geometry.num_views:
            raise RenderError(f"view {view} is out of range: the geometry has {self.vector_geometry.num_views} views")
        view %= self.vector_geometry.num_views
        method = self._choose_method(scene)
        with self.gl.current():
            buffers = self._upload(scene)
            table = np.zeros((len(buffers.ranked), 4), np.uint32)
            table[:, 0] = buffers.channels
            table[:, 1] = self._active_objects(buffers, view)
            if method == "nested":
                drawn, container = _nesting_columns(scene, buffers).T
                table[:, 1] *= drawn
                table[:, 2] = container
            buffers.objects.write(table.tobytes())
            rays = view_rays(self._render_vec, view, buffers.ref)
            if method in ("sum", "nested"):
                out = self._render_sum(buffers, rays)
            else:
                out = self._render_resolve(buffers, rays)
        k = self.supersampling
        if k > 1:
            c, r, q = out.shape
            out = out.reshape(c, r // k, k, q // k, k).mean(axis=(2, 4), dtype=np.float64).astype(np.float32)
        np.maximum(out, 0.0, out=out)
        return out

    def release(self) -> None:
        if self.gl is None:
            return
        with self.gl.current():
            if self._scene is not None:
                self._scene.release()
                self._scene = None
            for buffer in self._buffers.values():
                buffer.release()
            self._buffers = {}
        if self._owns_context and self.gl is not None:
            self.gl.release()
        self.gl = None

    close = release

    def __enter__(self) -> "PathLengthRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    # -- setup ------------------------------------------------------------------------------

    def _check_size(self) -> None:
        rows, cols = self._render_vec.detector_shape
        limit = min(self.gl.ctx.info["GL_MAX_TEXTURE_SIZE"], *self.gl.ctx.info["GL_MAX_VIEWPORT_DIMS"])
        if max(rows, cols) > limit:
            raise RenderError(
                f"detector_shape {self.vector_geometry.detector_shape} × supersampling {self.supersampling} = {rows}×{cols} "
                f"exceeds this GL driver's limit of {limit} pixels per side; use fewer pixels or less supersampling"
            )
        need = rows * cols * (4 * 3 + _NODE_BYTES * _MIN_CROSSINGS)  # one channel + lists, lower bound
        free = available_memory()
        if free is not None and need > free:
            raise RenderError(
                f"detector_shape {self.vector_geometry.detector_shape} × supersampling {self.supersampling} needs at least "
                f"{need / 2**30:.1f} GiB but only {free / 2**30:.1f} GiB is available; reduce the detector size"
            )

    def _upload(self, scene: Scene) -> _SceneBuffers:
        cached = self._scene
        if cached is not None and cached.scene is scene and cached.revision == scene.revision:
            return cached
        if cached is not None:
            cached.release()
            self._scene = None
        bounds = scene.bounds
        ref = bounds.mean(axis=0)
        materials = scene.materials
        ranked = sorted(scene.objects, key=lambda o: o.rank)
        soups = []
        for number, o in enumerate(ranked):
            soup = np.zeros((len(o.mesh.faces), 3, 4), np.float32)
            soup[:, :, :3] = (o.mesh.vertices - ref).astype(np.float32)[o.mesh.faces]
            soup[:, 0, 3] = np.array(number, np.uint32).view(np.float32)
            soups.append(soup)
        num_triangles = sum(len(t) for t in soups)
        # Fixed point: the largest total (one bounding-box diagonal) must stay below 2^31 units.
        diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
        fixed_scale = 2.0 ** np.floor(np.log2(2.0**30 / diagonal))
        ctx = self.gl.ctx
        corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]]) - ref
        self._scene = _SceneBuffers(
            scene=scene,
            revision=scene.revision,
            ref=ref,
            triangles=ctx.buffer(np.concatenate(soups).tobytes()),
            objects=ctx.buffer(reserve=16 * len(ranked)),
            large=ctx.buffer(reserve=4 * (4 + num_triangles)),
            large_corners=ctx.buffer(reserve=6 * 8 * num_triangles),
            ranked=ranked,
            channels=np.array([materials.index(o.material) for o in ranked], np.uint32),
            num_channels=len(materials),
            num_triangles=num_triangles,
            fixed_scale=float(fixed_scale),
            corners=corners,
        )
        return self._scene

    def _choose_method(self, scene: Scene) -> str:
        if self.overlap == "nested" and scene.nesting() is None:
            raise RenderError("overlap='nested' needs every overlap to be one object wholly inside another; "
                              "this scene has partial overlaps: use overlap='resolve' or 'auto'")
        if self.overlap != "auto":
            method, why = self.overlap, "forced"
        elif not (pairs := scene.overlaps()):
            method, why = "sum", "no overlaps"
        elif scene.nesting() is not None:
            method, why = "nested", f"{len(pairs)} overlapping pairs, each one object inside another"
        else:
            method, why = "resolve", f"{len(pairs)} overlapping pairs, some partial"
        if method != self.last_method:
            log.info("path lengths: method=%s (%s)", method, why)
        self.last_method = method
        return method

    def _active_objects(self, buffers: _SceneBuffers, view: int) -> np.ndarray:
        """Per object (by rank): 0 when wholly behind a cone-beam source, which no ray reaches.

        An object that straddles the source plane is refused: its path lengths are undefined.
        """
        active = np.ones(len(buffers.ranked), np.uint32)
        if self.vector_geometry.beam != "cone":
            return active
        src, det, u, v = np.split(self.vector_geometry.array[view], 4)
        normal = np.cross(u, v)
        normal *= np.sign(normal @ (det - src))
        offset = (buffers.ref - src) @ normal  # depth of X is (X - ref)·normal + offset
        if np.all(buffers.corners @ normal + offset > 0):
            return active
        for number, o in enumerate(buffers.ranked):
            depth = (o.mesh.vertices - buffers.ref) @ normal + offset
            if np.all(depth <= 0):
                active[number] = 0
            elif np.any(depth <= 0):
                raise SceneError(
                    f"object {o.name!r} crosses the source plane in view {view}: the source would sit inside "
                    "or beside it. Move the object or the source (source_to_origin) so the object is in front of it."
                )
        if active.any() and np.allclose(buffers.ref, src, rtol=0, atol=1e-9 * (1 + np.abs(src).max())):
            raise SceneError(f"view {view}: the source sits at the centre of the scene's bounding box; move it")
        return active

    # -- crossings: every exact ray-triangle hit, recorded by crossing.glsl ------------------

    def _record_crossings(self, buffers: _SceneBuffers, rays, defines: dict, uniforms: dict) -> None:
        """Pass 1 (compute: small triangles) then pass 2 (rasteriser: the large ones it listed)."""
        ctx = self.gl.ctx
        rows, cols = self._render_vec.detector_shape
        defines = {**defines, "MAX_SMALL_PIXELS": self.small_triangle_pixels}
        small = self.gl.compute("pathlength_small.comp", defines)
        large = self.gl.program("pathlength_large.vert", "pathlength_large.frag", defines)
        uniforms = {
            **uniforms,
            "u_origin_num": rays.origin_num,
            "u_origin_den": rays.origin_den,
            "u_direction": rays.direction,
            "u_world_to_pixel": rays.world_to_pixel,
            "u_half_detector": (cols / 2.0, rows / 2.0),
            "u_size": (cols, rows),
            "u_num_triangles": buffers.num_triangles,
            "u_snap_margin": self._snap_margin,
        }
        for prog in (small, large):
            _set_uniforms(prog, uniforms)
        for binding, buffer in ((0, buffers.triangles), (2, buffers.objects), (3, buffers.large)):
            buffer.bind_to_storage_buffer(binding)
        buffers.large_corners.bind_to_storage_buffer(7)
        buffers.large.write(np.array([0, 1, 0, 0], np.uint32).tobytes())  # empty draw command
        groups = (buffers.num_triangles + 63) // 64
        wide = min(groups, self._max_groups)
        small.run(wide, (groups + wide - 1) // wide)
        ctx.memory_barrier()
        self._empty_framebuffer().use()
        self._vao(large).render_indirect(buffers.large, moderngl.TRIANGLES, count=1)
        ctx.memory_barrier()

    def _empty_framebuffer(self) -> moderngl.Framebuffer:
        if "framebuffer" not in self._buffers:
            rows, cols = self._render_vec.detector_shape
            self._buffers["framebuffer"] = self.gl.ctx.empty_framebuffer((cols, rows))
        return self._buffers["framebuffer"]

    def _vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        key = f"vao{prog.glo}"
        if key not in self._buffers:
            self._buffers[key] = self.gl.ctx.vertex_array(prog, [])
        return self._buffers[key]

    def _buffer(self, name: str, size: int) -> moderngl.Buffer:
        """A scratch buffer of at least ``size`` bytes, kept between views."""
        buffer = self._buffers.get(name)
        if buffer is None or buffer.size < size:
            if buffer is not None:
                buffer.release()
            buffer = self._buffers[name] = self.gl.ctx.buffer(reserve=size)
        return buffer

    # -- single pass: signed distances summed per pixel ------------------------------------------

    def _render_sum(self, buffers: _SceneBuffers, rays) -> np.ndarray:
        rows, cols = self._render_vec.detector_shape
        size = 4 * buffers.num_channels * rows * cols
        acc = self._buffer("accumulators", size)
        acc.clear(size)
        acc.bind_to_storage_buffer(4)
        self._record_crossings(buffers, rays, {}, {"u_fixed_scale": buffers.fixed_scale})
        units = np.frombuffer(acc.read(size=size), dtype=np.int32)
        out = units / buffers.fixed_scale
        return out.astype(np.float32).reshape(buffers.num_channels, rows, cols)

    # -- overlap resolution: per-pixel crossing lists ---------------------------------------------

    def crossing_lists(self, scene: Scene, view: int = 0, skip=None) -> _SceneBuffers:
        """Record every crossing of ``view``'s rays in per-pixel lists and return the uploaded
        scene, for a resolve pass of another stage (the voxelizer). Objects for which
        ``skip(object)`` is true are not tested. Bound on return: objects (2; per object by
        rank: channel, drawn, 0, label), heads (4), nodes (5), counters (6). Call inside
        ``self.gl.current()``."""
        buffers = self._upload(scene)
        table = np.zeros((len(buffers.ranked), 4), np.uint32)
        table[:, 0] = buffers.channels
        table[:, 1] = self._active_objects(buffers, view)
        if skip is not None:
            table[:, 1] *= [not skip(o) for o in buffers.ranked]
        table[:, 3] = [o.label for o in buffers.ranked]
        buffers.objects.write(table.tobytes())
        self._record_lists(buffers, view_rays(self._render_vec, view, buffers.ref))
        buffers.objects.bind_to_storage_buffer(2)
        return buffers

    def resolve_kept_lists(self, shader: str, defines: dict, uniforms: dict) -> None:
        """Run compute pass ``shader`` (8×8 groups over the pixels; it reads the lists of
        :meth:`crossing_lists` without emptying them) with room for MAX_CROSSINGS crossings a
        pixel; where a pixel holds more, it counts an overflow, and the pass runs again wider."""
        rows, cols = self._render_vec.detector_shape
        counters = self._buffers["counters"]
        while True:
            prog = self.gl.compute(shader, {**defines, "MAX_CROSSINGS": self._max_crossings})
            _set_uniforms(prog, uniforms)
            counters.write(np.zeros(4, np.uint32).tobytes())
            prog.run((cols + 7) // 8, (rows + 7) // 8, 1)
            self.gl.ctx.memory_barrier()
            _, overflow, depth, _ = np.frombuffer(counters.read(), np.uint32)
            if not overflow:
                return
            self._max_crossings = int(2 ** np.ceil(np.log2(depth)))
            log.info("%s: pixels with up to %d crossings; running again", shader, depth)

    def empty_lists(self) -> None:
        """Empty the per-pixel lists after a resolve pass that leaves them (the voxelizer's)."""
        rows, cols = self._render_vec.detector_shape
        self._buffers["heads"].write(np.full(rows * cols, _END, np.uint32).tobytes())

    def _record_lists(self, buffers: _SceneBuffers, rays) -> None:
        """Every crossing into the per-pixel lists, growing the node pool until it holds them."""
        rows, cols = self._render_vec.detector_shape
        heads = self._buffers.get("heads")
        if heads is None:
            heads = self._buffers["heads"] = self.gl.ctx.buffer(np.full(rows * cols, _END, np.uint32).tobytes())
            self._grow_node_pool(4 * rows * cols)
        counters = self._buffer("counters", 16)
        while True:
            heads.bind_to_storage_buffer(4)
            self._buffers["nodes"].bind_to_storage_buffer(5)
            counters.write(np.zeros(4, np.uint32).tobytes())
            counters.bind_to_storage_buffer(6)
            self._record_crossings(buffers, rays, {"RESOLVE": 1}, {"u_capacity": self._capacity})
            used = int(np.frombuffer(counters.read(size=4), np.uint32)[0])
            if used <= self._capacity:
                return
            self._grow_node_pool(used)

    def _render_resolve(self, buffers: _SceneBuffers, rays) -> np.ndarray:
        rows, cols = self._render_vec.detector_shape
        npix = rows * cols
        nch = buffers.num_channels
        lengths = self._buffer("lengths", 4 * nch * npix)
        while True:
            self._record_lists(buffers, rays)
            resolve = self.gl.compute("pathlength_resolve.comp", {"MAX_CROSSINGS": self._max_crossings, "NUM_CHANNELS": nch})
            buffers.objects.bind_to_storage_buffer(2)
            lengths.bind_to_storage_buffer(7)
            resolve["u_size"].value = (cols, rows)
            resolve.run((cols + 7) // 8, (rows + 7) // 8, 1)
            self.gl.ctx.memory_barrier()
            _, overflow, max_depth, _ = np.frombuffer(self._buffers["counters"].read(), np.uint32)
            if overflow:  # the pass emptied the lists: record again, with room for the deepest
                self._max_crossings = int(2 ** np.ceil(np.log2(max_depth)))
                log.info("path lengths: %d pixels with up to %d crossings; re-rendering", overflow, max_depth)
                continue
            data = np.frombuffer(lengths.read(size=4 * nch * npix), dtype=np.float32)
            return data.reshape(nch, rows, cols).copy()

    def _grow_node_pool(self, needed: int) -> None:
        rows, cols = self._render_vec.detector_shape
        capacity = int(needed * 1.25) + 1024
        size = capacity * _NODE_BYTES
        free = available_memory()
        if free is not None and size > free // 2:
            raise RenderError(
                f"the scene has {needed} ray-surface crossings in one view ({needed / (rows * cols):.0f} per pixel); "
                f"storing them needs {size / 2**30:.1f} GiB. Reduce the detector size or supersampling, "
                "or render without overlap resolution (overlap='sum') if the objects do not really overlap"
            )
        self._buffer("nodes", size)
        self._capacity = capacity
        self.empty_lists()  # a list cut short by the overflow is in the heads buffer


def _nesting_columns(scene: Scene, buffers: _SceneBuffers) -> np.ndarray:
    """Per object (by rank): (1 if it is drawn else 0, its container's channel + 1 or 0)."""
    nesting = scene.nesting()
    channel = {o.order: c for o, c in zip(buffers.ranked, buffers.channels)}
    columns = np.zeros((len(buffers.ranked), 2), np.uint32)
    columns[:, 0] = 1
    for k, o in enumerate(buffers.ranked):
        container = nesting[o.order]
        if container == o.order or (container is not None and channel[container] == channel[o.order]):
            columns[k, 0] = 0  # hidden, or +L and -L in one channel: nothing to draw
        elif container is not None:
            columns[k, 1] = channel[container] + 1
    return columns


def _set_uniforms(prog, values: dict) -> None:
    """Set the uniforms ``prog`` uses (the compiler drops the ones a stage does not read)."""
    for name, value in values.items():
        if name not in prog:
            continue
        if isinstance(value, np.ndarray):
            prog[name].write(value.astype(np.float32).tobytes())
        else:
            prog[name].value = value


def _refine(vec: VectorGeometry, k: int) -> VectorGeometry:
    """The same detector with k×k sub-pixels (centres of a regular sub-grid of each pixel)."""
    if k == 1:
        return vec
    arr = vec.array.copy()
    arr[:, 6:12] /= k
    rows, cols = vec.detector_shape
    return VectorGeometry(vec.beam, (rows * k, cols * k), arr)
