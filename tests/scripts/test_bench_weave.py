"""scripts/bench_weave.py: its --quick run end to end (one fresh child process per case), its error
columns against the sagitta formula, and the budget's prediction (its --self-check). The script is
run as a child process (tests import no benchmark code)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from references.texgen import texgen_available
from xrayraster.weave import UnitCell

ROOT = Path(__file__).resolve().parents[2]


def _bench_weave(*args):
    return subprocess.run([sys.executable, "-m", "scripts.bench_weave", *args], cwd=ROOT, capture_output=True,
                          text=True)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench_weave")
    done = _bench_weave("--quick", "--json", str(out / "b.json"), "--plot", str(out / "b.png"))
    assert done.returncode == 0, done.stdout + done.stderr
    return json.loads((out / "b.json").read_text()), out / "b.png"


def _record(payload, kind):
    (rec,) = [r for r in payload["records"] if r["kind"] == kind]
    assert "error" not in rec and "skipped" not in rec, rec
    return rec


def test_quick_run_measures_the_same_sample_in_every_child(quick):
    payload, png = quick
    scan, measure, boolean = (_record(payload, kind) for kind in ("scan", "interpenetration", "boolean"))
    # Separate processes, separately built Samples: one seed and one distortion give one sample.
    assert boolean["before_mm3"] == pytest.approx(measure["volume_mm3"], rel=1e-9)
    assert measure["volume_mm3"] > 0 and boolean["after_mm3"] <= 1e-9 * measure["volume_mm3"]
    assert scan["triangles"] == measure["triangles"] + 12  # the scene adds the matrix box: 6 faces, 2 triangles each
    for rec in (scan, measure, boolean):
        # ru_maxrss is KiB on Linux: a Python process with numpy, trimesh and manifold3d holds tens to hundreds of MiB
        assert 20 < rec["baseline_mib"] <= rec["peak_mib"] < 4096
        assert rec["cells"] == 1 and rec["resolution"] == "coarse" and rec["calls"] == 1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(texgen_available() is not None, reason=f"TexGen peer: {texgen_available()}")
def test_quick_run_builds_every_yarn_of_the_cell_with_texgen(quick):
    rec = _record(quick[0], "texgen")
    cell = UnitCell()
    assert rec["yarns"] == (cell.weft_per_layer * cell.weft_layers + cell.binders
                            + len(cell.stuffer_x) * len(cell.stuffer_gaps))
    assert 0 <= rec["refused"] <= rec["yarns"] and 0 <= rec["watertight_fraction"] <= 1
    assert rec["seconds"] == pytest.approx(rec["build_s"] + rec["mesh_s"])


def test_error_columns_follow_the_sagitta(quick):
    errors = quick[0]["tessellation_error"]
    cell = UnitCell()
    assert set(errors) == {"default", "coarse"}
    for e in errors.values():
        rate = e["samples_per_mm"]
        radius, reach, h = e["binder_bend_radius_mm"], cell.warp_height / 2, 1.0 / rate
        # the outermost fibre's chord on the tightest bend: (R + d)(1 - cos(h / 2R))
        assert e["path_mm"] == pytest.approx((radius + reach) * (1 - np.cos(h / (2 * radius))), rel=1e-9)
        assert e["total_mm"] == pytest.approx(max(e["weft_section_mm"], e["warp_section_mm"]) + e["path_mm"])
    # the lenticular warp's arcs are smooth: halving the outline's points quadruples its sagitta
    ratio = errors["coarse"]["warp_section_mm"] / errors["default"]["warp_section_mm"]
    assert ratio == pytest.approx(4.0, rel=0.05)


def test_budget_predicts_growth_per_doubling_and_skips_after_a_skip():
    done = _bench_weave("--self-check")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count(": ok") == 4, done.stdout
