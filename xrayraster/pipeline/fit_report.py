"""What ``xrayraster fit`` writes: the fitted scan file, its report as JSON and a picture of it
(real, starting and fitted histograms, noise power spectra and edge profiles side by side, each
figure's error before and after in the titles). Each file is written atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import tomli_w

from ..core.files import atomic_write, atomic_write_text
from ..core.ownership import SOFTWARE, TOML_HEADER, check_replaceable_files
from ..io.optional import optional_module
from .fit import FitResult

CURVES = (("real", "k"), ("start", "C1"), ("fitted", "C0"))


def report_paths(fitted_toml: Path) -> tuple[Path, Path]:
    """The report's JSON and PNG beside ``fitted_toml`` (``FITTED.fit.json``, ``FITTED.fit.png``)."""
    fitted_toml = Path(fitted_toml)
    return fitted_toml.with_suffix(".fit.json"), fitted_toml.with_suffix(".fit.png")


def write_fit(result: FitResult, fitted_toml, *, real_name: str, scan_name: str) -> list[Path]:
    """Write the fitted scan file at ``fitted_toml`` and its report beside it; the paths written."""
    fitted_toml = Path(fitted_toml)
    json_path, png_path = report_paths(fitted_toml)
    check_replaceable_files([fitted_toml, json_path, png_path])
    header = (f"{TOML_HEADER} fit: {scan_name} fitted to {real_name}; report: {json_path.name}\n"
              f"# {'converged' if result.converged else 'not converged (the best run kept)'} in "
              f"{len(result.runs)} runs, {result.seconds:.0f} s\n")
    written = [atomic_write_text(fitted_toml, header + tomli_w.dumps(result.table))]
    record = {"generator": "xrayraster fit", "real": real_name, "scan_file": scan_name, **result.to_dict()}
    written.append(atomic_write_text(json_path, json.dumps(record, indent=1, default=float) + "\n"))
    written.append(write_fit_png(result, png_path))
    return written


def write_fit_png(result: FitResult, path) -> Path:
    optional_module("matplotlib", "compare", "the fit's picture")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(13, 4), layout="constrained")
    FigureCanvasAgg(figure)
    histogram, spectrum, edge = figure.subplots(1, 3)
    figures = {"real": result.real, "start": result.start, "fitted": result.fitted}
    volumes = list(result.volumes.values())
    low, high = (np.percentile(np.concatenate([v.ravel()[::7] for v in volumes]), (0.1, 99.9)) if volumes
                 else (0.0, 1.0))
    for name, colour in CURVES:
        if name in result.volumes:
            counts, edges = np.histogram(result.volumes[name], bins=200, range=(low, high), density=True)
            histogram.plot((edges[:-1] + edges[1:]) / 2, counts, color=colour, label=name)
        nps = figures[name].nps
        if nps:
            spectrum.plot(np.arange(len(nps)) / (2 * (len(nps) - 1)), nps, color=colour, label=name)
        distance, profile = figures[name].edge_profile
        if distance:
            edge.plot(distance, profile, ".-", color=colour, markersize=3, label=name)
    errors = result.errors
    histogram.set_title(f"histograms; class peaks' largest error {_percent(errors['peaks'])}", fontsize=9)
    histogram.set_xlabel("μ (cm⁻¹)")
    histogram.set_yscale("log")
    spectrum.set_title(f"noise power spectrum in the air; σ error {_percent(errors['noise_sigma'])}", fontsize=9)
    spectrum.set_xlabel("spatial frequency (cycles a voxel)")
    spectrum.set_ylabel("share of the power")
    edge.set_title(f"the sample's surface; width error {_percent(errors['edge_width_mm'])}", fontsize=9)
    edge.set_xlabel("signed distance from the surface (mm, + outside)")
    edge.set_ylabel("mean μ (cm⁻¹)")
    for axes in (histogram, spectrum, edge):
        axes.legend(fontsize=7)
    return atomic_write(path, lambda tmp: figure.savefig(tmp, format="png", dpi=100, metadata={"Software": SOFTWARE}))


def _percent(pair) -> str:
    """``start → fitted`` relative errors as percentages, n/a where a figure was not measured (NaN)."""
    return " → ".join("n/a" if value != value else f"{value:+.1%}" for value in pair)
