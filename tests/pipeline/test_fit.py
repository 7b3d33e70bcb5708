"""``xrayraster fit`` (pipeline/fit.py) on "real" scans made by the simulator with values the fit is
not told: it must find them again from the volume alone, and refuse bad inputs in one line."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tifffile
import tomli_w

import xrayraster as xr
from xrayraster import cli
from xrayraster.pipeline.fit_report import report_paths

ROOT = Path(__file__).resolve().parents[2]
# The hidden scanner: a matrix 6 % denser, 0.4 as many photons, a 0.8 px detector blur, 0.3 % gain
# variation (rings), and the real scan's own noise draw.
HIDDEN = {"materials.matrix.density": 1.15, "source.mas": 0.0002, "detector.blur_sigma_px": 0.8,
          "detector.gain_variation": 0.003}


def start_table() -> dict:
    """The bundled small scan with air above and below the sample (the noise and rings are measured
    there) and few photons (so the photon noise shows beside the 90 views' streaks)."""
    table = tomllib.loads((ROOT / "examples" / "scan_small.toml").read_text())
    table["geometry"]["detector_shape"] = [44, 64]
    table["volume"]["shape"] = [40, 64, 64]
    table["source"]["mas"] = 0.0005
    table["scan"]["seed"] = 5
    return table


@pytest.fixture(scope="module")
def real(gl, cl, tmp_path_factory):
    """The start scan file, and the real volume and labels of the hidden one (its own seed)."""
    folder = tmp_path_factory.mktemp("fit")
    table = start_table()
    (folder / "start.toml").write_text(tomli_w.dumps(table))
    for key, value in HIDDEN.items():
        section, *rest = key.split(".")
        holder = table.setdefault(section, {})
        for part in rest[:-1]:
            holder = holder.setdefault(part, {})
        holder[rest[-1]] = value
    table["scan"]["seed"] = 11
    (folder / "hidden.toml").write_text(tomli_w.dumps(table))
    result = xr.scan(folder / "hidden.toml", gl=gl, cl=cl)
    result.volume.save(folder / "real.tif")
    result.labels.save(folder / "labels.tif")
    return folder


def test_with_region_labels_every_hidden_value_is_found(real, capsys):
    out = real / "fitted.toml"
    assert cli.main(["fit", str(real / "real.tif"), str(real / "start.toml"), "-o", str(out),
                     "--labels", str(real / "labels.tif")]) == 0
    print(capsys.readouterr().out)
    fitted = tomllib.loads(out.read_text())
    assert fitted["materials"]["matrix"]["density"] == pytest.approx(1.15, rel=0.02)
    for name in ("weft_carbon", "warp_carbon"):  # not changed: found where they were
        assert fitted["materials"][name]["density"] == pytest.approx(start_table()["materials"][name]["density"],
                                                                     rel=0.02)
    assert fitted["source"]["mas"] == pytest.approx(0.0002, rel=0.15)
    assert fitted["detector"]["blur_sigma_px"] == pytest.approx(0.8, abs=0.15)
    assert fitted["detector"]["gain_variation"] == pytest.approx(0.003, rel=0.2)
    report_json, report_png = report_paths(out)
    report = json.loads(report_json.read_text())
    assert report["generator"] == "xrayraster fit" and report["converged"]
    for name, error in report["relative_errors"].items():  # each figure named, before and after
        assert abs(error["fitted"]) < abs(error["start"]), name
    assert abs(report["relative_errors"]["peaks"]["fitted"]) < 0.02
    assert abs(report["relative_errors"]["noise_sigma"]["fitted"]) < 0.10
    assert abs(report["relative_errors"]["edge_width_mm"]["fitted"]) < 0.10
    assert set(report["not_fitted"]) == {"source.focal_spot_mm", "detector.electronic_noise", "weave.sample.seed"}
    for key, value in start_table()["weave"].items():  # the labels are the start cell's: it stays
        if not isinstance(value, dict):
            assert report["parameters"][f"weave.{key}"]["fitted"] == pytest.approx(value), key
    assert report["weave"]["agreement"]["fitted"] == 1.0 and report["weave"]["tracers"] == []
    assert report_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The fitted file is a scan file: it loads (its paths made absolute) and names its report.
    assert xr.pipeline.load_scan_file(out).options.seed == 5
    assert report_json.name in out.read_text().splitlines()[0]


def test_without_labels_the_cell_is_fitted_and_then_each_material(real):
    result = xr.fit(real / "real.tif", real / "start.toml")
    fitted = dict(result.parameters)
    # The mAs within 25 % (0.00016 here: the body cut by μ moves the air the noise is taken in).
    assert fitted["source.mas"][1] == pytest.approx(0.0002, rel=0.25)
    assert fitted["detector.blur_sigma_px"][1] == pytest.approx(0.8, abs=0.15)
    for key in ("weft_spacing", "warp_spacing", "thickness"):  # the hidden cell is the start's
        assert fitted[f"weave.{key}"][1] == pytest.approx(fitted[f"weave.{key}"][0], rel=0.05), key
    # Each material under the fitted cell's labels: the matrix 6 % denser, the yarns as they were.
    assert fitted["materials.matrix.density"][1] == pytest.approx(1.15, rel=0.04)
    for name in ("weft_carbon", "warp_carbon"):
        assert fitted[f"materials.{name}.density"][1] == pytest.approx(fitted[f"materials.{name}.density"][0], rel=0.04)
    assert "materials.*.density" not in result.unidentified
    assert result.weave["tracers"] == []  # carbon only: no yarn is bright
    assert abs(result.errors["peaks"][1]) < 0.02


def test_without_labels_and_the_cell_kept_one_factor_is_fitted_for_the_materials(real):
    result = xr.fit(real / "real.tif", real / "start.toml", weave=False)
    fitted = dict(result.parameters)
    assert fitted["source.mas"][1] == pytest.approx(0.0002, rel=0.15)
    assert not any(key.startswith("weave.") for key in fitted) and not result.weave
    factors = {key: b / a for key, (a, b) in fitted.items() if key.endswith(".density")}
    assert max(factors.values()) - min(factors.values()) < 1e-9  # one factor for every material
    assert "materials.*.density" in result.unidentified
    assert abs(result.errors["peaks"][1]) < 0.02


@pytest.mark.parametrize("make, message", [
    (lambda folder: np.zeros((8, 64, 64), np.float32), r"shape \(8, 64, 64\), the scan file's \[volume\] grid"),
    (lambda folder: np.full((40, 64, 64), 0.3, np.float32), "is constant"),
    (lambda folder: np.zeros((40, 64, 64), np.float32), r"is constant \(0\): nothing to fit to"),
    (lambda folder: np.where(np.arange(40 * 64 * 64).reshape(40, 64, 64) == 7, np.nan, 0.1).astype(np.float32),
     "1 NaN or infinite voxels"),
])
def test_a_bad_real_volume_is_one_line_and_exit_2(real, tmp_path, capsys, make, message):
    bad = tmp_path / "bad.tif"
    tifffile.imwrite(bad, make(tmp_path))
    assert cli.main(["fit", str(bad), str(real / "start.toml"), "-o", str(tmp_path / "fitted.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.tif"]


def test_a_scan_file_that_cannot_be_simulated_is_one_line_and_exit_2(real, tmp_path, capsys):
    table = start_table()
    table["source"]["kvp"] = -40.0
    (tmp_path / "bad.toml").write_text(tomli_w.dumps(table))
    assert cli.main(["fit", str(real / "real.tif"), str(tmp_path / "bad.toml"), "-o", str(tmp_path / "f.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "kvp must be > 0" in err, err
    assert cli.main(["fit", str(tmp_path / "missing.tif"), str(tmp_path / "bad.toml"), "-o",
                     str(tmp_path / "f.toml")]) == 2
    assert "missing.tif" in capsys.readouterr().err
    assert cli.main(["fit", str(real / "real.tif"), str(real / "start.toml"), "-o", str(tmp_path / "f.tif")]) == 2
    assert "must end in .toml" in capsys.readouterr().err
