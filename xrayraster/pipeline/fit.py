"""A scan file fitted to a real reconstruction (``xrayraster fit``, ``xr.fit``; docs/fit.md).

The simulation of a scan file is made to look like a real scan in what a segmentation network
sees (:mod:`~xrayraster.pipeline.fit_figures`), one knob a figure:

=====================================  ====================================  =========================
figure                                 scan-file key                         update
=====================================  ====================================  =========================
the sample surface's edge width        ``detector.blur_sigma_px``            width² = a + b·blur², two runs
each class's peak                      ``materials.NAME.density``            ×= real / simulated peak
a tracer's peak                        its fibre fraction                    ×= real / simulated peak
the rings                              ``detector.gain_variation``           rms² = a + b·gain², two runs
the noise σ in the air                 ``source.mas``                        photon variance ∝ 1 / mAs
=====================================  ====================================  =========================

A woven sample's cell is fitted first, and its tracer yarns found where the file names none
(:mod:`~xrayraster.pipeline.fit_weave`, :mod:`~xrayraster.pipeline.fit_tracer`); ``weave=False``
keeps the file's cell. The sample's path lengths are rendered once (again with the fitted cell);
every run after is the physics of those path lengths
(:meth:`~xrayraster.simulate.renderer.Renderer.project_lengths`) and an FDK on the file's grid, all
with the file's seed (the same noise draws: a change of a knob is not hidden by new noise). Each
round updates the knobs in the order above; the fit stops when every figure is within its
tolerance (:data:`TOLERANCES`) or after ``rounds`` rounds, and keeps the best run (the smallest
largest relative error). What the figures cannot tell apart is said, not guessed: the focal spot
blurs as the detector does, and electronic noise adds to photon noise, so those two keep the
file's values; a knob whose figure does not move beyond its own noise is reported as not pinned
down.

The real volume must be on the scan file's ``[volume]`` grid (z, y, x, cm⁻¹). Its classes come from
``labels`` (the user's region labels on the same grid, the scan's label values) or, without them,
from the fitted cell's labels (a weave), else the classes share one peak, the mean of a Gaussian
mixture of its values started at the simulation's; the sample is where μ is above halfway from the
air to its lowest class.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..core.errors import ConfigError
from ..core.inputs import read_tiff_file
from ..gl.voxelize import voxelize
from ..io.scan_file import ScanFile, load_scan_file
from ..io.scan_keys import absolute_paths, set_key
from ..io.scene_file import read_toml
from ..physics.scatter import detector_layout
from ..recon.fdk import fdk
from ..recon.fdk_weights import footprint_radius
from ..recon.opencl import CLContext
from ..scene.scene import Scene
from ..simulate.renderer import Renderer
from .fit_figures import Figures, class_peaks, measure, mixture_means, sides_seen
from .fit_search import TOLERANCES, Knobs, Search, relative_errors
from .fit_tracer import FIBRE, START_FRACTION, find_tracers, with_tracers
from .fit_weave import AIR, FITTED_EROSION, MATRIX, YARN, WeaveFit, class_of_labels, fit_weave


@dataclass(frozen=True)
class FitResult:
    """What :func:`fit` found: the fitted scan file's ``table`` (TOML-ready, its paths absolute), the
    ``parameters`` (key → (start, fitted)), the figures of the ``real`` volume and of the simulation
    at the ``start`` and ``fitted``, the ``errors`` (figure → (start, fitted) relative errors),
    ``unidentified`` (key → why it kept the file's value), whether every figure came within its
    tolerance (``converged``), each run's knobs and errors (``runs``), the wall ``seconds``, and the
    three volumes (``volumes``: "real", "start", "fitted"; for the report's histograms)."""

    table: dict
    parameters: dict
    real: Figures
    start: Figures
    fitted: Figures
    errors: dict
    unidentified: dict
    converged: bool
    runs: list
    seconds: float
    volumes: dict = dataclasses.field(default_factory=dict, repr=False)
    weave: dict = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict:
        """The report (docs/fit.md): JSON-ready."""
        return {"parameters": {k: {"start": a, "fitted": b} for k, (a, b) in self.parameters.items()},
                "figures": {"real": self.real.to_dict(), "start": self.start.to_dict(),
                            "fitted": self.fitted.to_dict()},
                "relative_errors": {k: {"start": _plain(a), "fitted": _plain(b)} for k, (a, b) in self.errors.items()},
                "tolerances": TOLERANCES, "not_fitted": self.unidentified, "converged": self.converged,
                "runs": [{"values": r["knobs"].values(), "relative_errors": {k: _plain(v) for k, v in r["errors"].items()}}
                         for r in self.runs],
                "seconds": self.seconds, **({"weave": self.weave} if self.weave else {})}


def fit(real, scan, *, labels=None, rounds: int = 3, weave: bool = True, gl=None,
        cl: CLContext | None = None) -> FitResult:
    """Fit the scan file ``scan`` (a path) to the reconstruction ``real`` (a TIFF path or a (z, y, x)
    array in cm⁻¹ on the file's grid), with the user's region ``labels`` (a path or an array) when
    given (module docstring). ``weave=False`` keeps a ``[weave]``'s cell as the file gives it."""
    started = time.perf_counter()
    path = Path(scan)
    loaded = load_scan_file(path)
    table = absolute_paths(read_toml(path, "scan file"), path.parent)
    real = _volume(real, loaded, "the real volume")
    knobs = initial = Knobs.of(loaded, table)
    with Renderer(loaded.geometry, context=gl) as renderer, (nullcontext(cl) if cl is not None else CLContext()) as cl:
        sample = _Rendered.of(loaded, renderer)
        mount = (voxelize(loaded.mount, loaded.volume, context=renderer.gl).data > 0 if loaded.mount is not None
                 else np.zeros(sample.labels.shape, bool))
        inside, axis_radius = _field_of_view(loaded)
        figures = _Measure(inside & ~mount, axis_radius, float(min(loaded.volume.voxel_size)))
        volumes = {"real": real}

        def run(k: Knobs, sample: _Rendered, figures: _Measure, noise: bool = True,
                keep: str | None = None) -> Figures:
            scanned = sample.scanned
            projections = renderer.project_lengths(
                scanned.with_materials(k.materials(scanned.materials, sample.tracers)), sample.lengths,
                k.spectrum(loaded.spectrum), detector=k.detector(loaded.detector),
                noise=noise and loaded.options.noise, seed=loaded.options.seed,
                realism=dataclasses.replace(loaded.realism, gain_variation=k.gain,  # without noise the flats' too
                                            flat_fields=loaded.realism.flat_fields if noise else None),
                spectral_table=True)
            volume = fdk(projections, volume=loaded.volume, filter=loaded.options.filter, context=cl,
                         truncation=loaded.options.truncation, truncation_width=loaded.options.truncation_width,
                         object_radius_mm=footprint_radius(*scanned.bounds))
            if keep:
                volumes[keep] = volume.data
            return figures(volume.data, sample.labels)

        start = run(knobs, sample, figures, keep="start")
        real_labels = None
        if labels is not None:
            real_labels = _given_labels(labels, loaded, start)
        else:
            figures = figures.lumped(volumes["start"], start.peaks)
            lumped = figures(volumes["start"])  # with the start's own exact labels' peaks where the cell is fitted
            start = dataclasses.replace(lumped, peaks=start.peaks) if weave and loaded.weave is not None else lumped
        first, woven, tracers = start, None, []
        if weave and loaded.weave is not None:
            woven, tracers, scene = _fit_weave(real, real_labels, figures.inside, start, loaded, sample.scene,
                                               renderer.gl)
            sample = _Rendered.of(woven.scan, renderer, scene)
            # The peaks are now each class's, under the fitted cell's labels.
            figures = dataclasses.replace(figures, classes=(), cell_labels=sample.labels, tracers=tuple(tracers))
            knobs = dataclasses.replace(knobs, tracers=dict.fromkeys((t.yarn for t in tracers), START_FRACTION),
                                        matrix=sample.matrix)
            first = run(knobs, sample, figures)
        target = figures(real, real_labels, real=True)
        search = Search(knobs, first, target, functools.partial(run, sample=sample, figures=figures),
                        sample.scanned.objects)
        if not sides_seen(first, target):
            search.kept.add("detector.blur_sigma_px")
            search.unidentified["detector.blur_sigma_px"] = (
                "the sample shows no side in the field of view, and its faces along the axis are smeared by the "
                "cone beam (Feldkamp's artefact) more than by a blur: the file's kept")
        if woven is not None:
            search.unidentified.update(woven.unidentified)
        if figures.classes:
            search.unidentified["materials.*.density"] = ("without region labels the classes' peaks overlap: one factor "
                                                          "is fitted for every material of the sample (--labels fits each)")
        for _ in range(rounds):
            if search.converged:
                break
            search.round()
        best_knobs, best = search.best
        run(best_knobs, sample, figures, keep="fitted")  # the same seed: the best run's volume again, for the report
    fitted_table = best_knobs.write(copy.deepcopy(table))
    parameters = initial.compare(best_knobs)
    if woven is not None:
        for key, (_, value) in woven.values.items():
            set_key(fitted_table, key, round(value, 4))
        parameters = {**woven.values, **parameters}
    return FitResult(fitted_table, parameters, target, start, best,
                     {name: (relative_errors(start, target)[name], relative_errors(best, target)[name])
                      for name in TOLERANCES},
                     {**search.unidentified, **UNSEPARATED, **(WEAVE_KEPT if woven is not None else {})},
                     search.converged, search.runs, time.perf_counter() - started, volumes,
                     _weave_report(woven, tracers, best_knobs))


def _fit_weave(real, real_labels, inside, start: Figures, loaded: ScanFile, sample: Scene,
               gl) -> tuple[WeaveFit, list, Scene]:
    """The weave's cell fitted (:func:`~xrayraster.pipeline.fit_weave.fit_weave`) from the start's
    peaks of each class (its exact labels', ``sample`` the start's scene), and, where the file names
    none, its tracers found (:mod:`~xrayraster.pipeline.fit_tracer`); with the fitted sample's scene."""
    class_of = class_of_labels(sample)
    peaks = {AIR: 0.0}
    for cls in (MATRIX, YARN):
        values = [start.peaks[label] for label, c in class_of.items() if c == cls and label in start.peaks]
        peaks[cls] = float(np.mean(values)) if values else 0.0
    woven = fit_weave(loaded, real, inside, peaks, gl, real_labels, sample)
    scene = woven.scan.sample_scene()
    tracers = []
    if not loaded.weave.materials.tracers:
        tracers = find_tracers(woven.smoothed, woven.means, inside, scene, loaded.volume, gl)
    if tracers:  # a tracer yarn's material, and its place last among the objects (it wins priority ties)
        woven = dataclasses.replace(woven, scan=with_tracers(woven.scan, tracers))
        scene = woven.scan.sample_scene()
    return woven, tracers, scene


def _weave_report(woven: WeaveFit | None, tracers: list, knobs: "Knobs") -> dict:
    """The report's ``weave`` entry: the cell's agreement with the real classes, and the tracers."""
    if woven is None:
        return {}
    return {**woven.to_dict(), "tracers": [{"yarn": t.yarn, "bright_share": t.share,
                                            "fibre": FIBRE, "fibre_fraction": knobs.tracers[t.yarn]}
                                           for t in tracers]}


@dataclass(frozen=True)
class _Measure:
    """How :func:`fit` takes a volume's figures (:func:`~xrayraster.pipeline.fit_figures.measure`) over
    the field of view ``inside`` (each column's distance from the axis ``axis_radius``, voxels of
    ``voxel_mm``), each of its ``tracers``' peak in its core (the real or the simulated one).

    With the user's labels (no ``mixture``) the classes are those labels. Without them (:meth:`lumped`),
    in every volume alike, the sample is where μ is above half its lowest class's peak (``lowest``,
    the start's, scaled as the mixture's peak is), and its classes' peaks are each class's under
    ``cell_labels`` (the fitted cell's, where the weave was fitted), else the one peak ``classes``
    share: a two-component mixture's, started at ``mixture``."""

    inside: np.ndarray
    axis_radius: np.ndarray
    voxel_mm: float
    mixture: dict = dataclasses.field(default_factory=dict)
    lowest: float = 0.0
    classes: tuple = ()
    cell_labels: np.ndarray | None = None
    tracers: tuple = ()

    def lumped(self, start: np.ndarray, peaks: dict) -> "_Measure":
        """Without labels: the mixture started at the mean of the start volume's class ``peaks`` (its
        exact labels') and fitted to ``start`` once."""
        mixture = {"air": 0.0, "sample": float(np.mean(list(peaks.values())))}
        mixture["sample"] = mixture_means(start[self.inside], mixture)["sample"]
        return dataclasses.replace(self, mixture=mixture, lowest=min(peaks.values()), classes=tuple(peaks))

    def __call__(self, volume: np.ndarray, labels: np.ndarray | None = None, real: bool = False) -> Figures:
        cores = {t.yarn: t.real if real else t.simulated for t in self.tracers}
        if not self.mixture:
            return measure(volume, labels, self.inside, self.axis_radius, self.voxel_mm, cores)
        peak = mixture_means(volume[self.inside], self.mixture)["sample"]
        above = volume > self.lowest / 2 * peak / self.mixture["sample"]
        body = ndimage.binary_fill_holes(ndimage.binary_opening(above, iterations=1)).astype(np.uint8)
        peaks = (class_peaks(volume, self.cell_labels, self.inside, FITTED_EROSION, self.voxel_mm)
                 if self.cell_labels is not None else dict.fromkeys(self.classes, peak))
        return dataclasses.replace(measure(volume, body, self.inside, self.axis_radius, self.voxel_mm, cores),
                                   peaks=peaks)


@dataclass(frozen=True)
class _Rendered:
    """A scan file's sample as the fit runs it: its scene, that with its mount (``scanned``), its path
    lengths, its labels on the grid, the scene's material of each tracer yarn and its matrix."""

    scene: Scene
    scanned: Scene
    lengths: np.ndarray
    labels: np.ndarray
    tracers: dict
    matrix: object

    @classmethod
    def of(cls, loaded: ScanFile, renderer: Renderer, scene: Scene | None = None) -> "_Rendered":
        """``loaded``'s sample (its ``scene`` where meshed already) rendered and voxelized."""
        scene = scene if scene is not None else loaded.sample_scene()
        scanned = loaded.with_mount(scene)
        by_name = {o.name: o.material for o in scene.objects}
        names = [t.yarn for t in loaded.weave.materials.tracers] if loaded.weave is not None else []
        return cls(scene, scanned, renderer.path_lengths_all(scanned, progress=False),
                   voxelize(scene, loaded.volume, context=renderer.gl).data,
                   {name: by_name[name] for name in names if name in by_name}, by_name.get("matrix"))


def _plain(value: float):
    """``value`` for JSON: None for NaN."""
    return None if math.isnan(value) else value


#: What of a weave the cell's fit leaves as the file gives it.
WEAVE_KEPT = {"weave.sample.seed": "the yarns' random distortion: not fitted, the file's kept (so are the "
                                    "cell's phase and the distortion's amplitudes)"}
#: Knobs the figures cannot tell apart from a fitted one: they keep the file's values.
UNSEPARATED = {
    "source.focal_spot_mm": "blurs the surface as the detector blur does: fitted as detector.blur_sigma_px",
    "detector.electronic_noise": "adds to the photon noise: the noise σ is fitted through source.mas",
}


def _volume(value, loaded: ScanFile, what: str) -> np.ndarray:
    """``value`` (a TIFF path or an array) as a float64 volume on the scan file's grid, checked."""
    if isinstance(value, (str, Path)):
        value = read_tiff_file(value, what)[0]
    volume = np.asarray(value, dtype=np.float64)
    if volume.shape != loaded.volume.shape:
        raise ConfigError(f"{what} has shape {volume.shape}, the scan file's [volume] grid {loaded.volume.shape}: "
                          "reconstruct it on that grid (or set [volume] to it)")
    if not np.isfinite(volume).all():
        raise ConfigError(f"{what} has {int((~np.isfinite(volume)).sum())} NaN or infinite voxels; give finite values")
    if volume.max() == volume.min():
        raise ConfigError(f"{what} is constant ({volume.flat[0]:g}): nothing to fit to")
    return volume


def _field_of_view(loaded: ScanFile) -> tuple[np.ndarray, np.ndarray]:
    """The voxels every view sees (a cylinder about the axis, 95 % of the detector's reach there)
    and each column's distance from the axis in voxels."""
    grid = loaded.volume
    y, x = np.meshgrid(grid.axis_centres(1), grid.axis_centres(2), indexing="ij")
    radius_mm = np.hypot(y, x)
    layout = detector_layout(loaded.geometry)
    reach = layout.shape[1] * layout.pitch_mm[1] / 2 / layout.magnification
    inside = np.broadcast_to(radius_mm < 0.95 * reach, grid.shape).copy()
    return inside, radius_mm / grid.voxel_size[1]


def _given_labels(labels, loaded: ScanFile, start: Figures) -> np.ndarray:
    """The user's region labels, checked: on the grid, holding some of the scan's classes."""
    given = _volume(labels, loaded, "the labels").astype(np.int64)
    if given.min() < 0 or not set(np.unique(given)) & set(start.peaks):
        raise ConfigError(f"the labels hold none of the scan's classes {sorted(start.peaks)} (0 is the air)")
    return given
