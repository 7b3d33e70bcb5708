"""Path lengths through closed meshes, per material, for every detector pixel (OpenGL).

How a view is rendered
----------------------
Every triangle is drawn as a conservative screen-space box around its projection; the fragment
stage then intersects the pixel's own ray (source → pixel centre, or the parallel ray) with the
exact triangle in float32, watertight (``shaders/ray.glsl``). A crossing where the ray leaves a
solid adds its distance ``t`` and one where it enters subtracts it. Distances are measured from
a point beside the scene, not from the source (``raysetup.py``), so the error does not grow with
the source distance, and the rasteriser's sub-pixel snapping never decides which triangle a ray
hits.

* ``method="sum"``: one additive pass per material, for scenes whose objects do not overlap.
* ``method="resolve"``: every crossing goes into a per-pixel list, which a compute pass sorts
  and sweeps: between two crossings the highest-priority object the ray is inside owns the
  length. Used when objects overlap.

``overlap="auto"`` (default) picks ``sum`` unless :meth:`Scene.overlaps` finds overlapping
objects; the choice is logged and kept in :attr:`Renderer.last_method`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import moderngl
import numpy as np

from .geometry import VectorGeometry, as_vector_geometry
from .glcontext import GLContext
from .raysetup import view_rays
from .scene import Scene, SceneError

log = logging.getLogger("xrayraster")

_END = 0xFFFFFFFF
_NODE_BYTES = 16
_MIN_CROSSINGS = 16


class RenderError(ValueError):
    """A render request cannot be met; the message names the problem and the fix."""


@dataclass
class _SceneBuffers:
    """A scene uploaded once (vertices relative to ``ref``) and reused for every view."""

    scene: Scene
    revision: int
    ref: np.ndarray
    vertices: moderngl.Buffer
    faces: moderngl.Buffer
    objects: list  # SceneObjects in draw order (by channel, then insertion)
    ranges: list  # per object, in draw order: (first_vertex, vertex_count, channel, rank)
    channel_ranges: list  # per channel: (first_vertex, vertex_count)
    corners: np.ndarray  # (8, 3) bounding-box corners relative to ref

    def release(self) -> None:
        self.vertices.release()
        self.faces.release()


class Renderer:
    """Renders path lengths for a scan geometry; owns (or borrows) one :class:`GLContext`.

    ``supersampling=k`` averages k×k rays per pixel (sub-pixel centres on a regular grid):
    a time-versus-error knob at silhouettes, cost ∝ k².
    """

    def __init__(self, geometry, *, supersampling: int = 1, overlap: str = "auto", context: GLContext | None = None):
        self.geometry = geometry
        self._vec = as_vector_geometry(geometry)
        if int(supersampling) != supersampling or supersampling < 1:
            raise RenderError(f"supersampling must be a positive integer, got {supersampling!r}")
        if overlap not in ("auto", "sum", "resolve"):
            raise RenderError(f"overlap must be 'auto', 'sum' or 'resolve', got {overlap!r}")
        self.supersampling = int(supersampling)
        self.overlap = overlap
        self._render_vec = _refine(self._vec, self.supersampling)
        self._owns_context = context is None
        self.gl = context or GLContext()
        self._check_size()
        self._scene: _SceneBuffers | None = None
        self._targets: list[moderngl.Framebuffer] = []
        self._lists: dict = {}
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
        if not -self._vec.num_views <= view < self._vec.num_views:
            raise RenderError(f"view {view} is out of range: the geometry has {self._vec.num_views} views")
        view %= self._vec.num_views
        buffers = self._upload(scene)
        method = self._choose_method(scene)
        skip = self._objects_behind_source(buffers, view)
        rays = view_rays(self._render_vec, view, buffers.ref)
        if method == "sum":
            out = self._render_sum(buffers, rays, skip)
        else:
            out = self._render_resolve(buffers, rays, skip)
        k = self.supersampling
        if k > 1:
            c, r, q = out.shape
            out = out.reshape(c, r // k, k, q // k, k).mean(axis=(2, 4), dtype=np.float64).astype(np.float32)
        np.maximum(out, 0.0, out=out)
        return out

    def release(self) -> None:
        if self._scene is not None:
            self._scene.release()
            self._scene = None
        for fbo in self._targets:
            for tex in fbo.color_attachments:
                tex.release()
            fbo.release()
        self._targets = []
        for obj in self._lists.values():
            if hasattr(obj, "release"):
                obj.release()
        self._lists = {}
        if self._owns_context and self.gl is not None:
            self.gl.release()
        self.gl = None

    close = release

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    # -- setup ------------------------------------------------------------------------------

    def _check_size(self) -> None:
        rows, cols = self._render_vec.detector_shape
        limit = min(self.gl.ctx.info["GL_MAX_TEXTURE_SIZE"], *self.gl.ctx.info["GL_MAX_VIEWPORT_DIMS"])
        if max(rows, cols) > limit:
            raise RenderError(
                f"detector_shape {self._vec.detector_shape} × supersampling {self.supersampling} = {rows}×{cols} "
                f"exceeds this GL driver's limit of {limit} pixels per side; use fewer pixels or less supersampling"
            )
        need = rows * cols * (4 * 3 + _NODE_BYTES * _MIN_CROSSINGS)  # one channel + lists, lower bound
        free = _available_memory()
        if free is not None and need > free:
            raise RenderError(
                f"detector_shape {self._vec.detector_shape} × supersampling {self.supersampling} needs at least "
                f"{need / 2**30:.1f} GiB but only {free / 2**30:.1f} GiB is available; reduce the detector size"
            )

    def _upload(self, scene: Scene) -> _SceneBuffers:
        cached = self._scene
        if cached is not None and cached.scene is scene and cached.revision == scene.revision:
            return cached
        if cached is not None:
            cached.release()
        bounds = scene.bounds
        ref = bounds.mean(axis=0)
        channels = scene.materials
        ranked = sorted(scene.objects, key=lambda o: o.rank)
        rank_of = {o.order: i for i, o in enumerate(ranked)}
        draw_order = sorted(scene.objects, key=lambda o: (channels.index(o.material), o.order))
        verts, faces, ranges, base, first = [], [], [], 0, 0
        for o in draw_order:
            verts.append((o.mesh.vertices - ref).astype(np.float32))
            faces.append((o.mesh.faces + base).astype(np.uint32))
            count = 3 * len(o.mesh.faces)
            ranges.append((first, count, channels.index(o.material), rank_of[o.order]))
            base += len(o.mesh.vertices)
            first += count
        channel_ranges = []
        for c in range(len(channels)):
            mine = [r for r in ranges if r[2] == c]
            channel_ranges.append((mine[0][0], sum(r[1] for r in mine)))
        ctx = self.gl.ctx
        corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]]) - ref
        self._scene = _SceneBuffers(
            scene=scene,
            revision=scene.revision,
            ref=ref,
            vertices=ctx.buffer(np.concatenate(verts).tobytes()),
            faces=ctx.buffer(np.concatenate(faces).tobytes()),
            objects=draw_order,
            ranges=ranges,
            channel_ranges=channel_ranges,
            corners=corners,
        )
        return self._scene

    def _choose_method(self, scene: Scene) -> str:
        if self.overlap != "auto":
            method, why = self.overlap, "forced"
        else:
            pairs = scene.overlaps()
            method = "resolve" if pairs else "sum"
            why = f"{len(pairs)} overlapping pairs" if pairs else "no overlaps"
        if method != self.last_method:
            log.info("path lengths: method=%s (%s)", method, why)
        self.last_method = method
        return method

    def _objects_behind_source(self, buffers: _SceneBuffers, view: int) -> set:
        """Indices (draw order) of objects wholly behind a cone-beam source, which no ray reaches.

        An object that straddles the source plane is refused: its path lengths are undefined.
        """
        if self._vec.beam != "cone":
            return set()
        src, det, u, v = np.split(self._vec.array[view], 4)
        normal = np.cross(u, v)
        normal *= np.sign(normal @ (det - src))
        offset = (buffers.ref - src) @ normal  # depth of X is (X - ref)·normal + offset
        if np.all(buffers.corners @ normal + offset > 0):
            return set()
        skip = set()
        for index, o in enumerate(buffers.objects):
            depth = (o.mesh.vertices - buffers.ref) @ normal + offset
            if np.all(depth <= 0):
                skip.add(index)
            elif np.any(depth <= 0):
                raise SceneError(
                    f"object {o.name!r} crosses the source plane in view {view}: the source would sit inside "
                    "or beside it. Move the object or the source (source_to_origin) so the object is in front of it."
                )
        if len(skip) < len(buffers.objects) and np.allclose(buffers.ref, src, rtol=0, atol=1e-9 * (1 + np.abs(src).max())):
            raise SceneError(f"view {view}: the source sits at the centre of the scene's bounding box; move it")
        return skip

    def _set_view_uniforms(self, prog: moderngl.Program, rays) -> None:
        rows, cols = self._render_vec.detector_shape
        prog["u_origin_num"].write(rays.origin_num.astype(np.float32).tobytes())
        prog["u_origin_den"].write(rays.origin_den.astype(np.float32).tobytes())
        prog["u_direction"].write(rays.direction.astype(np.float32).tobytes())
        prog["u_half_detector"].value = (cols / 2.0, rows / 2.0)
        prog["u_world_to_pixel"].write(rays.world_to_pixel.astype(np.float32).tobytes())

    def _bind_scene(self, buffers: _SceneBuffers) -> None:
        buffers.vertices.bind_to_storage_buffer(0)
        buffers.faces.bind_to_storage_buffer(1)

    # -- single additive pass -------------------------------------------------------------------

    def _render_sum(self, buffers: _SceneBuffers, rays, skip: set) -> np.ndarray:
        ctx = self.gl.ctx
        rows, cols = self._render_vec.detector_shape
        prog = self.gl.program("pathlength.vert", "pathlength_sum.frag")
        self._set_view_uniforms(prog, rays)
        self._bind_scene(buffers)
        vao = self._vao(prog)
        out = np.empty((len(buffers.channel_ranges), rows, cols), dtype=np.float32)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        try:
            for c in range(len(buffers.channel_ranges)):
                fbo = self._target(c)
                fbo.use()
                fbo.clear(0.0)
                for index, (first, count, channel, _) in enumerate(buffers.ranges):
                    if channel == c and index not in skip:
                        vao.render(moderngl.TRIANGLES, vertices=count, first=first)
                out[c] = np.frombuffer(fbo.read(components=1, dtype="f4"), dtype=np.float32).reshape(rows, cols)
        finally:
            ctx.disable(moderngl.BLEND)
        return out

    def _target(self, channel: int) -> moderngl.Framebuffer:
        ctx = self.gl.ctx
        rows, cols = self._render_vec.detector_shape
        while len(self._targets) <= channel:
            tex = ctx.texture((cols, rows), 1, dtype="f4")
            self._targets.append(ctx.framebuffer(color_attachments=[tex]))
        return self._targets[channel]

    def _vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        key = ("vao", prog.glo)
        if key not in self._lists:
            self._lists[key] = self.gl.ctx.vertex_array(prog, [])
        return self._lists[key]

    # -- overlap resolution: per-pixel crossing lists ---------------------------------------------

    def _render_resolve(self, buffers: _SceneBuffers, rays, skip: set) -> np.ndarray:
        ctx = self.gl.ctx
        rows, cols = self._render_vec.detector_shape
        npix = rows * cols
        nch = len(buffers.channel_ranges)
        lists = self._crossing_lists(buffers)
        collect = self.gl.program("pathlength.vert", "pathlength_collect.frag")
        self._set_view_uniforms(collect, rays)
        vao = self._vao(collect)
        while True:
            self._bind_scene(buffers)
            lists["heads"].bind_to_image(0, read=True, write=True)
            lists["nodes"].bind_to_storage_buffer(2)
            lists["counter"].write(np.zeros(1, np.uint32).tobytes())
            lists["counter"].bind_to_storage_buffer(3)
            collect["u_capacity"].value = lists["capacity"]
            self._target(0).use()
            for index, (first, count, _, rank) in enumerate(buffers.ranges):
                if index not in skip:
                    collect["u_rank"].value = rank
                    vao.render(moderngl.TRIANGLES, vertices=count, first=first)
            ctx.memory_barrier()
            used = int(np.frombuffer(lists["counter"].read(), np.uint32)[0])
            if used > lists["capacity"]:
                self._grow_node_pool(lists, used)
                continue
            depth = lists["max_crossings"]
            resolve = self.gl.compute("pathlength_resolve.comp", {"MAX_CROSSINGS": depth, "NUM_CHANNELS": nch})
            lists["rank_channel"].bind_to_storage_buffer(4)
            lists["lengths"].bind_to_storage_buffer(5)
            lists["overflow"].write(np.zeros(2, np.uint32).tobytes())
            lists["overflow"].bind_to_storage_buffer(6)
            resolve["u_size"].value = (cols, rows)
            resolve.run((cols + 7) // 8, (rows + 7) // 8, 1)
            ctx.memory_barrier()
            overflow, max_depth = np.frombuffer(lists["overflow"].read(), np.uint32)
            if overflow:
                lists["max_crossings"] = int(2 ** np.ceil(np.log2(max_depth)))
                log.info("path lengths: %d pixels with up to %d crossings; re-rendering", overflow, max_depth)
                continue
            data = np.frombuffer(lists["lengths"].read(size=4 * nch * npix), dtype=np.float32)
            return data.reshape(nch, rows, cols).copy()

    def _crossing_lists(self, buffers: _SceneBuffers) -> dict:
        ctx = self.gl.ctx
        rows, cols = self._render_vec.detector_shape
        nch = len(buffers.channel_ranges)
        lists = self._lists
        if "heads" not in lists:
            lists["heads"] = ctx.texture((cols, rows), 1, dtype="u4")
            lists["heads"].write(np.full(rows * cols, _END, np.uint32).tobytes())
            lists["capacity"] = 0
            lists["nodes"] = ctx.buffer(reserve=_NODE_BYTES)
            lists["counter"] = ctx.buffer(reserve=4)
            lists["overflow"] = ctx.buffer(reserve=8)
            lists["max_crossings"] = _MIN_CROSSINGS
            self._grow_node_pool(lists, 4 * rows * cols)
        table = np.zeros(len(buffers.ranges), np.uint32)
        for _, _, channel, rank in buffers.ranges:
            table[rank] = channel
        if "rank_channel" in lists:
            lists["rank_channel"].release()
            lists["lengths"].release()
        lists["rank_channel"] = ctx.buffer(table.tobytes())
        lists["lengths"] = ctx.buffer(reserve=4 * nch * rows * cols)
        return lists

    def _grow_node_pool(self, lists: dict, needed: int) -> None:
        rows, cols = self._render_vec.detector_shape
        capacity = int(needed * 1.25) + 1024
        size = capacity * _NODE_BYTES
        free = _available_memory()
        if free is not None and size > free // 2:
            raise RenderError(
                f"the scene has {needed} ray-surface crossings in one view ({needed / (rows * cols):.0f} per pixel); "
                f"storing them needs {size / 2**30:.1f} GiB. Reduce the detector size or supersampling, "
                "or render without overlap resolution (overlap='sum') if the objects do not really overlap"
            )
        lists["nodes"].release()
        lists["nodes"] = self.gl.ctx.buffer(reserve=size)
        lists["capacity"] = capacity
        # A list cut short by the overflow is in the heads image: empty every list.
        lists["heads"].write(np.full(rows * cols, _END, np.uint32).tobytes())


def _refine(vec: VectorGeometry, k: int) -> VectorGeometry:
    """The same detector with k×k sub-pixels (centres of a regular sub-grid of each pixel)."""
    if k == 1:
        return vec
    arr = vec.array.copy()
    arr[:, 6:12] /= k
    rows, cols = vec.detector_shape
    return VectorGeometry(vec.beam, (rows * k, cols * k), arr)


def _available_memory() -> int | None:
    """Bytes of memory available to this process (Linux), or None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None

