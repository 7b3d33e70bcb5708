"""Frames of a preview: view 0 of a document, rendered as ``xrayraster render`` (a scene file) or
``xrayraster scan`` (a scan file) renders it, by one :class:`~xrayraster.Renderer` kept across
frames.

A frame does only what changed since the last one (the module's one job): turning the sample
only retargets the renderer (no mesh upload, no spectrum, no shader compiled again); a new
spectrum or detector reloads the file's tables (SpekPy keeps its tube model while only the mAs
changes), not a scene file's meshes; the sample is meshed again only when a key below it changed;
a path-length frame does no spectral sum.

While the input moves (a slider or the image dragged), a frame may be *reduced*: the same view on
the detector binned to at most :data:`MOVING_PIXELS` pixels (:func:`binned`), rendered by a
renderer of its own that keeps its uploaded scene too, so that the image follows the hand; the
page asks for the full frame once the input has stopped.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass

import numpy as np

from ..core.errors import ConfigError
from ..core.estimate import plan
from ..core.geometry import VectorGeometry
from ..core.projections import Projections
from ..gl.context import GLContext
from ..gl.pathlengths import interpenetrating_overlap
from ..physics.detector import Detector
from ..pipeline.plan import FrameJob
from ..recon.opencl import CLContext
from ..simulate.renderer import Renderer
from .document import Document, View, turned_angles
from .quick_slice import QuickSlice, quick_slice


@dataclass(frozen=True)
class Frame:
    """One rendered view: ``image`` float32 (rows, cols) in ``unit``, what it shows (``quantity``),
    the angle of the view (degrees), and the seconds of each stage."""

    image: np.ndarray
    quantity: str
    unit: str
    angle_deg: float | None
    seconds: dict
    layout: dict | None = None  # the scan seen from above (:func:`layout`)
    binning: int = 1  # 1: the full frame; b: the detector binned b × b (a reduced frame, while moving)
    full_shape: tuple | None = None  # the full frame's (rows, cols); None: the image's own


#: A reduced frame (while the input moves) has at most this many pixels: 256², a quarter of a 512²
#: frame's, which the small twin's 229 k triangles render in about a third of the time.
MOVING_PIXELS = 256 * 256


class Previewer:
    """Renders frames of documents on its own GL context (made on the first frame, in the thread
    that renders: a GL context is current in one thread). ``threads``: the spectral sum's.
    ``moving_pixels``: the most pixels of a reduced frame (:meth:`frame` with ``moving``)."""

    def __init__(self, threads: int | None = None, moving_pixels: int = MOVING_PIXELS):
        if int(moving_pixels) != moving_pixels or moving_pixels < 1:
            raise ConfigError(f"moving_pixels must be a positive integer, got {moving_pixels!r}")
        self.threads, self.moving_pixels = threads, int(moving_pixels)
        self._gl: GLContext | None = None  # owned here: the renderers and the quick slices' scans borrow it
        self._cl = None  # the quick slices' OpenCL context, made on the first
        # One renderer per binning (1: the full frame), each with its scene uploaded: switching
        # between a reduced frame and the full one uploads and compiles nothing again.
        self._renderers: dict[int, Renderer] = {}
        self._loaded = (None, None, None)  # (tables as JSON, the sample's key, SceneFile or ScanFile)
        self._sample = (None, None)  # (the sample's tables as JSON, the scene the projections see)

    @property
    def _renderer(self) -> Renderer | None:
        """The full frames' renderer (None before the first)."""
        return self._renderers.get(1)

    def frame(self, document: Document, view: View, moving: bool = False) -> Frame:
        """View 0 of ``document`` as ``view`` shows it (ConfigError naming the key of a bad value).
        ``moving``: a reduced frame, the same view on the detector binned to at most
        :attr:`moving_pixels` pixels (:func:`binning`, :func:`binned`; the full frame when it has
        no more), each binned pixel rendered as the file renders its own."""
        start = time.perf_counter()
        loaded, scene, renderer = self._prepare(document, view, moving)
        prepared = time.perf_counter()
        if view.output == "path_length":
            image = renderer.path_lengths(scene, 0)[view.material]
            seconds = {"path_lengths": time.perf_counter() - prepared}
            quantity, unit = f"path length: {material_names(scene)[view.material]}", "mm"
        else:
            options = self._options(document, view, loaded)
            shot = renderer.project(scene, loaded.spectrum, 0, **options)
            image, seconds = shot.image, dict(renderer.last_seconds)
            quantity = view.output
            unit = "1" if view.output != "raw" else "counts" if options["detector"].counting else "keV deposited"
        factor = binning(loaded.geometry.detector_shape, self.moving_pixels) if moving else 1
        return Frame(image, quantity, unit, first_angle_deg(renderer.geometry), {"prepare": prepared - start, **seconds},
                     layout(renderer.vector_geometry, scene.bounds), factor, tuple(loaded.geometry.detector_shape))

    def projections(self, document: Document, view: View) -> Projections:
        """View 0 as the command line writes it (:meth:`Document.command`): path lengths of every
        material, or the radiograph, with the same provenance, for a TIFF the same as its."""
        loaded, scene, renderer = self._prepare(document, view)
        if view.output == "path_length":
            return renderer.path_lengths_all(scene, [0], progress=False)
        return renderer.project_all(scene, loaded.spectrum, [0], progress=False, **self._options(document, view, loaded))

    def quick_slice(self, document: Document, view: View) -> QuickSlice:
        """The middle slice of a scan file's grid from a cut-down scan, with its labels (:mod:`.quick_slice`)."""
        self._gl = self._gl or GLContext()
        self._cl = self._cl or CLContext()
        return quick_slice(document, view, self.load(document), gl=self._gl, cl=self._cl, threads=self.threads)

    def release(self) -> None:
        for renderer in self._renderers.values():
            renderer.release()
        self._renderers.clear()
        for context in (self._cl, self._gl):
            if context is not None:
                context.release()
        self._gl = self._cl = None

    # -- what changed ----------------------------------------------------------------------------

    def _prepare(self, document: Document, view: View, moving: bool = False):
        """The loaded file, the scene its projections see, and the renderer pointed at the view
        (``moving``: at the view on the binned detector of a reduced frame)."""
        loaded = self.load(document)
        scene = self.scene(document, loaded)
        if view.output == "path_length" and view.material >= len(scene.materials):
            raise ConfigError(f"view: material {view.material} is not one of the scene's "
                              f"{len(scene.materials)} materials (0 to {len(scene.materials) - 1})")
        factor = binning(loaded.geometry.detector_shape, self.moving_pixels) if moving else 1
        geometry = binned(turned(loaded.geometry, view.angle_deg), factor)
        return loaded, scene, self._renderer_for(geometry, document, scene, factor)

    @staticmethod
    def _options(document: Document, view: View, loaded) -> dict:
        """``Renderer.project``'s options as ``render`` (a scene file) or ``scan`` (a scan file: noisy
        views interpolate their spectral sums) sets them."""
        return dict(detector=loaded.detector if loaded.detector is not None else Detector(), output=view.output,
                    noise=view.noise, seed=view.seed if view.noise or loaded.realism.needs_seed else None,
                    realism=loaded.realism, spectral_table=document.kind == "scan" and view.noise)

    def load(self, document: Document):
        """The document as its loader reads it, loaded again only when its tables changed; a frame
        of it that cannot fit in memory is refused here, before any meshing (:class:`FrameJob`)."""
        key, sample = json.dumps(document.table, sort_keys=True), document.sample_key()
        if self._loaded[0] != key:
            # Only the scanner changed: a scene file's meshes are not read again.
            loaded = document.load(objects_of=self._loaded[2] if self._loaded[1] == sample else None)
            if document.kind == "scene" and loaded.spectrum is None:
                raise ConfigError(f"{document.path}: a preview shows radiographs, so the file needs a [source] table "
                                  "(the X-ray spectrum) and [materials] (docs/scene-format.md)")
            plan(FrameJob(loaded), ConfigError, f"{loaded.path} ")
            self._loaded = (key, sample, loaded)
        return self._loaded[2]

    def scene(self, document: Document, loaded):
        """The scene the projections see: a scene file's objects, or a scan file's sample with its
        mount; the one kept from before while its tables are unchanged (not meshed, not uploaded
        to GL again)."""
        key = document.sample_key()
        if self._sample[0] != key:
            scene = loaded.scene if document.kind == "scene" else loaded.with_mount(loaded.sample_scene())
            self._sample = (key, scene)
        return self._sample[1]

    def _renderer_for(self, geometry, document: Document, scene, factor: int = 1) -> Renderer:
        """The renderer of frames binned ``factor`` × ``factor`` (1: full frames), pointed at ``geometry``."""
        # A woven sample's yarns interpenetrate: its renderer picks as xrayraster scan's does for one view.
        woven = document.kind == "scan" and "weave" in document.table
        overlap = interpenetrating_overlap(scene, geometry, views=1) if woven else "auto"
        renderer = self._renderers.get(factor)
        if renderer is not None and renderer.overlap != overlap:
            renderer.release()
            renderer = None
        if renderer is None:
            for other in [f for f in self._renderers if f not in (1, factor)]:
                self._renderers.pop(other).release()  # the detector changed: one reduced renderer at a time
            self._gl = self._gl or GLContext()
            renderer = Renderer(geometry, overlap=overlap, threads=self.threads, context=self._gl)
            self._renderers[factor] = renderer
        elif renderer.geometry != geometry:
            renderer.retarget(geometry)
        return renderer


def first_angle_deg(geometry) -> float | None:
    """The angle of a circular scan's first view, degrees (None for per-view vectors)."""
    return math.degrees(geometry.angles[0]) if hasattr(geometry, "angles") else None


def turned(geometry, angle_deg: float | None):
    """``geometry`` turned so its first view is at ``angle_deg`` (its views keep their spacing);
    as it is for None or a per-view vector geometry, which has no angle to turn."""
    if angle_deg is None or not hasattr(geometry, "angles"):
        return geometry
    # The first angle exactly as a file's start_angle_deg gives it, so a saved file's view 0 is this one;
    # the others turned as a saved file's angles_deg are (:func:`~.document.turned_angles`).
    return dataclasses.replace(geometry, angles=tuple(turned_angles(geometry.angles, math.radians(angle_deg))))


def binning(shape, pixels: int) -> int:
    """How many detector pixels a side a reduced frame bins into one: the smallest power of two
    that leaves at most ``pixels`` pixels (1: the frame has no more)."""
    rows, cols = shape
    factor = 1
    while math.ceil(rows / factor) * math.ceil(cols / factor) > pixels and factor < max(rows, cols):
        factor *= 2
    return factor


def binned(geometry, factor: int):
    """``geometry`` with its detector binned ``factor`` × ``factor``: the same detector (its centre,
    extent and offsets), ⌈rows / factor⌉ × ⌈cols / factor⌉ pixels each ``rows / ⌈rows / factor⌉``
    (``cols / ...``) times as large: exactly ``factor`` times where it divides the shape. As it is
    for 1."""
    if factor == 1:
        return geometry
    rows, cols = geometry.detector_shape
    shape = (math.ceil(rows / factor), math.ceil(cols / factor))
    scale = (rows / shape[0], cols / shape[1])
    if isinstance(geometry, VectorGeometry):
        vectors = geometry.array.copy()
        vectors[:, 6:9] *= scale[1]  # u: from one column to the next
        vectors[:, 9:12] *= scale[0]  # v: from one row to the next
        return VectorGeometry(geometry.beam, shape, vectors)
    pixel = (geometry.pixel_size[0] * scale[0], geometry.pixel_size[1] * scale[1])
    return dataclasses.replace(geometry, detector_shape=shape, pixel_size=pixel)


def material_names(scene) -> list[str]:
    """The names of ``scene``'s materials, in channel order."""
    return [getattr(m, "name", str(m)) for m in scene.materials]


def layout(vector_geometry, bounds) -> dict:
    """View 0 seen from above (x, y in mm, the rotation axis at 0): the source (None for a parallel
    beam), the detector's two ends, the corners of the scene's bounding box, and the radius of the
    field of view (the circle every ray of the view's fan, or band, covers)."""
    s, d, u, _ = np.split(vector_geometry.array[0], 4)
    half = u * vector_geometry.detector_shape[1] / 2
    ends = [d - half, d + half]
    cone = vector_geometry.beam == "cone"

    def reach(end):  # the distance of the edge ray through ``end`` from the axis, seen from above
        direction = (end - s if cone else s)[:2]
        cross = direction[0] * end[1] - direction[1] * end[0]
        return abs(float(cross)) / max(float(np.linalg.norm(direction)), 1e-300)

    (x0, y0, _), (x1, y1, _) = bounds
    return {"source": s[:2].tolist() if cone else None, "direction": None if cone else s[:2].tolist(),
            "detector": [e[:2].tolist() for e in ends], "fov_mm": min(reach(e) for e in ends),
            "sample": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]}
