"""scripts/profile_scan.py: the passes it times add up to the stages scan.json reports."""

from __future__ import annotations

import json

import pytest

from scripts import profile_scan


@pytest.mark.usefixtures("gl")
def test_passes_are_charged_to_their_stages(tmp_path):
    out = tmp_path / "profile.json"
    profile_scan.main(["--quick", "--json", str(out)])
    payload = json.loads(out.read_text())
    rows, stages = payload["rows"], payload["stages_s"]
    by_stage = {}
    for row in rows:
        by_stage[row["stage"]] = by_stage.get(row["stage"], 0.0) + row["seconds"]
    for stage in profile_scan.STAGES:  # each stage's passes and rest make up its time
        assert by_stage[stage] == pytest.approx(stages[stage], abs=1e-9)
    calls = {(row["stage"], row["pass"]): row["calls"] for row in rows}
    assert calls["projections", "CPU physics"] == 120  # one radiograph a view of examples/twin_small.toml
    assert calls["projections", "GL crossing passes"] >= 120  # once a view, again where a list overflowed
    assert calls["fdk", "backprojection"] >= 1 and calls["labels", "GL overlap/label pass"] >= 1
    assert all(row["seconds"] >= 0 for row in rows if row["pass"] != "rest")
    # the timers are gone afterwards
    assert not hasattr(profile_scan.CrossingEngine._record, "__wrapped__")
    assert profile_scan.scan_module._timed.__name__ == "_timed"
