"""A scan file fitted to a real reconstruction (``xrayraster fit``, ``xr.fit``; docs/fit.md).

The simulation of a scan file is made to look like a real scan in what a segmentation network
sees (:mod:`~xrayraster.pipeline.fit_figures`), one knob a figure:

=====================================  ====================================  =========================
figure                                 scan-file key                         update
=====================================  ====================================  =========================
the sample surface's edge width        ``detector.blur_sigma_px``            width² = a + b·blur², two runs
each class's peak                      ``materials.NAME.density``            ×= real / simulated peak
the rings                              ``detector.gain_variation``           rms² = a + b·gain², two runs
the noise σ in the air                 ``source.mas``                        photon variance ∝ 1 / mAs
=====================================  ====================================  =========================

The sample's path lengths are rendered once; every run after is the physics of those path lengths
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
the classes' peaks are the means of a Gaussian mixture of its values started at the simulation's
peaks, and the sample is where μ is above halfway from the air to its lowest class.
"""

from __future__ import annotations

import copy
import dataclasses
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
from ..physics.detector import Detector
from ..physics.scatter import detector_layout
from ..physics.spectrum import Spectrum
from ..recon.fdk import fdk
from ..recon.fdk_weights import footprint_radius
from ..recon.opencl import CLContext
from ..scene.materials import Material
from ..simulate.renderer import Renderer
from .fit_figures import Figures, measure, sides_seen

#: Relative error of each figure within which it is fitted (the peaks: each class's).
TOLERANCES = {"peaks": 0.01, "noise_sigma": 0.05, "edge_width_mm": 0.05, "ring_rms": 0.10}
#: The figure each knob is fitted by.
FIGURE_OF = {"source.mas": "noise_sigma", "detector.blur_sigma_px": "edge_width_mm",
             "detector.gain_variation": "ring_rms"}
#: The figures as the report names them.
FIGURE_NAMES = {"peaks": "class peaks", "noise_sigma": "noise σ", "edge_width_mm": "edge width", "ring_rms": "rings' RMS"}
#: The blur (px) and gain variation of the second run that sets a knob's quadratic model.
BLUR_STEP_PX, GAIN_STEP = 0.5, 0.005


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

    def to_dict(self) -> dict:
        """The report (docs/fit.md): JSON-ready."""
        return {"parameters": {k: {"start": a, "fitted": b} for k, (a, b) in self.parameters.items()},
                "figures": {"real": self.real.to_dict(), "start": self.start.to_dict(),
                            "fitted": self.fitted.to_dict()},
                "relative_errors": {k: {"start": _plain(a), "fitted": _plain(b)} for k, (a, b) in self.errors.items()},
                "tolerances": TOLERANCES, "not_fitted": self.unidentified, "converged": self.converged,
                "runs": [{"values": r["knobs"].values(), "relative_errors": {k: _plain(v) for k, v in r["errors"].items()}}
                         for r in self.runs],
                "seconds": self.seconds}


def fit(real, scan, *, labels=None, rounds: int = 3, gl=None, cl: CLContext | None = None) -> FitResult:
    """Fit the scan file ``scan`` (a path) to the reconstruction ``real`` (a TIFF path or a (z, y, x)
    array in cm⁻¹ on the file's grid), with the user's region ``labels`` (a path or an array) when
    given (module docstring)."""
    started = time.perf_counter()
    path = Path(scan)
    loaded = load_scan_file(path)
    table = absolute_paths(read_toml(path, "scan file"), path.parent)
    real = _volume(real, loaded, "the real volume")
    knobs = _Knobs.of(loaded, table)
    scene = loaded.sample_scene()
    scanned = loaded.with_mount(scene)
    with Renderer(loaded.geometry, context=gl) as renderer, (nullcontext(cl) if cl is not None else CLContext()) as cl:
        lengths = renderer.path_lengths_all(scanned, progress=False)
        simulated_labels = voxelize(scene, loaded.volume, context=renderer.gl).data
        mount = (voxelize(loaded.mount, loaded.volume, context=renderer.gl).data > 0 if loaded.mount is not None
                 else np.zeros(simulated_labels.shape, bool))
        inside, axis_radius = _field_of_view(loaded)
        inside &= ~mount
        voxel_mm = float(min(loaded.volume.voxel_size))

        # Without labels, in every volume alike: the sample's classes share one peak, a two-component
        # mixture's (started at ``mixture``), and the sample is where μ is above half its lowest
        # class's, scaled as that peak is (``lowest``: the first run's, with its exact labels).
        classes: list = []
        mixture: dict = {}
        lowest: list = []

        def figures(volume, labels_=None):
            if not mixture:
                return measure(volume, labels_, inside, axis_radius, voxel_mm)
            peak = mixture_means(volume[inside], mixture)["sample"]
            above = volume > lowest[0] / 2 * peak / mixture["sample"]
            sample = ndimage.binary_fill_holes(ndimage.binary_opening(above, iterations=1)).astype(np.uint8)
            return dataclasses.replace(measure(volume, sample, inside, axis_radius, voxel_mm),
                                       peaks=dict.fromkeys(classes, peak))

        volumes = {"real": real}

        def run(k: _Knobs, noise: bool = True, keep: str | None = None) -> Figures:
            projections = renderer.project_lengths(
                scanned.with_materials(k.materials(scanned.materials)), lengths, k.spectrum(loaded.spectrum),
                detector=k.detector(loaded.detector), noise=noise and loaded.options.noise, seed=loaded.options.seed,
                realism=dataclasses.replace(loaded.realism, gain_variation=k.gain,  # without noise the flats' too
                                            flat_fields=loaded.realism.flat_fields if noise else None),
                spectral_table=True)
            volume = fdk(projections, volume=loaded.volume, filter=loaded.options.filter, context=cl,
                         truncation=loaded.options.truncation, truncation_width=loaded.options.truncation_width,
                         object_radius_mm=footprint_radius(*scanned.bounds))
            if keep:
                volumes[keep] = volume.data
            return figures(volume.data, simulated_labels)

        start = run(knobs, keep="start")
        real_labels = None
        if labels is not None:
            real_labels = _given_labels(labels, loaded, start)
        else:
            classes.extend(start.peaks)
            lowest.append(min(start.peaks.values()))
            mixture.update(air=0.0, sample=float(np.mean(list(start.peaks.values()))))
            mixture["sample"] = mixture_means(volumes["start"][inside], mixture)["sample"]
            start = figures(volumes["start"])
        target = figures(real, real_labels)
        search = _Search(knobs, start, target, run, scanned.objects)
        if not sides_seen(start, target):
            search.kept.add("detector.blur_sigma_px")
            search.unidentified["detector.blur_sigma_px"] = (
                "the sample shows no side in the field of view, and its faces along the axis are smeared by the "
                "cone beam (Feldkamp's artefact) more than by a blur: the file's kept")
        if classes:
            search.unidentified["materials.*.density"] = ("without region labels the classes' peaks overlap: one factor "
                                                          "is fitted for every material of the sample (--labels fits each)")
        for _ in range(rounds):
            if search.converged:
                break
            search.round()
        best_knobs, best = search.best
        run(best_knobs, keep="fitted")  # the same seed: the best run's volume again, for the report
    fitted_table = best_knobs.write(copy.deepcopy(table))
    return FitResult(fitted_table, knobs.compare(best_knobs), target, start, best,
                     {name: (_errors(start, target)[name], _errors(best, target)[name]) for name in TOLERANCES},
                     {**search.unidentified, **UNSEPARATED}, search.converged, search.runs,
                     time.perf_counter() - started, volumes)


def _plain(value: float):
    """``value`` for JSON: None for NaN."""
    return None if math.isnan(value) else value


#: Knobs the figures cannot tell apart from a fitted one: they keep the file's values.
UNSEPARATED = {
    "source.focal_spot_mm": "blurs the surface as the detector blur does: fitted as detector.blur_sigma_px",
    "detector.electronic_noise": "adds to the photon noise: the noise σ is fitted through source.mas",
}


@dataclass(frozen=True)
class _Knobs:
    """The fitted values: each [materials] entry's density factor, mAs, blur (px) and gain variation."""

    density: dict  # material name → factor on the file's density
    base_density: dict  # material name → the file's density
    mas: float
    base_mas: float
    blur: float
    gain: float

    @classmethod
    def of(cls, loaded: ScanFile, table: dict) -> "_Knobs":
        declared = table.get("materials", {})
        densities = {name: float(spec["density"]) for name, spec in declared.items()
                     if isinstance(spec, dict) and "density" in spec}
        mas = float(table.get("source", {}).get("mas", 1.0))
        detector = loaded.detector or Detector()
        return cls({name: 1.0 for name in densities}, densities, mas, mas, detector.blur_sigma_px,
                   loaded.realism.gain_variation)

    def materials(self, materials) -> dict:
        """The scene's materials with the fitted densities, by the scene's material."""
        return {m: Material(m.name, m.composition, m.density * self.density[m.name]) for m in materials
                if getattr(m, "name", None) in self.density and self.density[m.name] != 1.0}

    def spectrum(self, spectrum: Spectrum) -> Spectrum:
        if self.mas == self.base_mas:
            return spectrum
        return Spectrum.from_arrays(spectrum.energies, spectrum.fluence * (self.mas / self.base_mas),
                                    f"{spectrum.description} at {self.mas:.4g} mAs")

    def detector(self, detector: Detector | None) -> Detector:
        return dataclasses.replace(detector or Detector(), blur_sigma_px=self.blur, psf=None)

    def values(self) -> dict:
        return {**{f"materials.{name}.density": self.base_density[name] * f for name, f in self.density.items()},
                "source.mas": self.mas, "detector.blur_sigma_px": self.blur, "detector.gain_variation": self.gain}

    def compare(self, other: "_Knobs") -> dict:
        return {key: (value, other.values()[key]) for key, value in self.values().items()}

    def write(self, table: dict) -> dict:
        for key, value in self.values().items():
            if key == "source.mas" and "kvp" not in table.get("source", {}):
                continue  # a source without a tube: its photons, not mAs, are what the file gives
            set_key(table, key, round(float(value), 6))
        return table


class _Search:
    """The rounds of :func:`fit`: each knob updated from its figure, every run kept."""

    def __init__(self, knobs: _Knobs, start: Figures, target: Figures, run, objects):
        self.knobs, self.figures, self.target, self._run = knobs, start, target, run
        self.label_material = {o.label: getattr(o.material, "name", None) for o in objects}
        self.runs = [self._record(knobs, start)]
        self.unidentified: dict[str, str] = {}
        self.kept: set[str] = set()  # knobs the figures cannot show at all: never changed

    @property
    def best(self) -> tuple[_Knobs, Figures]:
        """The run with the smallest largest error over the figures whose knobs are pinned down (with
        the file's mAs where the mAs is not)."""
        free = {FIGURE_OF.get(key) for key in self.unidentified}
        runs = [r for r in self.runs if "source.mas" not in self.unidentified or r["knobs"].mas == self.knobs.base_mas]
        row = min(runs or self.runs, key=lambda r: _worst(r["errors"], free))
        return row["knobs"], row["figures"]

    @property
    def converged(self) -> bool:
        """Whether the best run has every figure within its tolerance (a figure that cannot be
        measured, or whose knob is not pinned down, aside)."""
        free = {FIGURE_OF.get(key) for key in self.unidentified}
        return all(abs(e) <= TOLERANCES[name] for name, e in _errors(self.best[1], self.target).items()
                   if not math.isnan(e) and name not in free)

    def evaluate(self, knobs: _Knobs) -> Figures:
        figures = self._run(knobs)
        self.runs.append(self._record(knobs, figures))
        return figures

    def round(self) -> None:
        if "detector.blur_sigma_px" not in self.kept:
            self.knobs = self._quadratic("blur", "edge_width_mm", BLUR_STEP_PX, "detector.blur_sigma_px")
        self._densities()  # after the blur, which moves the peaks of thin regions
        self.knobs = self._quadratic("gain", "ring_rms", GAIN_STEP, "detector.gain_variation")
        self._mas()  # after the rings, which vary from slice to slice as the noise does

    def _densities(self) -> None:
        ratios: dict[str, list[float]] = {}
        for label, peak in self.target.peaks.items():
            name = self.label_material.get(label)
            simulated = self.figures.peaks.get(label)
            if name in self.knobs.density and simulated and simulated > 0 and peak > 0:
                ratios.setdefault(name, []).append(peak / simulated)
        if not ratios:
            return
        density = {name: f * (float(np.mean(ratios[name])) if name in ratios else 1.0)
                   for name, f in self.knobs.density.items()}
        self.knobs = dataclasses.replace(self.knobs, density=density)
        self.figures = self.evaluate(self.knobs)

    def _mas(self) -> None:
        """The photons' share of the air's variance goes as 1 / mAs; the rest (streaks, cone-beam
        artefacts: the same in the simulation) is the variance of a run without noise."""
        simulated, real = self.figures.noise_sigma, self.target.noise_sigma
        if not (simulated > 0 and real > 0):
            self.unidentified["source.mas"] = "no air around the sample inside the field of view to measure the noise in"
            return
        structure = self._run(self.knobs, noise=False).noise_sigma ** 2
        photons, wanted = simulated**2 - structure, real**2 - structure
        if photons < 0.1 * simulated**2 or wanted <= 0.1 * real**2:
            self.unidentified["source.mas"] = (f"the photon noise is under a tenth of the air's variance (σ {real:.3g} "
                                               f"real, {math.sqrt(max(structure, 0)):.3g} without noise): the file's kept")
            if self.knobs.mas != self.knobs.base_mas:  # an earlier round's value, from a figure now seen as structure
                self.knobs = dataclasses.replace(self.knobs, mas=self.knobs.base_mas)
                self.figures = self.evaluate(self.knobs)
            return
        self.unidentified.pop("source.mas", None)
        self.knobs = dataclasses.replace(self.knobs, mas=self.knobs.mas * photons / wanted)
        self.figures = self.evaluate(self.knobs)

    def _quadratic(self, knob: str, figure: str, step: float, key: str) -> _Knobs:
        """The knob whose figure is the target's, from figure² = a + b·knob² through two runs."""
        here = getattr(self.knobs, knob)
        first, want = getattr(self.figures, figure), getattr(self.target, figure)
        if math.isnan(first) or math.isnan(want):
            self.unidentified[key] = f"the {FIGURE_NAMES[figure]} cannot be measured in these volumes"
            return self.knobs
        other = self.evaluate(dataclasses.replace(self.knobs, **{knob: here + step}))
        second = getattr(other, figure)
        slope = (second**2 - first**2) / ((here + step) ** 2 - here**2)
        if not slope > 0 or abs(second - first) < 0.02 * first:
            self.unidentified[key] = (f"the {FIGURE_NAMES[figure]} barely moves with it ({first:.4g} → "
                                      f"{second:.4g} for {here:g} → {here + step:g})")
            self.figures = other if abs(second - want) < abs(first - want) else self.figures
            return self.knobs
        self.unidentified.pop(key, None)
        value = math.sqrt(max(here**2 + (want**2 - first**2) / slope, 0.0))
        # Below this the figure is within its tolerance of the knob's zero: such a value is not told from none.
        floor = first**2 - slope * here**2
        smallest = math.sqrt(max(((1 + TOLERANCES[figure]) ** 2 - 1) * floor, 0.0) / slope)
        if value < smallest:
            self.unidentified[key] = (f"under {smallest:.2g} it changes the {FIGURE_NAMES[figure]} by less than "
                                      f"{TOLERANCES[figure]:.0%}: {value:.2g} found, not told from 0")
        knobs = dataclasses.replace(self.knobs, **{knob: value})
        self.figures = self.evaluate(knobs)
        return knobs

    def _record(self, knobs: _Knobs, figures: Figures) -> dict:
        return {"knobs": knobs, "figures": figures, "errors": _errors(figures, self.target)}


def _worst(errors: dict, free: set) -> float:
    """The largest relative error of the figures not in ``free`` (NaN: not measured, left out)."""
    return max((abs(e) for name, e in errors.items() if not math.isnan(e) and name not in free), default=math.inf)


def _errors(figures: Figures, target: Figures) -> dict:
    """Relative error of each figure against the target's (the peaks: the largest of the classes')."""
    peaks = [abs(figures.peaks[k] / v - 1) for k, v in target.peaks.items() if k in figures.peaks and v]
    out = {"peaks": max(peaks, default=math.nan)}
    for name in ("noise_sigma", "edge_width_mm", "ring_rms"):
        want = getattr(target, name)
        out[name] = getattr(figures, name) / want - 1 if want and not math.isnan(want) else math.nan
    return out


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


def mixture_means(values: np.ndarray, peaks: dict[int, float], iterations: int = 100) -> dict[int, float]:
    """The means of a 1-D Gaussian mixture of ``values`` (EM on a histogram of 1024 bins), a
    component a class started at its ``peaks`` value, by class."""
    counts, edges = np.histogram(values, bins=1024)
    centres = (edges[:-1] + edges[1:]) / 2
    labels = sorted(peaks, key=peaks.get)
    means = np.array([peaks[k] for k in labels], dtype=np.float64)
    gaps = np.diff(means)
    spread = np.full(len(means), max(float(gaps[gaps > 0].min()) / 4 if (gaps > 0).any() else 0.0,
                                     float(np.std(values)) / 20, 1e-6))
    share = np.full(len(means), 1 / len(means))
    for _ in range(iterations):
        density = share * np.exp(-0.5 * ((centres[:, None] - means) / spread) ** 2) / spread
        weight = density / np.maximum(density.sum(axis=1, keepdims=True), 1e-300) * counts[:, None]
        total = np.maximum(weight.sum(axis=0), 1e-12)
        means = (weight * centres[:, None]).sum(axis=0) / total
        spread = np.maximum(np.sqrt((weight * (centres[:, None] - means) ** 2).sum(axis=0) / total), 1e-6)
        share = total / total.sum()
    return {k: float(m) for k, m in zip(labels, means)}
