"""PatchDataset's targets (docs/ml.md), in every layout: with ``target="instances"`` a patch's target
is the crop of the stored instance volume at the patch's start (read back by the format's own
library), with ``"directions"`` the (3, z, y, x) crop of the stored directions, flipped with the image
and each flipped axis's component negated, unit on the yarns and 0 elsewhere; patches are placed
by the class labels whatever the target; a build without the target is refused naming it and
the fix."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core.errors import ConfigError
from xrayraster.dataset.layouts import LAYOUTS

from builds import NAME, SHAPES, SPLITS, instance_ids, layered, scan_result, unit_directions, write_build

h5py = pytest.importorskip("h5py")
nib = pytest.importorskip("nibabel")

PATCH = (8, 10, 12)
EXTRAS = ("instances", "directions")


@pytest.fixture(scope="module", params=sorted(LAYOUTS))
def build(request, tmp_path_factory) -> tuple[Path, str]:
    layout = request.param
    return write_build(tmp_path_factory.mktemp("targets") / layout, layout, extra_labels=EXTRAS), layout


def stored(root: Path, layout: str, index: int, label: str) -> np.ndarray:
    """Sample ``index``'s ``label`` array as its layout's documented file holds it, read by its own library."""
    if layout == "tiff":
        import tifffile

        return tifffile.imread(root / "samples" / f"{index:05d}" / f"{label}.tif")
    if layout == "nnunet":
        part = "Ts" if SPLITS[index] == "test" else "Tr"
        return np.asanyarray(nib.load(root / f"{label}{part}" / f"{NAME}_{index:05d}.nii.gz").dataobj).T
    with h5py.File(root / "samples" / f"{index:05d}.h5", "r") as f:
        return f[label][()]


def crop(array: np.ndarray, start, size=PATCH) -> np.ndarray:
    return array[(..., *(slice(s, s + n) for s, n in zip(start, size)))]


def test_an_instance_patch_is_the_crop_of_the_stored_instances(build):
    root, layout = build
    patches = xr.ml.PatchDataset(root, PATCH, split=None, patches_per_sample=5, target="instances", seed=3)
    for item in range(len(patches)):
        where = patches.patch(item)
        ids = stored(root, layout, where.sample, "instances")
        assert ids.dtype == np.uint16 and np.array_equal(ids, instance_ids(SHAPES[where.sample]))
        target = patches[item][1]
        assert target.dtype == np.uint16 and target.shape == PATCH
        np.testing.assert_array_equal(target, crop(ids, where.start))


def test_a_direction_patch_is_the_stored_crop_flipped_and_unit_on_the_yarns(build):
    root, layout = build
    patches = xr.ml.PatchDataset(root, PATCH, split=None, patches_per_sample=8, flips=True, target="directions", seed=5)
    flipped = 0
    for item in range(len(patches)):
        where = patches.patch(item)
        axes = tuple(a for a, f in enumerate(where.flipped) if f)
        expected = np.flip(crop(stored(root, layout, where.sample, "directions"), where.start),
                           tuple(a + 1 for a in axes)).astype(np.float32)
        for axis in axes:  # the x, y, z components: flipping z (axis 0) reverses the z component
            expected[2 - axis] *= -1
        target = patches[item][1]
        assert target.dtype == np.float32 and target.shape == (3, *PATCH)
        np.testing.assert_array_equal(target, expected)
        yarn = np.flip(crop(layered(SHAPES[where.sample]), where.start), axes) >= 2
        assert np.allclose(np.linalg.norm(target, axis=0)[yarn], 1.0, atol=2e-3) and not target[:, ~yarn].any()
        flipped += bool(axes)
    assert flipped, "no patch was flipped: the signs were not tested"
    assert np.array_equal(stored(root, layout, 0, "directions").astype(np.float32),
                          unit_directions(SHAPES[0]).astype(np.float32))


def test_patches_are_placed_by_the_classes_whatever_the_target(build):
    """The same seed places the same patches for every target, and class_shares centres them on the
    class labels' voxels (a 1-voxel patch is its centre)."""
    root, _ = build
    options = {"split": None, "patches_per_sample": 20, "class_shares": {3: 1.0}, "seed": 7}
    by_target = {t: xr.ml.PatchDataset(root, (1, 1, 1), target=t, **options) for t in ("classes", "instances")}
    for item in range(len(by_target["classes"])):
        classes, instances = (by_target[t].patch(item) for t in ("classes", "instances"))
        assert classes == instances and classes.centred_on == 3
        assert by_target["classes"][item][1][0, 0, 0] == 3 and by_target["instances"][item][1][0, 0, 0] > 0


def test_a_build_without_the_target_is_refused_naming_it_and_the_fix(tmp_path):
    root = write_build(tmp_path / "plain", "tiff")
    with pytest.raises(ConfigError, match=r"^target 'directions': this build's samples have no directions; add "
                                          r'"directions" to \[scan\] labels in the dataset file and build again$'):
        xr.ml.PatchDataset(root, PATCH, target="directions")
    with pytest.raises(ConfigError, match=r"^target must be one of 'classes', 'instances', 'directions', "
                                          r"got 'centrelines'"):
        xr.ml.PatchDataset(root, PATCH, target="centrelines")
    # One sample of the split without them is refused too, naming it; a split whose samples have them is served.
    mixed = write_build(tmp_path / "mixed", "tiff", extra_labels=EXTRAS)
    LAYOUTS["tiff"].write_sample(mixed, 1, scan_result(xr.VolumeGeometry(SHAPES[1], 0.1), 1),
                                 {"split": "train", "seed": 1, "values": {}}, name=NAME)
    with pytest.raises(ConfigError, match=r"^target 'instances': 1 of the 3 samples of split 'train' "
                                          r"\(sample 1 first\) have no instances; add"):
        xr.ml.PatchDataset(mixed, PATCH, target="instances")
    assert len(xr.ml.PatchDataset(mixed, PATCH, split="val", target="instances", patches_per_sample=2)) == 2
