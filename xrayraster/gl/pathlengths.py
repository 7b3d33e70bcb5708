"""Path lengths through closed meshes, per material, for every detector pixel (OpenGL).

The crossings of every pixel's ray with the scene's triangles come from the crossing engine
(:mod:`xrayraster.gl.crossings`: exact, watertight, independent of the rasteriser's coverage
rules). This module turns them into lengths by one of three methods:

* ``method="sum"``: an exit adds its distance ``t`` and an entry subtracts it, in a 32-bit
  fixed-point accumulator per material and pixel: exact, order-independent, so a view renders to
  the same bytes every time. For scenes whose objects do not overlap.
* ``method="nested"``: the same single pass when every overlap is one object wholly inside
  another (yarns in a matrix block, inclusions): each object also takes its length off its
  container's channel (:meth:`Scene.nesting`), which is the priority rule without sorting. Partial
  overlaps join it as signed intersection meshes (:meth:`Scene.one_pass`,
  :mod:`xrayraster.scene.overlap_terms`: inclusion–exclusion), as a woven sample's yarns need.
* ``method="resolve"``: every crossing goes into a per-pixel list, which a compute pass
  (``shaders/pathlength_resolve.comp``) sorts and sweeps: between two crossings the
  highest-priority object the ray is inside owns the length. Used when objects overlap partially
  in a way the terms cannot write (:mod:`~xrayraster.scene.overlap_terms` says when).

``overlap="auto"`` (default) picks ``sum`` when :meth:`Scene.overlaps` finds no overlapping
objects, ``nested`` when all overlaps are containments or the partial ones have terms, else
``resolve``; the choice is logged and kept in :attr:`PathLengthRenderer.last_method`, and any
method can be forced.
"""

from __future__ import annotations

import logging

import numpy as np

from ..core.choices import OVERLAP_MODES, check_choice
from ..core.errors import RenderError
from ..core.geometry import VectorGeometry, as_vector_geometry
from ..core.memory import available_memory
from ..scene.scene import Scene
from .context import GLContext
from .crossings import MAX_SMALL_TRIANGLE_PIXELS, MIN_CROSSINGS, NODE_BYTES, SMALL_TRIANGLE_PIXELS, CrossingEngine
from .scene_upload import UploadedScene

log = logging.getLogger("xrayraster")

#: Overlap terms are drawn while their triangles are at most this many a ray; past it the per-pixel
#: sort is cheaper. Measured on llvmpipe (2 cores, ``scripts/bench_one_pass.py``): the one pass was
#: 1.2-1.7x faster than the sort at 0.2-1.2 terms' triangles a ray (twin_small at 256² and 512²,
#: the twin at 512²) and 0.8-0.9x at 3.0 (twin_small at 128²). On a GPU, where the sort is 3-16x
#: slower than a sum (BENCHMARKS.md), the break-even can only lie further out.
TERM_TRIANGLES_PER_RAY = 2
#: A woven scene with up to three triangles a ray is searched for overlap terms
#: (:func:`interpenetrating_overlap`) when its scan has at least this many rays (views × pixels) a
#: triangle: the search costs 3-6 µs a triangle, and the one pass saves about 40 ns a ray where it
#: pays (a 256³ dataset sample: 0.42 s of search, then 8.5 against 11.0 ms a view of 256²).
SEARCH_RAYS_PER_TRIANGLE = 128


class PathLengthRenderer:
    """Renders path lengths for a scan geometry; owns (or borrows) one :class:`GLContext`.

    :class:`xrayraster.Renderer` adds radiographs on top (:mod:`xrayraster.simulate`).

    ``supersampling=k`` averages k×k rays per pixel (sub-pixel centres on a regular grid):
    a time-versus-error knob at silhouettes, cost ∝ k².

    ``small_triangle_pixels``: a triangle whose pixel box holds at most this many pixel centres
    is tested pixel by pixel in a compute pass; larger ones go through the rasteriser. It only
    moves work between two exact paths (the result is the same); 0 rasterises everything, and at
    most :data:`~xrayraster.gl.crossings.MAX_SMALL_TRIANGLE_PIXELS` (16384) may be asked. The
    default, :data:`~xrayraster.gl.crossings.SMALL_TRIANGLE_PIXELS` (64), was the faster on llvmpipe
    and on an NVIDIA H200 alike.
    """

    def __init__(
        self,
        geometry,
        *,
        supersampling: int = 1,
        overlap: str = "auto",
        small_triangle_pixels: int = SMALL_TRIANGLE_PIXELS,
        context: GLContext | None = None,
    ):
        self.geometry = geometry
        self.vector_geometry = as_vector_geometry(geometry)
        if int(supersampling) != supersampling or supersampling < 1:
            raise RenderError(f"supersampling must be a positive integer, got {supersampling!r}")
        check_choice(overlap, OVERLAP_MODES, "overlap", RenderError)
        if (int(small_triangle_pixels) != small_triangle_pixels
                or not 0 <= small_triangle_pixels <= MAX_SMALL_TRIANGLE_PIXELS):
            raise RenderError(f"small_triangle_pixels must be an integer from 0 to {MAX_SMALL_TRIANGLE_PIXELS} (a "
                              f"larger box would outrun llvmpipe's loop limit), got {small_triangle_pixels!r}")
        self.supersampling = int(supersampling)
        self.overlap = overlap
        self._render_vec = _refine(self.vector_geometry, self.supersampling)
        self._owns_context = context is None
        self.gl = context or GLContext()
        self._check_size()
        self.small_triangle_pixels = int(small_triangle_pixels)
        self.engine = CrossingEngine(self._render_vec, self.gl, self.small_triangle_pixels)
        self.last_method: str | None = None
        self._planned: tuple = (None,)  # (scene, its revision, rays, the plan of _plan)
        self._columns: tuple = (None,)  # (uploaded scene, drawn, container column, host subtractions)

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
        method, nesting, terms = self._plan(scene)
        with self.gl.current():
            uploaded = self.engine.upload(scene, terms)
            table = self.engine.object_table(uploaded, view)
            subtract = ()
            if method == "nested":
                if self._columns[0] is not uploaded:
                    self._columns = (uploaded, *_containers(_nesting_columns(nesting, uploaded), uploaded.channels))
                _, drawn, container, subtract = self._columns
                table[:, 1] *= drawn
                table[:, 2] = container
            if method == "resolve":
                out = self._resolve(uploaded, view, table)
            else:
                out = self.engine.accumulate(uploaded, view, table, subtract)
        k = self.supersampling
        if k > 1:
            c, r, q = out.shape
            out = out.reshape(c, r // k, k, q // k, k).mean(axis=(2, 4), dtype=np.float64).astype(np.float32)
        np.maximum(out, 0.0, out=out)
        return out

    def retarget(self, geometry) -> None:
        """Render ``geometry``'s views from now on. With the same detector shape the GL context,
        the compiled shaders, the scratch buffers and the uploaded scene are kept (a preview
        turning the sample or moving the source pays for none of them again); another shape
        starts a new crossing engine on the same context."""
        vector_geometry = as_vector_geometry(geometry)
        render_vec = _refine(vector_geometry, self.supersampling)
        new_shape = render_vec.detector_shape != self._render_vec.detector_shape
        self.geometry, self.vector_geometry, self._render_vec = geometry, vector_geometry, render_vec
        if new_shape:  # checked before the engine's buffers are made, as in __init__
            self._check_size()
            self.engine.release()
            self.engine = CrossingEngine(render_vec, self.gl, self.small_triangle_pixels)
        self.engine.geometry = render_vec

    def release(self) -> None:
        if self.gl is None:
            return
        self.engine.release()
        if self._owns_context:
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
        need = rows * cols * (4 * 3 + NODE_BYTES * MIN_CROSSINGS)  # one channel + lists, lower bound
        free = available_memory()
        if free is not None and need > free:
            raise RenderError(
                f"detector_shape {self.vector_geometry.detector_shape} × supersampling {self.supersampling} needs at least "
                f"{need / 2**30:.1f} GiB but only {free / 2**30:.1f} GiB is available; reduce the detector size"
            )

    def _plan(self, scene: Scene) -> tuple:
        """(method, nesting or None, overlap terms) for ``scene``: chosen once for each revision of the
        scene and detector, not every view (the choice reads every overlap and term)."""
        key = (scene, scene.revision, self._pixels())
        if self._planned[:3] != key:  # a Scene compares by identity
            method = self._choose_method(scene)
            nesting, terms = None, ()
            if method == "nested":
                # Without terms only when slivers below the overlap test's tolerance (1e-6) cannot have
                # them: the overlaps that count are containments, as before terms.
                one_pass = scene.one_pass()
                nesting, terms = (one_pass.nesting, one_pass.terms) if one_pass is not None else (scene.nesting(), ())
            self._planned = (*key, (method, nesting, terms))
        return self._planned[3]

    def _choose_method(self, scene: Scene) -> str:
        if self.overlap == "nested" and scene.one_pass() is None:
            raise RenderError("overlap='nested' needs overlaps that one pass can render (containments, and partial "
                              "overlaps of at most three objects in one container); this scene has others: use "
                              "overlap='resolve' or 'auto'")
        if self.overlap != "auto":
            method, why = self.overlap, "forced"
        elif not (pairs := scene.overlaps()):
            method, why = "sum", "no overlaps"
        elif scene.nesting() is not None:
            method, why = "nested", f"{len(pairs)} overlapping pairs, each one object inside another"
        elif (one_pass := scene.one_pass()) is None:
            method, why = "resolve", f"{len(pairs)} overlapping pairs, some partial beyond what one pass can render"
        elif (extra := sum(len(t.mesh.faces) for t in one_pass.terms)) > TERM_TRIANGLES_PER_RAY * (pixels := self._pixels()):
            method, why = "resolve", (f"{len(pairs)} overlapping pairs, some partial: their {len(one_pass.terms)} "
                                      f"intersection meshes' {extra} triangles would cost more than sorting "
                                      f"{pixels} rays' crossings")
        else:
            method, why = "nested", (f"{len(pairs)} overlapping pairs, the partial ones as {len(one_pass.terms)} "
                                     f"signed intersection meshes ({extra} triangles)")
        if method != self.last_method:
            log.info("path lengths: method=%s (%s)", method, why)
        self.last_method = method
        return method

    def _pixels(self) -> int:
        """The rays of a view (pixels times supersampling²)."""
        rows, cols = self._render_vec.detector_shape
        return rows * cols

    def _resolve(self, uploaded: UploadedScene, view: int, table: np.ndarray) -> np.ndarray:
        rows, cols = self._render_vec.detector_shape
        nch = uploaded.num_channels
        lengths = self.engine.scratch("lengths", 4 * nch * rows * cols)
        lengths.clear()
        with self.engine.record_lists(uploaded, view, table) as lists:
            lists.resolve("pathlength_resolve.comp", {"NUM_CHANNELS": nch},
                          {"u_size": (cols, rows), "u_fixed_scale": uploaded.fixed_scale}, {"output": lengths})
        return self.gl.read(lengths, np.float32, nch * rows * cols).reshape(nch, rows, cols)


def interpenetrating_overlap(scene: Scene, geometry, views: int | None = None) -> str:
    """The overlap method for a scene whose objects are known to cut into each other (a woven
    sample's yarns): ``"auto"`` where the overlap search (manifold3d's booleans) may find terms that
    pay, else ``"resolve"`` at once, without a search that could only end in the sort.

    A weave's terms hold 0.45 (the twin, 700 k triangles) to 1.06 (twin_small, 47 k) of its own
    triangles, so they can pay (:data:`TERM_TRIANGLES_PER_RAY`) where the scene's triangles are at
    most the rays, or a few times them; beyond the rays the search must also pay for itself over the
    scan's views (:data:`SEARCH_RAYS_PER_TRIANGLE`). Measured: the twin (801 views of 512², 2.7
    triangles a ray) searches in 1.9 s and then renders 12 % faster a view; a 256³ dataset sample
    (360 views of 256², 77 k triangles, 1.2 a ray) in 0.42 s, then 23 % faster; a 128³ one (180
    views of 128², 2.9 a ray) would search for 0.27 s, half its GL time, to find terms twice too
    many for its rays. ``views``: how many views will be rendered (default the geometry's; a
    preview, which must show its first frame soon, passes 1)."""
    vec = as_vector_geometry(geometry)
    rays = vec.detector_shape[0] * vec.detector_shape[1]
    views = vec.num_views if views is None else views
    triangles = scene.num_triangles
    if triangles <= rays or (triangles <= 3 * rays and rays * views >= SEARCH_RAYS_PER_TRIANGLE * triangles):
        return "auto"
    return "resolve"


def _nesting_columns(nesting: list[int | None], uploaded: UploadedScene) -> np.ndarray:
    """Per object (by rank), then per term: (1 if it is drawn else 0, its container's channel + 1
    or 0). A term takes the container of its first member, whose channel it counts in."""
    channel = {o.order: c for o, c in zip(uploaded.ranked, uploaded.channels)}
    orders = [o.order for o in uploaded.ranked] + [t.members[0] for t in uploaded.terms]
    columns = np.zeros((len(orders), 2), np.uint32)
    columns[:, 0] = 1
    for k, (order, own) in enumerate(zip(orders, uploaded.channels)):
        container = nesting[order]
        if container == order or (container is not None and channel[container] == own):
            columns[k, 0] = 0  # hidden, or +L and -L in one channel: nothing to draw
        elif container is not None:
            columns[k, 1] = channel[container] + 1
    return columns


def _containers(columns: np.ndarray, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
    """``columns`` (:func:`_nesting_columns`) split between the shader and the host: where every drawn
    row of a channel has one container channel (a woven sample's yarns, all in the matrix), the
    host takes the whole channel off the container's once a view (a ``(container, channel)`` pair)
    instead of a second atomic add for every crossing (measured: 4 % of a twin_small view at 512²
    on llvmpipe). Returns drawn, the container column left to the shader, and the pairs."""
    drawn, container = columns.T.copy()
    pairs = []
    for channel in np.unique(channels):
        rows = (channels == channel) & (drawn != 0)
        values = np.unique(container[rows])
        if len(values) == 1 and values[0] != 0:
            pairs.append((int(values[0]) - 1, int(channel)))
            container[rows] = 0
    return drawn, container, tuple(pairs)


def _refine(vec: VectorGeometry, k: int) -> VectorGeometry:
    """The same detector with k×k sub-pixels (centres of a regular sub-grid of each pixel)."""
    if k == 1:
        return vec
    arr = vec.array.copy()
    arr[:, 6:12] /= k
    rows, cols = vec.detector_shape
    return VectorGeometry(vec.beam, (rows * k, cols * k), arr)
