"""The PyTorch view of a :class:`~.patches.PatchDataset` (torch is imported here only, on first use)."""

from __future__ import annotations

from ..io.optional import optional_module

torch = optional_module("torch", "ml", "PatchDataset.torch()")


class TorchPatches(torch.utils.data.Dataset):
    """``patches[i]`` as tensors: the image (1, z, y, x) float32 (one channel), and the target: class
    labels or instance ids (z, y, x) as int64 (the indices a cross-entropy loss takes), directions
    (3, z, y, x) float32 as they are. Patches are drawn as the NumPy dataset's (the same seed, epoch
    and item give the same tensors in any ``DataLoader`` worker); :meth:`set_epoch` draws new ones."""

    def __init__(self, patches):
        self.patches = patches

    def __len__(self) -> int:
        return len(self.patches)

    def __getitem__(self, item: int):
        image, target = self.patches[item]
        integer = target.dtype.kind != "f"  # class labels and instance ids: the indices a loss takes
        return torch.from_numpy(image[None]), torch.from_numpy(target.astype("int64") if integer else target)

    def set_epoch(self, epoch: int) -> None:
        self.patches.set_epoch(epoch)
