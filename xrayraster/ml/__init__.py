"""Training data for segmentation networks from dataset builds (docs/ml.md): :class:`PatchDataset`
(aligned image and label patches, in NumPy, or PyTorch with ``.torch()``) and :func:`predict_volume`
(a whole volume segmented by a patch model), :func:`largest_component` (the specimen kept, other
bodies cleared). PyTorch is the ``ml`` extra:
``pip install "xrayraster[ml]"``; nothing here imports it until asked."""

from ..core.lazy import lazy_names

_HOMES = {
    ".patches": ("MaterialScale", "Patch", "PatchDataset", "Percentiles", "Window"),
    ".predict": ("predict_volume",),
    ".postprocess": ("largest_component",),
}
__getattr__, __dir__ = lazy_names(globals(), _HOMES)
__all__ = sorted(name for names in _HOMES.values() for name in names)
