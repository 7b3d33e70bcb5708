"""The fit's knobs and its rounds (:func:`~xrayraster.pipeline.fit.fit`; docs/fit.md): the values a scan
file is fitted by (:class:`Knobs`), and the search that moves each from its figure and keeps every
run (:class:`Search`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..io.scan_file import ScanFile
from ..io.scan_keys import set_key
from ..physics.detector import Detector
from ..physics.spectrum import Spectrum
from ..scene.materials import Material
from ..weave.materials import FibreBundle
from .fit_figures import Figures
from .fit_tracer import FIBRE, tracer_entry

#: Relative error of each figure within which it is fitted (the peaks: each class's).
TOLERANCES = {"peaks": 0.01, "noise_sigma": 0.05, "edge_width_mm": 0.05, "ring_rms": 0.10}
#: The figure each knob is fitted by.
FIGURE_OF = {"source.mas": "noise_sigma", "detector.blur_sigma_px": "edge_width_mm",
             "detector.gain_variation": "ring_rms"}
#: The figures as the report names them.
FIGURE_NAMES = {"peaks": "class peaks", "noise_sigma": "noise σ", "edge_width_mm": "edge width", "ring_rms": "rings' RMS"}
#: The smallest fibre fraction a tracer is given.
MIN_FRACTION = 0.02
#: The blur (px) and gain variation of the second run that sets a knob's quadratic model.
BLUR_STEP_PX, GAIN_STEP = 0.5, 0.005


@dataclass(frozen=True)
class Knobs:
    """The fitted values: each [materials] entry's density factor, mAs, blur (px), gain variation and
    each tracer's fibre fraction."""

    density: dict  # material name → factor on the file's density
    base_density: dict  # material name → the file's density
    mas: float
    base_mas: float
    blur: float
    gain: float
    tracers: dict = dataclasses.field(default_factory=dict)  # tracer yarn → its fibres' fraction
    matrix: Material | None = None  # the sample's matrix, which a tracer's fibres lie in

    @classmethod
    def of(cls, loaded: ScanFile, table: dict) -> "Knobs":
        declared = table.get("materials", {})
        densities = {name: float(spec["density"]) for name, spec in declared.items()
                     if isinstance(spec, dict) and "density" in spec}
        mas = float(table.get("source", {}).get("mas", 1.0))
        detector = loaded.detector or Detector()
        return cls({name: 1.0 for name in densities}, densities, mas, mas, detector.blur_sigma_px,
                   loaded.realism.gain_variation)

    def materials(self, materials, tracers: dict | None = None) -> dict:
        """The scene's materials with the fitted densities, and its ``tracers`` (yarn → the scene's
        material) with their fitted fibre fractions, by the scene's material."""
        out = {m: Material(m.name, m.composition, m.density * self.density[m.name]) for m in materials
               if getattr(m, "name", None) in self.density and self.density[m.name] != 1.0}
        for yarn, fraction in self.tracers.items():
            if yarn in (tracers or {}):
                out[tracers[yarn]] = FibreBundle(FIBRE, fraction).material(out.get(self.matrix, self.matrix))
        return out

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

    def compare(self, other: "Knobs") -> dict:
        return {key: (value, other.values()[key]) for key, value in self.values().items()}

    def write(self, table: dict) -> dict:
        for key, value in self.values().items():
            if key == "source.mas" and "kvp" not in table.get("source", {}):
                continue  # a source without a tube: its photons, not mAs, are what the file gives
            set_key(table, key, round(float(value), 6))
        if self.tracers:
            set_key(table, "weave.materials.tracers", [tracer_entry(y, f) for y, f in self.tracers.items()])
        return table


class Search:
    """The rounds of :func:`fit`: each knob updated from its figure, every run kept."""

    def __init__(self, knobs: Knobs, start: Figures, target: Figures, run, objects):
        self.knobs, self.figures, self.target, self._run = knobs, start, target, run
        self.label_material = {o.label: getattr(o.material, "name", None) for o in objects}
        self.runs = [self._record(knobs, start)]
        self.unidentified: dict[str, str] = {}
        self.kept: set[str] = set()  # knobs the figures cannot show at all: never changed

    @property
    def best(self) -> tuple[Knobs, Figures]:
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
        return all(abs(e) <= TOLERANCES[name] for name, e in relative_errors(self.best[1], self.target).items()
                   if not math.isnan(e) and name not in free)

    def evaluate(self, knobs: Knobs) -> Figures:
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
        # A tracer's μ is mostly its fibres': its fraction scales as its peak.
        tracers = {yarn: min(max(f * self.target.tracers[yarn] / self.figures.tracers[yarn], MIN_FRACTION), 1.0)
                   for yarn, f in self.knobs.tracers.items()
                   if self.figures.tracers.get(yarn, 0) > 0 and self.target.tracers.get(yarn, 0) > 0}
        if not ratios and not tracers:
            return
        density = {name: f * (float(np.mean(ratios[name])) if name in ratios else 1.0)
                   for name, f in self.knobs.density.items()}
        self.knobs = dataclasses.replace(self.knobs, density=density, tracers={**self.knobs.tracers, **tracers})
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

    def _quadratic(self, knob: str, figure: str, step: float, key: str) -> Knobs:
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

    def _record(self, knobs: Knobs, figures: Figures) -> dict:
        return {"knobs": knobs, "figures": figures, "errors": relative_errors(figures, self.target)}


def _worst(errors: dict, free: set) -> float:
    """The largest relative error of the figures not in ``free`` (NaN: not measured, left out)."""
    return max((abs(e) for name, e in errors.items() if not math.isnan(e) and name not in free), default=math.inf)


def relative_errors(figures: Figures, target: Figures) -> dict:
    """Relative error of each figure against the target's (the peaks: the largest of the classes' and
    the tracers')."""
    peaks = [abs(figures.peaks[k] / v - 1) for k, v in target.peaks.items() if k in figures.peaks and v]
    peaks += [abs(figures.tracers[k] / v - 1) for k, v in target.tracers.items() if k in figures.tracers and v]
    out = {"peaks": max(peaks, default=math.nan)}
    for name in ("noise_sigma", "edge_width_mm", "ring_rms"):
        want = getattr(target, name)
        out[name] = getattr(figures, name) / want - 1 if want and not math.isnan(want) else math.nan
    return out
