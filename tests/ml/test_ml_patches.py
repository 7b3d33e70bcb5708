"""Training patches from dataset builds (xrayraster/ml, docs/ml.md), the NumPy path, in every layout:
a patch is the crop of the volume and labels at its start (volumes whose voxels encode their own
index, so a crop is checked exactly), the same seed gives the same patches in any order and any
process, the classes are centred on as asked within sampling error, a patch reads only its crop
(peak memory far below a volume's), and a real `xr.build` reads back. Also predict_volume's
windows: a voxel-wise model gives the voxel-wise answer exactly, and an edge-sensitive one is
blended as MONAI's sliding_window_inference blends it (where torch and MONAI are installed)."""

from __future__ import annotations

import pickle
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core.errors import ConfigError
from xrayraster.dataset.layouts import LAYOUTS
from xrayraster.ml.patches import strided

from builds import LABELS, SHAPES, coded, layered, write_build
from inputs import tiny

pytest.importorskip("h5py")
pytest.importorskip("nibabel")

PATCH = (8, 10, 12)


@pytest.fixture(scope="module", params=sorted(LAYOUTS))
def build(request, tmp_path_factory) -> Path:
    return write_build(tmp_path_factory.mktemp("ml") / request.param, request.param)


def test_a_patch_is_the_crop_at_its_start(build):
    patches = xr.ml.PatchDataset(build, PATCH, split="train", patches_per_sample=6, normalize=xr.ml.Window(0.0, 1.0))
    assert len(patches) == 3 * 6 and patches.dataset.labels == {0: "background", **LABELS}
    for item in range(len(patches)):
        image, labels = patches[item]
        where = patches.patch(item)
        sample = [0, 1, 3][item // 6]
        assert where.sample == sample and image.shape == labels.shape == PATCH
        crop = tuple(slice(b, b + p) for b, p in zip(where.start, PATCH))
        np.testing.assert_array_equal(image, coded(SHAPES[sample], sample)[crop])
        np.testing.assert_array_equal(labels, layered(SHAPES[sample])[crop])


def test_the_same_seed_gives_the_same_patches_in_any_order_and_process(build):
    def make(seed=3, **options):
        return xr.ml.PatchDataset(build, PATCH, split=None, patches_per_sample=4, flips=True, seed=seed, **options)

    a, b = make(), make()
    forward = [a[i] for i in range(len(a))]
    backward = [b[i] for i in reversed(range(len(b)))][::-1]
    copied = pickle.loads(pickle.dumps(make()))  # as a DataLoader worker gets it
    for (ia, la), (ib, lb), i in zip(forward, backward, range(len(a))):
        np.testing.assert_array_equal(ia, ib)
        np.testing.assert_array_equal(la, lb)
        np.testing.assert_array_equal(copied[i][1], la)
    other = make(seed=4)
    assert any(other.patch(i).start != a.patch(i).start for i in range(len(a)))
    a.set_epoch(1)
    assert any(a.patch(i).start != b.patch(i).start for i in range(len(a)))
    flipped = [p for p in (b.patch(i) for i in range(len(b))) if any(p.flipped)]
    assert flipped  # flips=True flips; a flipped patch is the crop flipped, image and labels together
    p = flipped[0]
    crop = tuple(slice(s, s + n) for s, n in zip(p.start, PATCH))
    axes = tuple(k for k, f in enumerate(p.flipped) if f)
    np.testing.assert_array_equal(b[p.item][1], np.flip(layered(SHAPES[p.sample])[crop], axes))


def test_patches_are_centred_on_each_class_as_asked(build):
    shares = {1: 0.2, 2: 0.3, 3: 0.4}  # and 0.1 placed uniformly
    patches = xr.ml.PatchDataset(build, PATCH, split=None, patches_per_sample=600, class_shares=shares, seed=11)
    drawn = [patches.patch(i) for i in range(len(patches))]
    n = len(drawn)
    for label, share in [*shares.items(), (None, 0.1)]:
        count = sum(p.centred_on == label for p in drawn)
        assert abs(count - share * n) < 4 * np.sqrt(n * share * (1 - share)), (label, count, share * n)
    balanced = xr.ml.PatchDataset(build, PATCH, split=None, patches_per_sample=400, seed=2)
    counts = np.bincount([balanced.patch(i).centred_on for i in range(len(balanced))], minlength=4)
    n = len(balanced)
    assert np.all(np.abs(counts - n / 4) < 4 * np.sqrt(n * 0.25 * 0.75)), counts


def test_a_centre_is_a_voxel_of_its_class(build):
    patches = xr.ml.PatchDataset(build, (1, 1, 1), split=None, patches_per_sample=50, class_shares={2: 0.5, 3: 0.5})
    for i in range(len(patches)):
        p = patches.patch(i)
        assert patches[i][1][0, 0, 0] == p.centred_on  # a 1-voxel patch is its centre


def test_a_patch_reads_its_crop_not_the_file(tmp_path):
    """tracemalloc's peak while reading patches (after the strided index) stays far below a volume's
    bytes, in every layout: 96³ float32 volumes are 3.5 MB, a 16³ patch 16 KB."""
    shape = (96, 96, 96)
    for layout in sorted(LAYOUTS):
        root = write_build(tmp_path / layout, layout, [shape], ["train"])
        patches = xr.ml.PatchDataset(root, 16, patches_per_sample=8).prepare()
        truth = layered(shape)
        tracemalloc.start()
        got = [(patches.patch(i).start, patches[i][1]) for i in range(len(patches))]
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        for start, labels in got:
            np.testing.assert_array_equal(labels, truth[tuple(slice(s, s + 16) for s in start)])
        print(layout, peak)
        assert peak < 0.25 * 96**3 * 4, (layout, peak)


def test_percentiles_and_windows_normalise_as_documented(build):
    window = xr.ml.PatchDataset(build, PATCH, normalize=xr.ml.Window(-100.0, 300_000.0), patches_per_sample=2)
    image, _ = window[0]
    start = window.patch(0).start
    crop = coded(SHAPES[0], 0)[tuple(slice(b, b + p) for b, p in zip(start, PATCH))]
    np.testing.assert_allclose(image, (crop + 100.0) / 300_100.0, rtol=1e-6)
    by_volume = xr.ml.PatchDataset(build, PATCH, normalize=xr.ml.Percentiles(10, 90), patches_per_sample=2)
    low, high = np.percentile(strided(coded(SHAPES[0], 0), 4), [10, 90])
    assert by_volume.sample_index(0).bounds == pytest.approx((low, high))


def test_a_bright_inclusion_neither_rescales_the_volume_nor_leaves_the_range():
    """1 % of the voxels three times brighter (a glass tracer in carbon): the default Percentiles'
    bounds move by under 2 %, where the 99.5th percentile's triple, and the mapped values stay
    within the clip."""
    rng = np.random.default_rng(0)
    volume = np.where(rng.random((48, 48, 48)) < 0.3, 0.0, rng.normal(0.5, 0.02, (48, 48, 48))).astype(np.float32)
    bright = volume.copy()
    bright[rng.random(volume.shape) < 0.01] = 1.6
    for name, normalize, moves in (("default", xr.ml.Percentiles(), False), ("99.5", xr.ml.Percentiles(0.5, 99.5), True)):
        before, after = (normalize.bounds(strided(v, 4)) for v in (volume, bright))
        assert (after[1] > 2 * before[1]) == moves and (abs(after[1] / before[1] - 1) < 0.02) != moves, name
    scaled = xr.ml.Percentiles().scaled(bright, xr.ml.Percentiles().bounds(strided(bright, 4)))
    assert scaled.dtype == np.float32 and scaled.min() >= -0.25 and scaled.max() == np.float32(1.25)
    assert xr.ml.Window(0.0, 1.0, clip=(0.0, 0.5)).scaled(bright, (0.0, 1.0)).max() == np.float32(0.5)
    with pytest.raises(ConfigError, match=r"Percentiles: clip must be None or \(low, high\) with low < high"):
        xr.ml.Percentiles(clip=(1.0, 0.0))


def test_the_material_scale_is_the_bulk_and_a_minority_barely_moves_it():
    """Air and a material of known median: MaterialScale maps 0 cm⁻¹ to 0 and that median to 1.
    1 % of glass-bright voxels, or a slab of plastic a little darker than the material filling 10 %
    of the grid, moves it by under 1.5 %; the bright voxels move the default Percentiles' 98th by more."""
    rng = np.random.default_rng(1)
    air = rng.random((48, 48, 48)) < 0.4
    volume = np.where(air, rng.normal(0.0, 0.01, air.shape), rng.normal(0.5, 0.03, air.shape)).astype(np.float32)
    scale = xr.ml.MaterialScale()
    low, high = scale.bounds(strided(volume, 4))
    assert low == 0.0 and high == pytest.approx(np.median(strided(volume, 4)[~strided(air, 4)]), rel=1e-9)
    bright, holder = volume.copy(), volume.copy()
    bright[rng.random(air.shape) < 0.01] = 1.6
    holder[:5] = rng.normal(0.45, 0.03, holder[:5].shape)
    def moved(normalize, changed):
        return normalize.bounds(strided(changed, 4))[1] / normalize.bounds(strided(volume, 4))[1] - 1

    assert abs(moved(scale, holder)) < 0.015
    assert abs(moved(scale, bright)) < 0.015 < abs(moved(xr.ml.Percentiles(), bright))
    assert xr.ml.MaterialScale().scaled(bright, scale.bounds(strided(bright, 4))).max() == np.float32(1.5)
    assert xr.ml.MaterialScale().bounds(np.zeros(64, np.float32)) == (0.0, 1e-6)
    with pytest.raises(ConfigError, match=r"MaterialScale: quantile must be in \(0, 1\)"):
        xr.ml.MaterialScale(quantile=1.0)


@pytest.mark.parametrize("air_share, glass_share", [(0.1, 0.0), (0.1, 0.06), (0.4, 0.03), (0.4, 0.06), (0.8, 0.01)])
def test_a_bright_minority_does_not_take_the_material_scale_over(air_share, glass_share):
    """Air, a composite at 0.45 cm⁻¹ and glass at 1.9 cm⁻¹ (up to a tenth of the material): the
    scale is the composite's median within 2 % (a median moves by the glass's share, not by its
    values). With 40 % air and 3 % glass, Otsu's two-class threshold splits the glass from the rest,
    so a scale taken above it would be the glass's 1.9."""
    rng = np.random.default_rng(2)
    draw = rng.random(200_000)
    composite = rng.normal(0.45, 0.04, draw.shape)
    sampled = np.where(draw < air_share, rng.normal(0.0, 0.05, draw.shape),
                       np.where(draw < 1.0 - glass_share, composite, rng.normal(1.9, 0.1, draw.shape)))
    middle = (draw >= air_share) & (draw < 1.0 - glass_share)
    assert xr.ml.MaterialScale().bounds(sampled)[1] == pytest.approx(np.median(sampled[middle]), rel=0.02)


@pytest.mark.parametrize("options, message", [
    ({"split": "holdout"}, r"split must be one of train, val, test or None"),
    ({"class_shares": {7: 0.5}}, r"class_shares: label\(s\) \[7\] are not in the build"),
    ({"class_shares": {1: 0.7, 2: 0.6}}, r"summing to at most 1"),
    ({"patch_size": (8, 8)}, r"patch_size must be a positive integer or \(z, y, x\)"),
    ({"patches_per_sample": 0}, r"patches_per_sample must be a positive integer"),
    ({"normalize": "z-score"}, r"normalize must be a Window, Percentiles or MaterialScale"),
])
def test_bad_options_are_named(build, options, message):
    with pytest.raises(ConfigError, match=message):
        xr.ml.PatchDataset(build, **{"patch_size": PATCH, **options})


def test_not_a_build_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"not a dataset build \(no build.json\)"):
        xr.ml.PatchDataset(tmp_path)


def test_a_real_build_reads_back(gl, cl, tmp_path):
    """Two tiny samples of `xr.build` (tests/dataset/test_dataset_build.py's), read by tifffile: the patches
    are their crops."""
    import tifffile

    xr.build(tiny(tmp_path, count=2), tmp_path / "out")
    patches = xr.ml.PatchDataset(tmp_path / "out", (8, 16, 16), split=None, patches_per_sample=3,
                                 normalize=xr.ml.Window(0.0, 1.0))
    for i in range(len(patches)):
        p = patches.patch(i)
        folder = tmp_path / "out" / "samples" / f"{p.sample:05d}"
        crop = tuple(slice(b, b + n) for b, n in zip(p.start, (8, 16, 16)))
        image, labels = patches[i]
        np.testing.assert_array_equal(labels, tifffile.imread(folder / "labels.tif")[crop])
        np.testing.assert_array_equal(image, tifffile.imread(folder / "volume.tif")[crop])


# -- predict_volume ------------------------------------------------------------------------------------

def test_a_voxelwise_model_is_stitched_to_the_voxelwise_answer():
    """Scores that depend on each voxel's value only: every window agrees, so the blend is exact,
    and any voxel a window missed or misplaced would show."""
    volume = np.random.default_rng(0).normal(0.5, 0.3, (23, 41, 37)).astype(np.float32)
    window = xr.ml.Window(0.0, 1.0)

    def model(batch):
        v = batch[:, 0]
        return np.stack([-(v - 0.2) ** 2, -(v - 0.5) ** 2, -(v - 0.8) ** 2], axis=1)

    expected = np.argmin(np.abs(volume[None] - np.array([0.2, 0.5, 0.8])[:, None, None, None]), axis=0)
    for blend in ("gaussian", "uniform"):
        got = xr.ml.predict_volume(model, volume, (16, 16, 16), normalize=window, blend=blend, batch_size=3)
        np.testing.assert_array_equal(got, expected)
    small = xr.ml.predict_volume(model, volume[:5, :6, :7], 16, normalize=window)  # padded, cut back
    np.testing.assert_array_equal(small, expected[:5, :6, :7])


def test_windows_blend_as_monais_sliding_window_inference(torch):
    """A model whose scores depend on where a voxel lies in its patch (a zero-padded box filter):
    our uniform blend equals MONAI's "constant" mode (the same windows, the same average)."""
    from monai import inferers as monai_inferers
    volume = np.random.default_rng(1).random((21, 30, 26)).astype(np.float32)
    weights = torch.ones(2, 1, 3, 3, 3) * torch.tensor([1.0, -0.5]).view(2, 1, 1, 1, 1)

    def model(batch):
        return torch.nn.functional.conv3d(torch.as_tensor(batch), weights, padding=1)

    expected = monai_inferers.sliding_window_inference(torch.from_numpy(volume)[None, None], (12, 16, 10), 1, model,
                                                       overlap=0.4, mode="constant")[0].numpy()
    got = xr.ml.predict_volume(lambda b: model(b).numpy(), volume, (12, 16, 10), overlap=0.4, blend="uniform",
                               normalize=xr.ml.Window(0.0, 1.0), scores=True)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)


# -- largest_component ---------------------------------------------------------------------------------

def test_the_largest_body_is_kept_and_the_rest_cleared():
    """A specimen of three labels, a holder slab below a gap of air, and a voxel touching the
    specimen at a corner only: the holder goes; the corner voxel stays with 26 neighbours and goes
    with 6 (faces only)."""
    labels = np.zeros((20, 12, 12), np.uint8)
    labels[8:18, 2:10, 2:10] = 1           # matrix
    labels[10:12, 2:10, 2:10] = 2          # a weft layer
    labels[13:15, 4:6, 2:10] = 3           # a warp inside
    labels[0:4] = 1                        # the holder: plastic that looks like matrix
    labels[7, 1, 1] = 3                    # meets the specimen at (8, 2, 2) by a corner
    specimen = labels.copy()
    specimen[0:4] = 0
    np.testing.assert_array_equal(xr.ml.largest_component(labels), specimen)
    faces_only = specimen.copy()
    faces_only[7, 1, 1] = 0
    np.testing.assert_array_equal(xr.ml.largest_component(labels, connectivity=1), faces_only)
    one_body = specimen.copy()
    np.testing.assert_array_equal(xr.ml.largest_component(one_body), specimen)
    assert not xr.ml.largest_component(np.zeros((3, 3, 3), np.uint8)).any()
    with pytest.raises(ConfigError, match="connectivity must be 1 to 3"):
        xr.ml.largest_component(labels, connectivity=4)
