"""Radiographs: the GL path lengths of a view composed with the physics (spectrum, materials,
detector, noise). GL knows nothing of photons and the physics nothing of GL; this is where they meet."""

from __future__ import annotations

import logging
import sys
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..core.errors import RenderError
from ..core.estimate import plan
from ..core.projections import Projections
from ..gl.pathlengths import PathLengthRenderer
from ..physics.beer_lambert import thread_count
from ..physics.detector import NEGLIGIBLE_BLUR_PX, Detector, blur_change_bound, negligible_blur
from ..physics.photon_factors import PhotonFactors
from ..physics.radiograph import Radiograph, SpectralModel, flat_noise, radiograph, spectral_model
from ..physics.realism import FLAT_TAG, GAIN_TAG, Realism, calibration_rng, focal_sigma_px, gain_map
from ..physics.scatter import ScatterModel, detector_layout, scatter_model
from ..scene.scene import Scene
from .estimate import RenderJob

log = logging.getLogger("xrayraster")


class Renderer(PathLengthRenderer):
    """Path lengths (:class:`~xrayraster.gl.pathlengths.PathLengthRenderer`, whose options it
    takes) and radiographs for a scan geometry. ``threads``: how many threads the spectral sum of
    :meth:`project` uses (default every core); a process pool or Dask worker running several
    renderers at once gives each its share, so they do not oversubscribe the cores.
    """

    def __init__(self, geometry, *, threads: int | None = None, **options):
        self.threads = thread_count(threads)  # checked before a GL context is made
        self._calibration = None  # (key, gain map, flat noise) of the last scan projected: see _fixed_patterns
        self._model = None  # (key, SpectralModel) of the last scene projected: see _spectral_model
        self._scatter = None  # (key, ScatterModel) of the last scene projected with scatter: see _scatter_model
        self.last_seconds: dict[str, float] = {}  # the last project()'s GL path lengths and CPU physics, s
        self._skips_logged: set = set()  # the negligible options already logged for this scan: see _log_skip
        super().__init__(geometry, **options)
        self.photon_factors = PhotonFactors(self.vector_geometry)  # each view's, once per relative pose
        self.physics_workers = physics_workers(self.gl.software, self.threads)

    def project(self, scene: Scene, spectrum, view: int = 0, *, detector: Detector | None = None,
                output: str = "lineint", noise: bool = False, seed: int | None = None,
                realism: Realism | None = None, spectral_table: bool = False) -> Radiograph:
        """The radiograph of one view (:class:`~xrayraster.physics.radiograph.Radiograph`).

        Scene materials must be :class:`~xrayraster.Material` objects. ``output``: ``"raw"``
        (detector signal), ``"transmission"`` or ``"lineint"`` (−ln of it). With ``noise``,
        quantum and electronic noise are drawn from a generator seeded by ``(seed, view)``:
        the same seed gives the same bytes, and every view its own independent stream.
        ``realism``: the scanner's imperfections (:class:`~xrayraster.physics.realism.Realism`;
        default none). Its fixed patterns, the flats' noise and the gain map, are drawn from ``seed``
        once for every view (so they need a seed even without ``noise``). ``spectral_table``: with
        ``noise``, the sums over energy bins are interpolated from a table of measured error
        (:mod:`~xrayraster.physics.spectral_table`, ≤ 1e-5 relative: a tenth of the photon noise at
        10⁸ photons a pixel) instead of summed in every pixel; noise-free views stay exact.
        The bins, attenuation coefficients and table are made once for the views of a scene.
        """
        physics = self._physics_of(scene, spectrum, detector, output, noise, seed, realism, spectral_table)
        start = time.perf_counter()
        lengths = self.path_lengths(scene, view)
        traced = time.perf_counter()
        shot = physics(view, lengths)
        self.last_seconds = {"path_lengths": traced - start, "physics": time.perf_counter() - traced}
        return shot

    def _physics_of(self, scene: Scene, spectrum, detector, output, noise, seed, realism, spectral_table, *,
                    threads: int | None = None):
        """The options of :meth:`project` checked, and the CPU half of a view for them: a function
        ``(view, path lengths) -> Radiograph`` that touches no GL, so it can run on a thread while
        the GL renders the next view. What every view shares (the spectral model, the scan's fixed
        patterns) is made here, once, before any view's physics runs. ``threads``: each view's spectral
        sum's (default :attr:`threads`)."""
        threads = threads or self.threads
        realism = realism or Realism()
        if noise and seed is None:
            raise RenderError("noise=True needs a seed (an int), so the noise is reproducible")
        if realism.needs_seed and seed is None:
            raise RenderError("flat_fields and gain_variation need a seed (an int): their patterns are drawn from it")
        detector = detector or Detector()
        if detector.blur_skipped:
            sigma = detector.blur_sigma_px
            self._log_skip(("blur_sigma_px", sigma), f"detector blur_sigma_px = {sigma:g}", blur_change_bound(sigma, sigma))
        gain, flat = self._fixed_patterns(spectrum, detector, realism, seed)
        model = self._spectral_model(scene, spectrum, detector, spectral_table and noise)
        scatter = self._scatter_model(scene, model, detector) if realism.scatter == "kernel" else None
        materials, views = scene.materials, self.vector_geometry.num_views

        def physics(view: int, lengths: np.ndarray) -> Radiograph:
            view %= views
            rng = np.random.default_rng([int(seed), view]) if noise else None
            return radiograph(lengths, materials, spectrum, detector, self.photon_factors(view),
                              output=output, noise=noise, rng=rng, threads=threads,
                              focal_sigma_px=self._focal_sigma_px(realism, view), gain=gain, flat_noise=flat,
                              model=model, scatter=scatter)

        return physics

    def retarget(self, geometry) -> None:
        """:meth:`PathLengthRenderer.retarget`; the scan's flats and gain map are drawn anew for it."""
        super().retarget(geometry)
        self.photon_factors = PhotonFactors(self.vector_geometry)
        self._calibration = None
        self._skips_logged.clear()  # a new scan: its negligible options are logged again

    def _spectral_model(self, scene: Scene, spectrum, detector: Detector, table: bool) -> SpectralModel:
        """The scene's bins, μ and (``table``) spectral table, kept for the next view of the same scene.
        The table covers every path up to the diagonal of the scene's bounds, the longest chord."""
        # The scene itself (compared by identity, and kept alive so its id is not reused) and its
        # revision stand for its materials and bounds: computing those took 0.7 ms a view.
        key = (scene, scene.revision, spectrum, detector, table)
        if self._model is None or self._model[0] != key:
            longest = float(np.linalg.norm(np.ptp(scene.bounds, axis=0))) if table else None
            self._model = (key, spectral_model(scene.materials, spectrum, detector, longest_mm=longest))
        return self._model[1]

    def _scatter_model(self, scene: Scene, model: SpectralModel, detector: Detector) -> ScatterModel:
        """The scatter kernels of the scene's materials under the model's bins, kept for the next view
        of the same scene, spectrum, detector and geometry (a circular scan's views share its detector's
        distance from the axis; view 0's is taken)."""
        layout = detector_layout(self.vector_geometry, 0)
        key = (model, detector, layout)
        if self._scatter is None or self._scatter[0] != key:
            self._scatter = (key, scatter_model(scene.materials, model.energies, model.photons, detector, layout))
        return self._scatter[1]

    def _focal_sigma_px(self, realism: Realism, view: int) -> tuple[float, float]:
        """The focal spot's penumbra σ ``(rows, cols)`` in pixels for ``view``; the physics skips an axis
        where it is negligible (:func:`~xrayraster.physics.radiograph.applied_focal_sigma_px`), logged here."""
        if not realism.focal_spot_mm:
            return (0.0, 0.0)
        sigma = focal_sigma_px(self.vector_geometry, view, realism.focal_spot_mm, realism.focal_plane_mm)
        skipped = [s if negligible_blur(s) else 0.0 for s in sigma]
        if any(skipped):
            axes = ", ".join(f"σ_{axis} = {s:.2g} px" for s, axis in zip(skipped, ("rows", "cols")) if s)
            self._log_skip(("focal_spot_mm", realism.focal_spot_mm, realism.focal_plane_mm),
                           f"focal_spot_mm = {realism.focal_spot_mm:g} (its penumbra's {axes} in view {view})",
                           blur_change_bound(*skipped))
        return sigma

    def _log_skip(self, key: tuple, what: str, bound: float) -> None:
        """Log at INFO, once per option and scan (until :meth:`retarget`), that a blur too small to show
        was skipped: ``what`` it was and the ``bound`` on its effect (a share of an edge's contrast)."""
        if key in self._skips_logged:
            return
        self._skips_logged.add(key)
        log.info("skipped %s: below the %g px threshold, it would change no pixel by more than %.2g %% of the "
                 "contrast around it (docs/realism.md)", what, NEGLIGIBLE_BLUR_PX, 100 * bound)

    def _fixed_patterns(self, spectrum, detector: Detector, realism: Realism, seed):
        """The scan's gain map and flat noise (None when off), drawn from ``seed`` on their own streams;
        the flats are exposed in view 0's geometry. Kept for the next view of the same scan, as
        they are drawn from the same streams every time: the bytes do not depend on the views asked."""
        if not realism.needs_seed:
            return None, None
        key = (int(seed), spectrum, detector, realism)
        if self._calibration is None or self._calibration[0] != key:
            shape = self.vector_geometry.detector_shape
            gain = flat = None
            if realism.gain_variation:
                gain = gain_map(realism.gain_variation, shape, calibration_rng(seed, GAIN_TAG))
            if realism.flat_fields is not None:
                flat = flat_noise(spectrum, detector, self.photon_factors(0), shape,
                                  realism.flat_fields, calibration_rng(seed, FLAT_TAG),
                                  focal_sigma_px=self._focal_sigma_px(realism, 0), threads=self.threads)
            self._calibration = (key, gain, flat)
        return self._calibration[1:]

    # -- every view in one call ----------------------------------------------------------------

    def path_lengths_all(self, scene: Scene, views=None, *, progress=None) -> Projections:
        """The path lengths of ``views`` (default every view; a list of indices) stacked into an
        :class:`~xrayraster.Projections` of quantity ``"path_length"`` in mm, on
        ``geometry[views]``, each view exactly :meth:`path_lengths`.

        ``progress``: ``True`` a tqdm bar on stderr, ``False`` none, or a callable
        ``progress(done, total)`` called after each view; default a bar when stderr is a terminal.
        A stack that cannot fit in memory is refused before any view is rendered.
        """
        views = self._views(views)
        self._check_stack(scene, views, len(scene.materials))
        stack = np.stack([self.path_lengths(scene, v) for v in _report(views, progress, "path lengths")])
        return Projections(stack, self.geometry[views], "path_length", "mm", {
            "materials": [_material_name(m) for m in scene.materials],
            "views": views,
            "supersampling": self.supersampling,
            "method": self.last_method,
            "renderer": self.gl.renderer,
        })

    def project_all(self, scene: Scene, spectrum, views=None, *, detector: Detector | None = None,
                    output: str = "lineint", noise: bool = False, seed: int | None = None,
                    realism: Realism | None = None, spectral_table: bool = False, progress=None) -> Projections:
        """The radiographs of ``views`` (default every view) stacked into an
        :class:`~xrayraster.Projections` on ``geometry[views]``, each view exactly :meth:`project`
        (same options; noise streams are seeded per view index, so a subset gives the same bytes
        as the full run). Unit: ``"1"`` for lineint and transmission; raw is ``"counts"`` for a
        counting detector, else ``"keV deposited"``. The provenance records the views, materials,
        spectrum, detector, seed and per-view bins, dropped signal, starved pixels, the pixels the
        scene covers and the starved ones among them (physics/starvation.py), as the
        command line writes them, the realism options when any is on, and the spectral table's grid
        and measured error when one was used, and with scatter each view's scatter-to-primary ratios
        (``spr_centre``, ``spr_covered``: :class:`~xrayraster.physics.radiograph.Radiograph`).
        ``progress`` as in :meth:`path_lengths_all`.
        """
        views = self._views(views)
        self._check_stack(scene, views, 1)
        detector = detector or Detector()
        realism = realism or Realism()
        workers = self.physics_workers
        physics = self._physics_of(scene, spectrum, detector, output, noise, seed, realism, spectral_table,
                                   threads=max(1, self.threads // workers))
        shots = []
        # The GL renders view k + 1 while threads turn the views before it into radiographs (numpy, the
        # spectral sum and a view's GL calls release the GIL): a view costs the larger of the two, not
        # their sum, where they run on different hardware (a GPU), and the GL's idle moments are filled
        # on a CPU. Each view's physics depends on its path lengths and index alone: the same bytes in
        # any order. The physics thread keeps the caller's priority: at a lower one (niceness 19, tried)
        # it starved whenever another process rendered (two builds' workers: 105 s a sample for 8 s).
        with ThreadPoolExecutor(workers, thread_name_prefix="xrayraster-physics") as cpu:
            pending = deque()
            for v in _report(views, progress, output):
                lengths = self.path_lengths(scene, v)
                if len(pending) == workers:
                    shots.append(pending.popleft().result())
                pending.append(cpu.submit(physics, v, lengths))
            shots.extend(f.result() for f in pending)
        return self._stacked(shots, scene, spectrum, views, detector, output, noise, seed, realism, spectral_table)

    def project_lengths(self, scene: Scene, lengths: Projections, spectrum, *, detector: Detector | None = None,
                        output: str = "lineint", noise: bool = False, seed: int | None = None,
                        realism: Realism | None = None, spectral_table: bool = False) -> Projections:
        """The radiographs :meth:`project_all` makes of ``scene``, from its path lengths already rendered
        (``lengths``: :meth:`path_lengths_all` of a scene with the same meshes and channels, such as
        ``scene.with_materials(...)`` of it, on this renderer's geometry): no GL. A fit that varies
        the materials, spectrum, detector or realism renders the path lengths once."""
        if lengths.quantity != "path_length" or lengths.data.shape[1] != len(scene.materials):
            raise RenderError(f"lengths must be the path lengths of the scene's {len(scene.materials)} materials "
                              f"(Renderer.path_lengths_all), got {lengths.quantity} of shape {lengths.data.shape}")
        views = list(lengths.provenance["views"])
        detector = detector or Detector()
        realism = realism or Realism()
        # Views on every thread, each its spectral sum on one: the bytes depend on the view alone.
        physics = self._physics_of(scene, spectrum, detector, output, noise, seed, realism, spectral_table, threads=1)
        with ThreadPoolExecutor(self.threads, thread_name_prefix="xrayraster-physics") as cpu:
            shots = list(cpu.map(physics, views, lengths.data))
        return self._stacked(shots, scene, spectrum, views, detector, output, noise, seed, realism, spectral_table)

    def _stacked(self, shots, scene, spectrum, views, detector, output, noise, seed, realism,
                 spectral_table) -> Projections:
        """The views' radiographs as one :class:`~xrayraster.Projections`, with their provenance."""
        unit = "1" if output != "raw" else "counts" if detector.counting else "keV deposited"
        # An ideal scan's provenance stays as it was before the realism options existed.
        extra = {"realism": realism.to_dict()} if realism.active else {}
        if realism.scatter != "none":
            extra["spr_centre"] = [shot.spr_centre for shot in shots]
            extra["spr_covered"] = [shot.spr_covered for shot in shots]
        table = self._model[1].table if spectral_table and noise else None
        if table is not None:
            extra["spectral_table"] = {"grid": list(table.shape), "error": table.error}
        return Projections(np.stack([shot.image for shot in shots]), self.geometry[views], output, unit, {
            "materials": [_material_name(m) for m in scene.materials],
            "material_compositions": [repr(m) for m in scene.materials],
            "views": views,
            "spectrum": spectrum.description,
            "spectrum_photons_per_mm2_at_1m": spectrum.total,
            "spectrum_bins": spectrum.n_bins,
            "detector": repr(detector),
            "bins_used": [shot.bins for shot in shots],
            "dropped_signal_share": [shot.dropped for shot in shots],
            "starved_pixels": [shot.starved for shot in shots],
            "covered_pixels": [shot.covered for shot in shots],
            "starved_covered_pixels": [shot.starved_covered for shot in shots],
            "noise": bool(noise),
            "seed": seed,
            "supersampling": self.supersampling,
            "method": self.last_method,
            "renderer": self.gl.renderer,
            **extra,
        })

    def _check_stack(self, scene: Scene, views: list[int], channels: int) -> None:
        """Refuse a stack of ``views`` that cannot fit in memory (:mod:`~xrayraster.simulate.estimate`)."""
        if not isinstance(scene, Scene):
            raise RenderError(f"expected a Scene, got {type(scene).__name__}")
        plan(RenderJob(len(views), self.vector_geometry.detector_shape, scene.num_triangles, channels,
                       self.supersampling), RenderError)

    def _views(self, views) -> list[int]:
        """``views`` (None: all) as a list of in-range indices, negatives counted from the end."""
        n = self.vector_geometry.num_views
        if views is None:
            return list(range(n))
        if isinstance(views, (int, np.integer)):
            raise RenderError(f"views must be a list of view indices (or None for all), got {views!r}; "
                              "for one view use path_lengths(scene, view) or project(...)")
        out = []
        for v in views:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not -n <= v < n:
                raise RenderError(f"view {v!r} is not an index of the geometry's {n} views")
            out.append(int(v) % n)
        if not out:
            raise RenderError("views is empty; give at least one view index (or None for all)")
        return out


def physics_workers(software_gl: bool, threads: int) -> int:
    """How many views :meth:`Renderer.project_all` turns into radiographs at once: one beside a GL that
    renders on the CPU cores (llvmpipe takes them), else half the ``threads``, each view's spectral sum
    on two. A view's physics is mostly single-threaded numpy (the noise, the flat, the log): on an
    NVIDIA H200's 16-core host one view took 17–22 ms on 1 to 16 threads, twice the GPU's view."""
    return 1 if software_gl else max(1, threads // 2)


def _material_name(material) -> str:
    return material.name if hasattr(material, "name") else str(material)


def _report(views: list[int], progress, what: str):
    """Iterate ``views`` reporting progress: a tqdm bar (True, or None with stderr a terminal), a
    callable ``progress(done, total)`` after each view, or nothing (False)."""
    if progress is None:
        progress = bool(getattr(sys.stderr, "isatty", lambda: False)())
    total = len(views)
    if callable(progress) and not isinstance(progress, bool):
        for k, v in enumerate(views, 1):
            yield v
            progress(k, total)
        return
    if progress is not True and progress is not False:
        raise RenderError(f"progress must be True, False, None or a callable progress(done, total), got {progress!r}")
    if not progress:
        yield from views
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=what, unit="view", file=sys.stderr) as bar:
        for v in views:
            yield v
            bar.update(1)
