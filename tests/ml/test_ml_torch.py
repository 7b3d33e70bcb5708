"""xrayraster.ml's torch path (the ml extra): PatchDataset.torch() under a DataLoader gives the NumPy
path's patches as tensors, the same batches with worker processes as without, and a MONAI U-Net
trains on them (a smoke test of a few iterations: the loss falls) and segments a whole volume
through predict_volume."""

from __future__ import annotations

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.dataset.layouts import LAYOUTS
from xrayraster.pipeline.scan import ScanResult

from builds import write_build

pytest.importorskip("h5py")

SHAPES = [(24, 28, 32), (28, 24, 28), (26, 30, 24)]
MU = np.array([0.0, 0.4, 0.7, 1.0], np.float32)  # cm⁻¹ of air, matrix, weft, warp


def layered(shape) -> np.ndarray:
    """Air above and below, then slabs of matrix, weft and warp 4 voxels thick, crossed every 6 in x."""
    z, y, x = np.indices(shape)
    return np.where((z > 2) & (z < shape[0] - 3), 1 + (z // 4 + x // 6) % 3, 0).astype(np.uint8)


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    return write_build(tmp_path_factory.mktemp("ml_torch") / "hdf5", "hdf5", SHAPES, ["train", "train", "test"])


def test_the_torch_dataset_is_the_numpy_one_in_any_worker(torch, build):
    patches = xr.ml.PatchDataset(build, 8, patches_per_sample=6, flips=True, seed=5)
    data = patches.torch()
    image, labels = data[3]
    assert image.dtype == torch.float32 and labels.dtype == torch.int64
    assert tuple(image.shape) == (1, 8, 8, 8) and tuple(labels.shape) == (8, 8, 8)
    np.testing.assert_array_equal(image[0].numpy(), patches[3][0])
    np.testing.assert_array_equal(labels.numpy(), patches[3][1])

    def batches(workers):
        loader = torch.utils.data.DataLoader(data, batch_size=4, num_workers=workers)
        return [(i.numpy(), lab.numpy()) for i, lab in loader]

    serial, parallel = batches(0), batches(2)
    assert len(serial) == len(parallel) == 3
    for (a, la), (b, lb) in zip(serial, parallel):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(la, lb)


def test_the_extra_targets_are_tensors_a_loss_takes(torch, tmp_path):
    """Instance ids as int64 (z, y, x), directions as float32 (3, z, y, x), the NumPy patches' values."""
    root = write_build(tmp_path / "hdf5", "hdf5", SHAPES, ["train", "train", "test"],
                       extra_labels=("instances", "directions"))
    for target, dtype, shape in (("instances", torch.int64, (8, 8, 8)), ("directions", torch.float32, (3, 8, 8, 8))):
        patches = xr.ml.PatchDataset(root, 8, patches_per_sample=2, flips=True, target=target)
        image, tensor = patches.torch()[1]
        assert tensor.dtype == dtype and tuple(tensor.shape) == shape and tuple(image.shape) == (1, 8, 8, 8)
        np.testing.assert_array_equal(tensor.numpy(), patches[1][1])


def test_a_unet_trains_on_patches_and_segments_a_volume(torch, tmp_path):
    """Volumes whose classes differ in attenuation (plus noise): a small MONAI U-Net's loss falls
    over 40 iterations, and predict_volume returns a label volume of the input's shape."""
    from monai.networks.nets import UNet

    rng = np.random.default_rng(0)
    root = tmp_path / "build"
    root.mkdir()
    (root / "build.json").write_text('{"identity": {"layout": "tiff", "name": "Twin"}}')
    for index, shape in enumerate(SHAPES):
        labels = layered(shape)
        grid = xr.VolumeGeometry(shape, 0.1)
        volume = (MU[labels] + rng.normal(0, 0.05, shape)).astype(np.float32)
        LAYOUTS["tiff"].write_sample(root, index, ScanResult(xr.Volume(volume, grid), xr.LabelVolume(labels, grid), {}),
                                     {"split": "train", "seed": index, "labels": {"1": "matrix", "2": "weft",
                                                                                  "3": "warp"}}, name="Twin")
    patches = xr.ml.PatchDataset(root, 16, patches_per_sample=40, normalize=xr.ml.Window(0.0, 1.0))
    loader = torch.utils.data.DataLoader(patches.torch(), batch_size=4, shuffle=True,
                                         generator=torch.Generator().manual_seed(0))
    model = UNet(spatial_dims=3, in_channels=1, out_channels=4, channels=(8, 16), strides=(2,), num_res_units=0)
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for image, labels in loader:
        optimiser.zero_grad()
        loss = torch.nn.functional.cross_entropy(model(image), labels)
        loss.backward()
        optimiser.step()
        losses.append(loss.item())
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:5]), losses
    volume = (MU[layered(SHAPES[0])] + rng.normal(0, 0.05, SHAPES[0])).astype(np.float32)
    predicted = xr.ml.predict_volume(model, volume, 16, normalize=xr.ml.Window(0.0, 1.0))
    assert predicted.shape == SHAPES[0] and predicted.dtype == np.uint8
    truth = layered(SHAPES[0])
    dice = [2 * np.sum((predicted == c) & (truth == c)) / (np.sum(predicted == c) + np.sum(truth == c)) for c in (1, 2, 3)]
    print(losses[:3], losses[-3:], dice)
    assert np.mean(dice) > 0.8, dice


def test_the_largest_body_is_monais(torch):
    """largest_component against MONAI's KeepLargestConnectedComponent (every label one foreground)
    on random blobs of three labels, with 26 and with 6 neighbours."""
    from monai.transforms import KeepLargestConnectedComponent
    from scipy import ndimage

    rng = np.random.default_rng(3)
    field = ndimage.gaussian_filter(rng.normal(size=(30, 34, 26)), 1.5)
    labels = np.digitize(field, np.quantile(field, [0.6, 0.75, 0.9])).astype(np.uint8)
    assert ndimage.label(labels > 0)[1] > 3  # several bodies to choose from
    for connectivity in (1, 3):
        expected = KeepLargestConnectedComponent(applied_labels=[1, 2, 3], independent=False,
                                                 connectivity=connectivity)(torch.from_numpy(labels)[None])[0]
        np.testing.assert_array_equal(xr.ml.largest_component(labels, connectivity=connectivity), expected.numpy())
