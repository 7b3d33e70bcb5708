"""scripts/profile_scan.py: the passes it times add up to the stages scan.json reports. The script
is run as a child process (tests import no benchmark code)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
STAGES = ("sample", "projections", "fdk", "labels")  # scan.json's stages


@pytest.mark.usefixtures("gl")
def test_passes_are_charged_to_their_stages(tmp_path):
    out = tmp_path / "profile.json"
    subprocess.run([sys.executable, "-m", "scripts.profile_scan", "--quick", "--json", str(out)], cwd=ROOT, check=True)
    payload = json.loads(out.read_text())
    rows, stages = payload["rows"], payload["stages_s"]
    assert set(STAGES) <= set(stages)
    by_stage = {}
    for row in rows:
        by_stage[row["stage"]] = by_stage.get(row["stage"], 0.0) + row["seconds"]
    for stage in STAGES:  # each stage's passes and rest make up its time
        assert by_stage[stage] == pytest.approx(stages[stage], abs=1e-9)
    calls = {(row["stage"], row["pass"]): row["calls"] for row in rows}
    assert calls["projections", "CPU physics"] == 120  # one radiograph a view of examples/twin_small.toml
    assert calls["projections", "GL crossing passes"] >= 120  # once a view, again where a list overflowed
    assert calls["fdk", "backprojection"] >= 1 and calls["labels", "GL overlap/label pass"] >= 1
    assert all(row["seconds"] >= 0 for row in rows if row["pass"] != "rest")
