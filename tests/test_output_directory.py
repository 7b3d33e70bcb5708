"""core.files.atomic_directory (a directory of outputs appears whole or not at all) and
ConeBeamGeometry.framing (a detector that sees the whole sample), checked from first principles."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core.files import NEW_DIR_MODE, atomic_directory


def _ours(path: Path) -> bool:
    return (path / "report.json").is_file()


def test_new_directory_appears_whole(tmp_path):
    out = tmp_path / "deep" / "meshes"
    with atomic_directory(out, replaceable=_ours) as tmp:
        assert tmp.parent == out.parent and not out.exists()   # built beside, under another name
        (tmp / "report.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]
    assert out.stat().st_mode & 0o777 == NEW_DIR_MODE
    assert [p.name for p in out.parent.iterdir()] == ["meshes"]        # no temporary left


def test_failure_leaves_the_old_output_untouched(tmp_path):
    out = tmp_path / "meshes"
    out.mkdir()
    (out / "report.json").write_text("old")
    with pytest.raises(RuntimeError), atomic_directory(out, replaceable=_ours) as tmp:
        (tmp / "report.json").write_text("new")
        raise RuntimeError("the work failed")
    assert (out / "report.json").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["meshes"]


def test_an_earlier_output_is_replaced_not_merged(tmp_path):
    out = tmp_path / "meshes"
    out.mkdir()
    (out / "report.json").write_text("old")
    (out / "yarn_7.stl").write_text("from a bigger run")
    with atomic_directory(out, replaceable=_ours) as tmp:
        (tmp / "report.json").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]
    assert [p.name for p in tmp_path.iterdir()] == ["meshes"]


@pytest.mark.parametrize("make", ["file", "foreign directory"])
def test_refuses_to_replace_what_it_did_not_write(tmp_path, make):
    out = tmp_path / "meshes"
    if make == "file":
        out.write_text("precious")
    else:
        out.mkdir()
        (out / "thesis.tex").write_text("precious")
    with pytest.raises(xr.ConfigError, match="not an earlier output"), atomic_directory(out, replaceable=_ours):
        pytest.fail("the body must not run")
    assert out.exists()


@pytest.mark.parametrize("radius, half_height, magnification", [(7.07, 2.0, 2.0), (1.0, 10.0, 1.3), (50.0, 1.0, 4.0)])
def test_framing_sees_the_whole_cylinder_from_every_view(radius, half_height, magnification):
    g = xr.ConeBeamGeometry.framing(radius, half_height, num_views=12, magnification=magnification, columns=200)
    assert g.detector_shape[1] == 200 and g.num_views == 12
    phi = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    rim = np.concatenate([np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, z)])
                          for z in (-half_height, half_height)])
    vec = g.to_vec().array
    rows, cols = g.detector_shape
    worst = 0.0
    for s, d, u, v in (np.split(row, 4) for row in vec):
        n = np.cross(u, v)
        t = ((d - s) @ n) / ((rim - s) @ n)              # where each ray s -> p meets the detector plane
        hit = s + t[:, None] * (rim - s) - d
        c = hit @ u / (u @ u)                            # pixel units from the detector centre
        r = hit @ v / (v @ v)
        assert np.all(np.abs(c) <= cols / 2) and np.all(np.abs(r) <= rows / 2)
        worst = max(worst, np.abs(c).max() / (cols / 2))
    assert worst > 0.97                                  # and it is not needlessly wide (2 % margin)
    assert math.isclose(g.source_to_detector / g.source_to_origin, magnification)


def test_framing_rejects_bad_values():
    with pytest.raises(xr.GeometryError, match="magnification"):
        xr.ConeBeamGeometry.framing(5.0, 1.0, magnification=1.0)
    with pytest.raises(xr.GeometryError, match="radius"):
        xr.ConeBeamGeometry.framing(-5.0, 1.0)
