"""scripts/train_segmentation.py (docs/ml.md): its baselines (references/segmentation.py) recover
well-separated classes exactly, and the --quick run, a child process, builds both sets, trains,
scores every method on both, and reruns with the same seed to the same scores (the experiment's
reproducibility). The scripts are run, never imported (tests import no benchmark code)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from references.segmentation import baseline, confusion, dice_from_confusion

ROOT = Path(__file__).resolve().parents[2]

METHODS = {"network", "network, every body kept", "multi-Otsu, median 3³", "multi-Otsu, Gaussian σ 1",
           "Gaussian mixture, median 3³", "Gaussian mixture, Gaussian σ 1"}


def test_baselines_recover_well_separated_classes_and_dice_counts_overlap(torch):
    """Blocks of four attenuations far apart, little noise: each baseline gives back the labels,
    its clusters matched to the labels by the order of their means (here not the label order).
    (``torch``: the ml extra, which brings scikit-learn.)"""
    z, y, x = np.indices((30, 24, 24))
    truth = ((z // 10 + y // 12) % 4).astype(np.uint8)
    mu = np.array([0.0, 0.9, 0.3, 0.6])  # label 2 is the second darkest: order air, 2, 3, 1
    volume = (mu[truth] + np.random.default_rng(0).normal(0, 0.02, truth.shape)).astype(np.float32)
    for name in ("multi-Otsu", "Gaussian mixture"):
        for smooth in ("median 3³", "Gaussian σ 1"):
            predicted = baseline(name, smooth, [0, 2, 3, 1])(volume)
            inner = (z % 10 > 2) & (z % 10 < 7) & (y % 12 > 2) & (y % 12 < 9)  # away from the blurred edges
            assert np.array_equal(predicted[inner], truth[inner]), (name, smooth)
    half = truth.copy()
    half[:15] = 0  # wipes the other classes' voxels in the first half
    d = dice_from_confusion(confusion(truth, half, 4), (1, 2, 3))
    for c in (1, 2, 3):
        kept, total = np.sum((truth == c) & (half == c)), np.sum(truth == c)
        assert d[c] == pytest.approx(2 * kept / (total + kept))


def test_the_quick_run_scores_every_method_and_reruns_to_the_same_scores(torch, gl, cl, tmp_path):
    common = ["--quick", "--out", str(tmp_path / "ml"), "--plots-dir", str(tmp_path)]
    runs = []
    for name in ("first", "again"):  # the second reuses the builds, and trains and scores again
        subprocess.run([sys.executable, "-m", "scripts.train_segmentation", *common, "--json",
                        str(tmp_path / f"{name}.json")], cwd=ROOT, check=True)
        runs.append(json.loads((tmp_path / f"{name}.json").read_text()))
    first, again = runs
    assert first["iterations"] == 30 and first["classes"] == 4 and first["train_samples"] == 8
    for set_name in ("test split", "shifted", "shifted, fresh draw"):
        results = first["results"][set_name]
        assert set(results) == METHODS
        for method, r in results.items():
            assert 0.0 <= r["mean_dice"] <= 1.0 and set(r["dice"]) == {"matrix", "weft", "warp"}
            assert r["mean_dice"] == again["results"][set_name][method]["mean_dice"]  # same seed, same network
            scored = np.asarray(r["confusion"]).sum()
            assert scored == np.asarray(results["network"]["confusion"]).sum() > 0  # every method, the same voxels
    assert first["loss_last_20"] == again["loss_last_20"]
    for png in ("ml_curve.png", "ml_slices.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_every_ablation_variant_takes_back_what_it_says():
    """Each variant's patterns of scripts/ml_shift_ablation.py match one line each of the shipped
    shifted file, and the training weave's ranges are those of examples/ml_train.toml (its --check)."""
    done = subprocess.run([sys.executable, "-m", "scripts.ml_shift_ablation", "--check"], cwd=ROOT,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "variants checked: ok" in done.stdout


def _spans(spec) -> list[tuple[float, float]] | None:
    """The values a numeric ``[vary]`` entry can take, as closed intervals; None for any other entry."""
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        return [(spec, spec)]
    if not isinstance(spec, dict):
        return None
    if "choice" in spec:
        values = spec["choice"]
        return [(v, v) for v in values] if all(isinstance(v, (int, float)) for v in values) else None
    for kind in ("uniform", "loguniform", "integer"):
        if kind in spec:
            return [tuple(spec[kind])]
    return [tuple(spec["clip"])] if "clip" in spec else None


@pytest.mark.parametrize("train_file", sorted(p.name for p in (ROOT / "examples").glob("ml_train*.toml")))
def test_no_training_range_reaches_the_shifted_sets(train_file):
    """The shifted set is held out: for every numeric key the two files both draw (the tube, the
    scanner's imperfections, the weave's spacings, widths, shares and thickness), none of its values
    lies inside the training file's range (they may meet at an end, a value drawn with probability 0:
    ml_train.toml's weft share 0.45-0.6 meets the shifted 0.6-0.65). The viewing geometry and the
    voxel grid are shared on purpose (docs/ml.md): a key both files set to the same value is not
    compared."""
    import tomllib

    shifted = tomllib.loads((ROOT / "examples" / "ml_shifted.toml").read_text())["vary"]
    train = tomllib.loads((ROOT / "examples" / train_file).read_text())["vary"]
    compared = 0
    for key in shifted.keys() & train.keys():
        held_out, trained = _spans(shifted[key]), _spans(train[key])
        if held_out is None or trained is None or shifted[key] == train[key]:
            continue
        low, high = min(a for a, _ in trained), max(b for _, b in trained)
        for a, b in held_out:
            assert b <= low or a >= high, \
                f"{train_file}: {key} = {train[key]} reaches the shifted set's {shifted[key]}"
        compared += 1
    assert compared >= 8, f"{train_file}: only {compared} ranges compared"


def test_the_run_around_a_fit_tells_the_fit_only_what_a_user_knows(torch, gl, cl, tmp_path):
    """scripts/train_around_fit.py --quick (docs/ml.md, "Training around a fit"): the scan file the fit
    starts from takes of the shifted scan only its scanner's settings and its holder (not its mAs,
    focal spot, blur, gain variation, tracer or weave); the training file is ml_train_scanner.toml's,
    its scanner's and weave's ranges replaced by ±10 % of each fitted knob and of the fitted cell's
    keys (±2 % of each density) about the fitted file (a knob the fit could not pin down: of the start
    file's value), which carries the tracer the fit found; the network is trained and scored on the
    shifted set."""
    import tomllib

    from xrayraster.dataset.dataset_file import draw, load_dataset_file
    from xrayraster.dataset.distributions import Uniform
    from xrayraster.io.scan_keys import value_at

    folder = tmp_path / "ml"
    subprocess.run([sys.executable, "-m", "scripts.train_around_fit", "--quick", "--out", str(folder),
                    "--plots-dir", str(tmp_path), "--json", str(tmp_path / "run.json")], cwd=ROOT, check=True)
    shifted = draw(load_dataset_file(ROOT / "examples" / "ml_shifted.toml"), 0).table
    start = tomllib.loads((folder / "start.toml").read_text())
    assert start["source"]["kvp"] == shifted["source"]["kvp"] == 50.0 and start["mount"] == shifted["mount"]
    assert start["geometry"]["source_to_origin"] == shifted["geometry"]["source_to_origin"]
    assert start["detector"] == {"flat_fields": 10}  # no blur, no gain variation
    assert start["source"]["mas"] == 1.25 and "focal_spot_mm" not in start["source"]  # scan_small.toml's
    assert "tracers" not in start["weave"]["materials"] and "weft_spacing" not in start["weave"]

    fitted = tomllib.loads((folder / "fitted.toml").read_text())
    train = tomllib.loads((folder / "train.toml").read_text())
    scanner = tomllib.loads((ROOT / "examples" / "ml_train_scanner.toml").read_text())["vary"]
    report = json.loads((folder / "fitted.fit.json").read_text())
    assert train["base"] == "fitted.toml"
    for key in ("source.kvp", "detector.flat_fields", "geometry.source_to_origin"):
        assert key not in train["vary"]
    resolved = load_dataset_file(folder / "train.toml").vary
    for key in ("source.mas", "detector.blur_sigma_px", "detector.gain_variation"):
        value = value_at(fitted, key)  # as the fitted file rounds it: to 6 decimals
        assert value == pytest.approx(report["parameters"][key]["fitted"], rel=0, abs=5.000001e-7)
        assert resolved[key] == Uniform(value * 0.9, value * 1.1) if value else key not in train["vary"]
    assert "source.focal_spot_mm" not in train["vary"]
    for name in ("weft_carbon", "warp_carbon", "matrix"):
        density = fitted["materials"][name]["density"]
        assert resolved[f"materials.{name}.density"] == Uniform(density * 0.98, density * 1.02)
    for key in ("weft_spacing", "warp_spacing", "thickness"):  # the cell ±10 % about the fitted one
        value = fitted["weave"][key]
        assert resolved[f"weave.{key}"] == Uniform(value * 0.9, value * 1.1)
    for key in ("weft_width_fraction", "warp_width_fraction", "weft_share"):  # shares stay below 1
        value = fitted["weave"][key]
        assert resolved[f"weave.{key}"] == Uniform(value * 0.9, min(value * 1.1, 0.99))
    # The shifted scan's glass weft found, in the fitted file, and drawn as it is there.
    assert [t["yarn"] for t in fitted["weave"]["materials"]["tracers"]] == ["weft_c0_l1_y1"]
    assert "weave.materials.tracers" not in train["vary"]
    for key, value in train["vary"].items():  # the rest (distortions, seeds, split) as ml_train_scanner.toml's
        assert key in report["parameters"] or value == scanner[key]
    run = json.loads((tmp_path / "run.json").read_text())
    assert 0.0 <= run["training"]["results"]["shifted"]["network"]["mean_dice"] <= 1.0


@pytest.mark.parametrize("scale", ["1.4,0.7", "0,1.4", "0.7"])
def test_a_bad_scale_range_is_refused_before_any_work(scale):
    """--scale LO,HI needs 0 < LO <= HI: anything else is argparse's one-line error (exit 2), before
    torch is imported or anything is built."""
    done = subprocess.run([sys.executable, "-m", "scripts.train_segmentation", "--scale", scale], cwd=ROOT,
                          capture_output=True, text=True)
    assert done.returncode == 2 and "--scale" in done.stderr and "0.7,1.4" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
