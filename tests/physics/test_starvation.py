"""Photon-starved scans: the share of the pixels the sample covers that detect no photon is recorded,
warned about over 1 % and refused over half (physics/starvation.py, docs/scan.md)."""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import pytest

from xrayraster import cli
from xrayraster.core.errors import StarvationWarning
from xrayraster.pipeline import load_scan_file, scan

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SMALL = EXAMPLES / "scan_small.toml"
SHARE = re.compile(r"(\d+\.\d) % of the pixels the sample covers are photon-starved")


def open_beam_photons(path: Path) -> float:
    """Photons a pixel on the central ray expects with nothing in the beam, from the spectrum and the
    geometry alone: fluence per mm² at 1 m × pixel area × (1 m / source-to-detector)² (inverse
    square; the default detector absorbs every photon)."""
    loaded = load_scan_file(path)
    (rows_mm, cols_mm), distance_mm = loaded.geometry.pixel_size, loaded.geometry.source_to_detector
    return loaded.spectrum.total * rows_mm * cols_mm * (1000.0 / distance_mm) ** 2


def with_mas(tmp_path: Path, mas: float) -> Path:
    text = SMALL.read_text(encoding="utf-8")
    assert "\nmas = 1.25\n" in text
    path = tmp_path / "scan.toml"
    path.write_text(text.replace("\nmas = 1.25\n", f"\nmas = {mas!r}\n"), encoding="utf-8")
    return path


def test_a_starved_scan_is_refused_after_its_first_batch_naming_the_share_and_the_flag(gl, cl, tmp_path, capsys):
    path = with_mas(tmp_path, 1e-9)
    photons = open_beam_photons(path)
    assert photons < 0.02  # so a pixel detects nothing with probability exp(-photons) ≥ 98 %
    code = cli.main(["scan", str(path), "-o", str(tmp_path / "out"), "--quiet"])
    lines = capsys.readouterr().err.splitlines()
    assert code == 2 and len(lines) == 1, lines
    assert "--allow-starved" in lines[0] and "raise [source] mas" in lines[0] and "first 32 views" in lines[0]
    # Attenuation only lowers a pixel's photons, so its chance of none is at least exp(-photons).
    assert float(SHARE.search(lines[0])[1]) / 100 >= math.exp(-photons) - 0.005
    assert not (tmp_path / "out").exists()


def test_allowed_the_starved_scan_completes_records_the_share_and_warns(gl, cl, tmp_path, capsys):
    path = with_mas(tmp_path, 1e-9)
    code = cli.main(["scan", str(path), "-o", str(tmp_path / "out"), "--quiet", "--allow-starved"])
    err = [line for line in capsys.readouterr().err.splitlines() if line]
    assert code == 0
    record = json.loads((tmp_path / "out" / "scan.json").read_text())["projections"]
    share = record["starved_share"]
    assert share == record["starved_covered_pixels"] / record["covered_pixels"]
    assert share >= math.exp(-open_beam_photons(path)) - 0.005
    assert record["starved_covered_pixels"] <= record["starved_pixels"]  # air starves too
    assert len(err) == 1 and err[0].startswith("xrayraster: warning: ") and f"{100 * share:.1f} %" in err[0]


def test_a_moderately_starved_scan_warns_and_runs(gl, cl, tmp_path):
    # Three photons a pixel in the open beam: exp(-3) = 5 % of the pixels see none, more behind the sample.
    photons = 3.0
    path = with_mas(tmp_path, 1.25 * photons / open_beam_photons(SMALL))
    assert open_beam_photons(path) == pytest.approx(photons)
    with pytest.warns(StarvationWarning, match=r"\d % of the pixels the sample covers") as caught:
        result = scan(path)
    share = result.metadata["projections"]["starved_share"]
    assert 0.01 < share < 0.5 and share >= math.exp(-photons) - 0.01
    assert f"{100 * share:.1f} %" in str(caught[0].message)


def test_the_example_scan_starves_nothing_and_says_nothing(gl, cl):
    with warnings.catch_warnings():
        warnings.simplefilter("error", StarvationWarning)
        record = scan(SMALL).metadata["projections"]
    assert record["starved_share"] == 0.0 and record["covered_pixels"] > 0


def test_render_warns_about_starved_radiographs(gl, tmp_path, capsys):
    text = (EXAMPLES / "bracket_ct.toml").read_text(encoding="utf-8")
    text = text.replace('mesh = "meshes/', f'mesh = "{EXAMPLES.as_posix()}/meshes/')
    assert "photons_per_mm2_at_1m = 1e7" in text
    scene = tmp_path / "scene.toml"
    scene.write_text(text.replace("photons_per_mm2_at_1m = 1e7", "photons_per_mm2_at_1m = 1e2"), encoding="utf-8")
    code = cli.main(["render", str(scene), "-o", str(tmp_path / "out.tif"), "--noise"])
    err = [line for line in capsys.readouterr().err.splitlines() if line]
    assert code == 0 and len(err) == 1, err
    assert err[0].startswith(f"xrayraster: warning: {scene}: ") and SHARE.search(err[0])
