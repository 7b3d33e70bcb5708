"""Sim-to-real metrics (xrayraster/pipeline/compare.py, ``xrayraster compare``) against their
formulas written here in float64 NumPy, and against scikit-image called directly."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from skimage import metrics  # the compare extra, in the test extra too: CI checks against it

from xrayraster import cli
from xrayraster.pipeline.compare import (
    CompareError,
    Histogram,
    compare,
    cosine_similarity,
    histogram,
    histogram_peaks,
    label_mask,
    psnr,
    ssim,
    value_range,
    write_histogram_png,
)

SHAPE = (12, 16, 20)  # every axis fits SSIM's 7-voxel window with interior to spare


def smooth_volume(seed: int = 0) -> np.ndarray:
    """A float32 volume with structure on the scale of SSIM's window (not white noise)."""
    z, y, x = np.meshgrid(*(np.arange(n) for n in SHAPE), indexing="ij")
    rng = np.random.default_rng(seed)
    wave = np.sin(0.5 * x + 0.3 * y) * np.cos(0.4 * z)
    return (0.45 + 0.05 * wave + 0.002 * rng.standard_normal(SHAPE)).astype(np.float32)


def noisy(volume: np.ndarray, sigma: float = 0.01, seed: int = 1) -> np.ndarray:
    return (volume + sigma * np.random.default_rng(seed).standard_normal(volume.shape)).astype(np.float32)


def psnr_formula(a, b, data_range) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return 10 * math.log10(data_range**2 / np.mean((a - b) ** 2))


def interior(shape, pad: int) -> np.ndarray:
    where = np.zeros(shape, bool)
    where[pad:-pad, pad:-pad, pad:-pad] = True
    return where


# Cosine similarity

def test_cosine_of_orthogonal_vectors_is_zero_and_of_a_scaled_copy_one():
    assert cosine_similarity([1.0, 0.0, 2.0, 0.0], [0.0, 3.0, 0.0, -1.0]) == 0.0
    a = np.random.default_rng(0).random(SHAPE).astype(np.float32)
    assert cosine_similarity(a, 2.5 * a) == pytest.approx(1.0, abs=1e-12)
    assert cosine_similarity(a, -a) == pytest.approx(-1.0, abs=1e-12)


def test_cosine_by_hand_and_in_float64():
    assert cosine_similarity([1, 2, 3], [4, 5, 6]) == pytest.approx(32 / math.sqrt(14 * 77), rel=1e-15)
    # float32 data whose float32 dot product would lose digits: the result is float64's.
    rng = np.random.default_rng(3)
    a, b = rng.random(SHAPE, dtype=np.float32) + 1e3, rng.random(SHAPE, dtype=np.float32) + 1e3
    a64, b64 = a.astype(np.float64).ravel(), b.astype(np.float64).ravel()
    expected = a64 @ b64 / math.sqrt((a64 @ a64) * (b64 @ b64))
    assert cosine_similarity(a, b) == pytest.approx(expected, rel=1e-13)


def test_cosine_of_a_zero_volume_is_an_error():
    with pytest.raises(CompareError, match="zero at every compared voxel"):
        cosine_similarity(np.zeros(SHAPE), np.ones(SHAPE))


# PSNR and SSIM

def test_psnr_is_the_formula_over_the_common_range():
    a = smooth_volume()
    b = noisy(a)
    common = max(a.max(), b.max()) - min(a.min(), b.min())
    assert psnr(a, b) == pytest.approx(psnr_formula(a, b, float(common)), rel=1e-12)
    assert psnr(a, b, data_range=2.0) == pytest.approx(psnr_formula(a, b, 2.0), rel=1e-12)
    assert psnr(a, a) == math.inf


def test_ssim_of_identical_volumes_is_one():
    a = smooth_volume()
    assert ssim(a, a) == pytest.approx(1.0, abs=1e-12)
    assert ssim(a, a, mask=a > 0.45) == pytest.approx(1.0, abs=1e-12)


def test_ssim_of_a_noisy_copy_is_skimage_averaged_over_the_documented_region():
    a = smooth_volume()
    b = noisy(a)
    common = float(max(a.max(), b.max()) - min(a.min(), b.min()))
    mean, full = metrics.structural_similarity(a.astype(np.float64), b.astype(np.float64), data_range=common, full=True)
    assert ssim(a, b) < 0.99
    assert ssim(a, b) == pytest.approx(mean, rel=1e-12)  # no mask: scikit-image's own mean
    mask = a > 0.45
    inside = np.concatenate([a[mask], b[mask]])
    masked_range = float(inside.max() - inside.min())
    _, full = metrics.structural_similarity(a.astype(np.float64), b.astype(np.float64), data_range=masked_range,
                                            full=True)
    expected = full[mask & interior(SHAPE, 3)].mean()  # 7-voxel window: 3 voxels from each face
    assert ssim(a, b, mask=mask) == pytest.approx(expected, rel=1e-12)


def test_ssim_window_that_does_not_fit_is_an_error():
    with pytest.raises(CompareError, match="does not fit"):
        ssim(np.ones((5, 16, 16)), np.ones((5, 16, 16)), data_range=1.0)
    with pytest.raises(CompareError, match="odd integer"):
        ssim(smooth_volume(), smooth_volume(), win_size=4)


# Histograms

def test_value_range_spans_both_volumes_inside_the_mask_only():
    a, b = np.array([0.1, 0.5, np.nan]), np.array([0.3, 0.7, 99.0])
    assert value_range(a, b, np.array([True, True, False])) == (0.1, 0.7)



def test_histogram_counts_every_masked_voxel_over_the_value_range():
    a = smooth_volume()
    mask = a > 0.45
    h = histogram(a, mask, bins=10)
    assert h.counts.sum() == mask.sum()
    assert (h.edges[0], h.edges[-1]) == (pytest.approx(a[mask].min()), pytest.approx(a[mask].max()))
    assert np.sum(h.density * h.bin_width) == pytest.approx(1.0)


def test_two_gaussian_peaks_are_found_within_one_bin():
    """A woven composite's two materials: 60 % matrix near 0.42 cm⁻¹, 40 % yarn near 0.50."""
    rng = np.random.default_rng(7)
    n = 40 * 50 * 50
    values = np.where(rng.random(n) < 0.6, rng.normal(0.42, 0.01, n), rng.normal(0.50, 0.01, n))
    h = histogram(values.reshape(40, 50, 50).astype(np.float32), bins=64)  # bins a quarter of σ wide
    peaks = histogram_peaks(h)
    assert len(peaks) == 2  # the sampling ripples of 100 000 voxels make no peak
    assert abs(peaks[0] - 0.42) < h.bin_width and abs(peaks[1] - 0.50) < h.bin_width  # higher first


def test_a_shoulder_is_not_a_peak():
    """Two Gaussians one σ apart merge into one hump with no dip: one peak, not two."""
    x = np.linspace(0, 1, 201)
    counts = np.round(1e4 * (np.exp(-0.5 * ((x - 0.45) / 0.05) ** 2) + 0.5 * np.exp(-0.5 * ((x - 0.50) / 0.05) ** 2)))
    h = Histogram(counts.astype(np.int64), np.linspace(-0.0025, 1.0025, 202))
    assert len(histogram_peaks(h)) == 1


# Masks

def test_a_mask_that_excludes_a_corrupted_region_restores_every_metric():
    a = smooth_volume()
    b = noisy(a)
    corrupted = b.copy()
    corrupted[4:8, 5:10, 6:12] = 5.0  # a streak far above the data
    # SSIM's windows reach 3 voxels past the region: the mask leaves those out too.
    mask = np.ones(SHAPE, bool)
    mask[1:11, 2:13, 3:15] = False
    clean, spoilt = compare(a, b, mask), compare(a, corrupted, mask)
    for field in ("cosine_similarity", "psnr_db", "data_range"):
        assert getattr(spoilt, field) == getattr(clean, field), field
    assert spoilt.ssim == pytest.approx(clean.ssim, rel=1e-12)  # the window filter's running sums round differently
    unmasked = compare(a, corrupted)
    assert all(getattr(unmasked, f) < getattr(clean, f) for f in ("cosine_similarity", "ssim", "psnr_db"))


def test_non_finite_voxels_are_an_error_unless_masked_out():
    a = smooth_volume()
    b = noisy(a)
    b[0, 0, :3] = np.nan
    with pytest.raises(CompareError, match=r"^b has 3 non-finite voxels.*mask"):
        compare(a, b)
    mask = np.ones(SHAPE, bool)
    mask[0, 0, :3] = False
    assert math.isfinite(compare(a, b, mask).psnr_db)


@pytest.mark.parametrize("mask, message", [
    (np.ones(SHAPE, np.uint8), "boolean mask"),
    (np.ones((2, 2, 2), bool), r"shape \(2, 2, 2\)"),
    (np.zeros(SHAPE, bool), "selects no voxel"),
])
def test_bad_masks_are_errors(mask, message):
    with pytest.raises(CompareError, match=message):
        compare(smooth_volume(), smooth_volume(1), mask)


def test_shapes_must_agree():
    with pytest.raises(CompareError, match=r"sim has shape \(12, 16, 20\) and real \(12, 16, 19\).*one voxel grid"):
        compare(smooth_volume(), smooth_volume()[..., :-1], names=("sim", "real"))


def test_label_mask_selects_classes_and_names_missing_ones():
    labels = np.array([[[0, 1, 2, 3]]], np.uint8)
    assert label_mask(labels).tolist() == [[[False, True, True, True]]]
    assert label_mask(labels, [2, 3]).tolist() == [[[False, False, True, True]]]
    with pytest.raises(CompareError, match=r"classes \[7\] are not in labels.tif, which holds \[0, 1, 2, 3\]"):
        label_mask(labels, [7], name="labels.tif")


# The optional libraries

def test_the_package_imports_without_the_compare_extra():
    code = ("import sys, xrayraster, xrayraster.cli; "
            "print([m for m in ('skimage', 'matplotlib') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2]).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("module, call", [
    ("skimage.metrics", lambda: ssim(smooth_volume(), smooth_volume())),
    ("matplotlib", lambda: write_histogram_png("never.png", {"a": histogram(smooth_volume())})),
])
def test_a_missing_library_names_the_extra(module, call, monkeypatch):
    monkeypatch.setitem(sys.modules, module, None)  # import raises ImportError, as when not installed
    with pytest.raises(CompareError, match=r'pip install "xrayraster\[compare\]"'):
        call()


# Outputs

def test_comparison_to_dict_is_json_and_png_is_written(tmp_path):
    from PIL import Image

    a = smooth_volume()
    result = compare(a, a, names=("sim", "real"))
    record = json.loads(json.dumps(result.to_dict(), allow_nan=False))  # identical: PSNR infinite, stored as null
    assert record["psnr_db"] is None and record["names"] == ["sim", "real"] and record["voxels"] == a.size
    assert sum(record["histogram"]["counts"]["real"]) == a.size
    path = write_histogram_png(tmp_path / "h.png", result)
    with Image.open(path) as image:
        assert image.format == "PNG" and image.size[0] > 100 and image.size[1] > 100


# The command line

@pytest.fixture
def tiffs(tmp_path):
    from xrayraster import LabelVolume, Volume, VolumeGeometry

    grid = VolumeGeometry(SHAPE, 0.1)
    a = smooth_volume()
    b = noisy(a)
    labels = np.where(a > 0.45, 2, 1).astype(np.uint8)
    paths = {"a": tmp_path / "sim.tif", "b": tmp_path / "real.tif", "labels": tmp_path / "labels.tif",
             "small": tmp_path / "small.tif"}
    Volume(a, grid).save(paths["a"], quicklook=False)
    Volume(b, grid).save(paths["b"], quicklook=False)
    LabelVolume(labels, grid).save(paths["labels"], quicklook=False)
    Volume(a[:, :, :-1], VolumeGeometry(a[:, :, :-1].shape, 0.1)).save(paths["small"], quicklook=False)
    return paths, a, b, labels


def test_cli_end_to_end(tiffs, tmp_path, capsys):
    from PIL import Image

    paths, a, b, labels = tiffs
    out = tmp_path / "out"
    assert cli.main(["compare", str(paths["a"]), str(paths["b"]), "--labels", str(paths["labels"]), "--class", "2",
                     "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    record = json.loads((out / "compare.json").read_text())
    mask = labels == 2
    a64, b64 = a[mask].astype(np.float64), b[mask].astype(np.float64)
    assert record["generator"] == "xrayraster compare" and record["unit"] == "1/cm"
    assert record["voxels"] == mask.sum() and record["names"] == [str(paths["a"]), str(paths["b"])]
    assert record["cosine_similarity"] == pytest.approx(a64 @ b64 / math.sqrt((a64 @ a64) * (b64 @ b64)), rel=1e-12)
    common = max(a64.max(), b64.max()) - min(a64.min(), b64.min())
    assert record["psnr_db"] == pytest.approx(psnr_formula(a64, b64, common), rel=1e-9)
    assert f"cosine similarity {record['cosine_similarity']:.6f}" in printed and "wrote" in printed
    with Image.open(out / "histograms.png") as image:
        assert image.format == "PNG" and image.size[0] > 100
    assert sorted(p.name for p in out.iterdir()) == ["compare.json", "histograms.png"]


@pytest.mark.parametrize("args, message", [
    (["{a}", "{small}"], r"\(12, 16, 20\) and .*small.tif \(12, 16, 19\)"),
    (["{a}", "{missing}"], r"volume B .*missing.tif: no such file"),
    (["{a}", "{b}", "--class", "2"], "give --labels too"),
    (["{a}", "{b}", "--labels", "{labels}", "--class", "9"], r"classes \[9\] are not in --labels"),
    (["{a}", "{b}", "--png", "{a}"], r"--png .*sim.tif: the file must end in .png"),
    (["{a}", "{b}", "--json", "{a}"], r"--json .*sim.tif: the file must end in .json"),
])
def test_cli_bad_input_exits_2_naming_the_argument(tiffs, tmp_path, capsys, args, message):
    paths, *_ = tiffs
    names = {**{k: str(v) for k, v in paths.items()}, "missing": str(tmp_path / "missing.tif")}
    assert cli.main(["compare", *(arg.format(**names) for arg in args)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("xrayraster: error: ") and len(err.strip().splitlines()) == 1
    assert re.search(message, err), err
