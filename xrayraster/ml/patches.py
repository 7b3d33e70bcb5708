"""Training patches from a dataset build: :class:`PatchDataset`, aligned (image, label) crops.

What a patch is, and the choices made:

* **Where.** Item ``i`` belongs to sample ``i // patches_per_sample`` of the split (samples in index
  order). Its position is drawn by ``numpy.random.default_rng((seed, epoch, i))``: the same seed,
  epoch and item give the same patch in any process, so a PyTorch ``DataLoader`` gives the same
  batches with any ``num_workers``, and :meth:`PatchDataset.set_epoch` draws new ones.
* **Class balance.** ``class_shares`` ({label: share}, shares summing to at most 1) is the share of
  patches centred on a voxel of each label; the rest are placed uniformly. ``"balanced"`` (the
  default) gives every label of the build (background included) the same share: a woven sample
  is mostly air at the edges of a scan's grid, and its warp is a few percent of the voxels. The
  centre is a voxel of that label: a block of ``index_block``³ voxels holding the label is drawn
  (uniformly among such blocks), then one of the label's voxels in it. The blocks that hold each
  label come from a first read of the sample's labels, slab by slab (a label one voxel thin is
  found; one byte a block and label is kept). The patch is then moved inside the volume where the
  centre lies near an edge. A sample without that label gets a uniform patch.
* **Intensity.** ``Percentiles(low, high, clip)`` (the default: 0.5, 98 and (−0.25, 1.25)) maps
  each volume's own percentiles, taken on every ``index_block``-th voxel along each axis, to 0 and
  1 and clips the result: it follows a change of kV or filter and needs no labels (so
  :func:`~xrayraster.ml.predict.predict_volume` normalises an unlabelled scan the same way), and a
  bright inclusion the training never showed (a glass tracer, a metal part: up to 2 % of the
  voxels) neither rescales the volume nor reaches the network with values it never saw. Measured
  (docs/ml.md): a glass tracer of 0.7-1 % of the voxels moved the 99.5th percentile from 0.54 to
  1.65 cm⁻¹. ``Window(low_cm, high_cm, clip)`` maps a fixed window of attenuation (cm⁻¹) instead.
  ``MaterialScale(quantile, clip)`` maps 0 cm⁻¹ to 0 and the median (by default) of the volume's
  material (the voxels above a threshold halfway to that median) to 1: a bulk statistic, which a
  minority of bright or plastic voxels barely moves, where a percentile of the whole volume sits in
  the tail that such voxels fill (and moves with the share of air in the grid). Measured
  (docs/ml.md): over the shifted scans, the class medians differ from the training scans' by 0.025
  of the scale with it, by 0.054 with ``Percentiles()``, whose 98th percentile a tracer and a
  holder move.
* **Target.** ``target`` is what is cropped beside the image: ``"classes"`` (the class labels,
  uint8), or an extra label the build's scans made (``[scan] labels`` in its dataset file):
  ``"instances"`` (one id per yarn, uint16) or ``"directions"`` ((3, z, y, x) float32, the x, y, z
  components of each yarn voxel's unit direction, 0 elsewhere). Class balance keeps placing
  patches by the class labels whatever the target (a yarn's id says nothing of its class's share).
* **Flips.** ``flips=True`` flips each axis with probability ½, the image and its target together;
  a direction's component along a flipped axis changes sign with it, so it still points along its
  yarn. No 90° turns: they would turn weft into the direction of warp, a cue the classes are told by.
* **Reading.** A patch reads only its crop (:mod:`.built_dataset`); a volume smaller than the patch
  is padded with 0 (air) and a target of 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.choices import PATCH_TARGETS, check_choice
from ..core.errors import ConfigError
from .built_dataset import BuiltDataset

#: The type of each target's patches (the directions are float16 on disk, float32 to a network).
TARGET_TYPES = {"classes": np.uint8, "instances": np.uint16, "directions": np.float32}


class _Intensity:
    """What the normalisations share: the mapping through a volume's bounds (low → 0, high → 1)."""

    clip: tuple | None

    def scaled(self, data: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
        """``data`` (cm⁻¹) mapped through ``bounds`` to 0 and 1, then clipped: float32."""
        low, high = (np.float32(b) for b in bounds)
        out = (np.asarray(data, np.float32) - low) / (high - low)
        return out if self.clip is None else np.clip(out, np.float32(self.clip[0]), np.float32(self.clip[1]), out=out)

    def _check_clip(self) -> None:
        c = self.clip
        if c is not None and not (len(c) == 2 and all(math.isfinite(x) for x in c) and c[0] < c[1]):
            raise ConfigError(f"{type(self).__name__}: clip must be None or (low, high) with low < high, got {c!r}")


@dataclass(frozen=True)
class Window(_Intensity):
    """A fixed window of linear attenuation, ``low_cm`` → 0 and ``high_cm`` → 1 (cm⁻¹); ``clip``:
    (low, high) that the mapped values saturate at, or None."""

    low_cm: float
    high_cm: float
    clip: tuple | None = None

    def __post_init__(self):
        if not (math.isfinite(self.low_cm) and math.isfinite(self.high_cm) and self.low_cm < self.high_cm):
            raise ConfigError(f"Window: need finite low_cm < high_cm, got {self.low_cm!r}, {self.high_cm!r}")
        self._check_clip()

    def bounds(self, sampled: np.ndarray) -> tuple[float, float]:
        return self.low_cm, self.high_cm


@dataclass(frozen=True)
class Percentiles(_Intensity):
    """Each volume's own ``low`` and ``high`` percentiles (0-100) → 0 and 1, the result clipped to
    ``clip`` (or None). The defaults (module docstring) let a bright inclusion of up to 2 % of the
    voxels neither rescale the volume nor reach the network with values it never saw."""

    low: float = 0.5
    high: float = 98.0
    clip: tuple | None = (-0.25, 1.25)

    def __post_init__(self):
        if not 0.0 <= self.low < self.high <= 100.0:
            raise ConfigError(f"Percentiles: need 0 <= low < high <= 100, got {self.low!r}, {self.high!r}")
        self._check_clip()

    def bounds(self, sampled: np.ndarray) -> tuple[float, float]:
        low, high = np.percentile(sampled, [self.low, self.high])
        return float(low), float(max(high, low + 1e-6))  # a constant volume: no division by 0


@dataclass(frozen=True)
class MaterialScale(_Intensity):
    """0 cm⁻¹ (air) → 0 and the ``quantile`` (0-1) of the volume's material → 1, the result clipped
    to ``clip`` (or None). For volumes of absolute attenuation, as a reconstruction of xrayraster's
    is (module docstring: why a bulk statistic, not a tail).

    The material is every voxel above the threshold halfway between air (0 cm⁻¹) and the median of
    the voxels above it: Ridler and Calvard's iterative selection with the air's level known,
    iterated from 0 up to its first fixed point. Not Otsu's threshold, which a bright minority
    takes over: a glass tracer of a few percent of the voxels can win Otsu's split against the air,
    and the scale then lands on the glass (measured on a shifted scan, docs/ml.md: 1.94 cm⁻¹
    against the composite's 0.47). A median does not see that minority's values."""

    quantile: float = 0.5
    clip: tuple | None = (-0.25, 1.5)

    def __post_init__(self):
        if not 0.0 < self.quantile < 1.0:
            raise ConfigError(f"MaterialScale: quantile must be in (0, 1), got {self.quantile!r}")
        self._check_clip()

    def bounds(self, sampled: np.ndarray) -> tuple[float, float]:
        sampled = np.asarray(sampled, np.float64).ravel()
        threshold = 0.0
        while np.any(above := sampled > threshold):
            # the map t → median(above t) / 2 never decreases, so from 0 this climbs to its first fixed point
            halfway = float(np.median(sampled[above])) / 2
            if halfway <= threshold:
                break
            threshold = halfway
        material = sampled[above]
        high = np.quantile(material, self.quantile) if material.size else 0.0
        return 0.0, float(max(high, 1e-6))  # an empty or all-negative volume: no division by 0


@dataclass(frozen=True)
class Patch:
    """Where item ``item`` lies: sample ``sample``, crop start (z, y, x) voxels, the label its
    centre was drawn on (None: placed uniformly) and the axes flipped."""

    item: int
    sample: int
    start: tuple
    centred_on: int | None
    flipped: tuple


@dataclass
class _SampleIndex:
    blocks: dict  # label → (n, 3) int32 (z, y, x) indices of the blocks that hold it
    bounds: tuple  # the intensity mapped to 0 and 1, cm⁻¹


class PatchDataset:
    """Aligned (image, target) patches of ``patch_size`` voxels (an int, or (z, y, x)) from the
    ``split`` (``train``, ``val``, ``test``, or None for all) of the build in ``root``, in any layout;
    the module docstring says how they are placed, normalised and flipped, and what ``target`` may
    be. ``dataset[i]`` is (image float32 (z, y, x), target): the class labels uint8 (z, y, x) by
    default, the instances uint16 (z, y, x) or the directions float32 (3, z, y, x);
    :meth:`torch` gives a ``torch.utils.data.Dataset``."""

    def __init__(self, root, patch_size=64, *, split: str | None = "train", patches_per_sample: int = 16,
                 class_shares="balanced", normalize=None, flips: bool = False, seed: int = 0,
                 index_block: int = 4, target: str = "classes"):
        self.dataset = BuiltDataset.open(root)
        self.samples = self.dataset.indices(split)
        self.split = split
        self.target = _target(target, self.dataset, self.samples, split)
        self.patch_size = patch_shape(patch_size)
        self.patches_per_sample = _positive("patches_per_sample", patches_per_sample)
        self.index_block = _positive("index_block", index_block)
        self.class_shares = _shares(class_shares, self.dataset.labels)
        self.normalize = Percentiles() if normalize is None else normalize
        if not isinstance(self.normalize, _Intensity):
            raise ConfigError(f"normalize must be a Window, Percentiles or MaterialScale, got {normalize!r}")
        self.flips = bool(flips)
        self.seed = _whole("seed", seed)
        self.epoch = 0
        self._index: dict[int, _SampleIndex] = {}

    def __len__(self) -> int:
        return len(self.samples) * self.patches_per_sample

    def __getitem__(self, item: int) -> tuple[np.ndarray, np.ndarray]:
        patch = self.patch(item)
        volume, labels = self.dataset.arrays(patch.sample)
        image = self.normalize.scaled(_crop(volume, patch.start, self.patch_size, np.float32),
                                      self.sample_index(patch.sample).bounds)
        source = labels if self.target == "classes" else self.dataset.extra_label(patch.sample, self.target)
        target = _crop(source, patch.start, self.patch_size, TARGET_TYPES[self.target])
        axes = tuple(a for a, f in enumerate(patch.flipped) if f)
        if axes:
            image, target = np.flip(image, axes).copy(), _flipped(target, axes)
        return image, target

    def set_epoch(self, epoch: int) -> None:
        """Draw the patches of ``epoch`` (module docstring)."""
        self.epoch = _whole("epoch", epoch)

    def patch(self, item: int) -> Patch:
        """Where item ``item`` lies (indexes the sample's labels on first use, then reads one block)."""
        if not -len(self) <= item < len(self):
            raise IndexError(f"item {item} is out of range: the dataset has {len(self)} patches")
        item %= len(self)
        sample = self.samples[item // self.patches_per_sample]
        rng = np.random.default_rng((self.seed, self.epoch, item))
        shape = self.dataset.arrays(sample)[1].shape
        free = [max(n - p, 0) for n, p in zip(shape, self.patch_size)]
        labels, shares = zip(*self.class_shares.items()) if self.class_shares else ((), ())
        weights = np.array([*shares, max(0.0, 1.0 - sum(shares))])  # the last: placed uniformly
        pick = rng.choice(len(weights), p=weights / weights.sum())
        blocks = self.sample_index(sample).blocks.get(labels[pick]) if pick < len(labels) else None
        if blocks is not None:
            centre = self._voxel_of(sample, labels[pick], blocks[rng.integers(len(blocks))], rng)
            start = tuple(int(np.clip(c - p // 2, 0, f)) for c, p, f in zip(centre, self.patch_size, free))
            centred_on = int(labels[pick])
        else:
            start, centred_on = tuple(int(rng.integers(f + 1)) for f in free), None
        flipped = tuple(bool(b) for b in rng.integers(2, size=3)) if self.flips else (False, False, False)
        return Patch(item, sample, start, centred_on, flipped)

    def sample_index(self, sample: int) -> _SampleIndex:
        """Which blocks of ``sample`` hold each label, and its intensity bounds (once a process)."""
        if sample not in self._index:
            volume, labels = self.dataset.arrays(sample)
            self._index[sample] = _SampleIndex(_label_blocks(labels, self.index_block),
                                               intensity_bounds(self.normalize, volume, self.index_block))
        return self._index[sample]

    def _voxel_of(self, sample: int, label: int, block, rng) -> tuple:
        """A voxel of ``label`` in ``block`` of ``sample``, drawn uniformly (reads the block)."""
        b = self.index_block
        low = [int(i) * b for i in block]
        region = np.asarray(self.dataset.arrays(sample)[1][low[0]:low[0] + b, low[1]:low[1] + b, low[2]:low[2] + b])
        voxels = np.argwhere(region == label)
        return tuple(int(o + v) for o, v in zip(low, voxels[rng.integers(len(voxels))]))

    def prepare(self) -> "PatchDataset":
        """Index every sample now (before a ``DataLoader`` forks its workers, which then inherit it)."""
        for sample in self.samples:
            self.sample_index(sample)
        return self

    def torch(self):
        """This dataset as a ``torch.utils.data.Dataset`` of (image (1, z, y, x) float32, labels
        (z, y, x) int64) tensors (needs the ``ml`` extra)."""
        from .torch_data import TorchPatches

        return TorchPatches(self)


def strided(array, stride: int) -> np.ndarray:
    """Every ``stride``-th voxel of ``array`` along each axis, from ``stride // 2``: one read."""
    o = stride // 2
    return np.asarray(array[o::stride, o::stride, o::stride])


def _label_blocks(labels, b: int) -> dict:
    """{label: (n, 3) int32 indices of the b³ blocks holding it}, read b planes at a time."""
    shape = labels.shape
    blocks: dict = {}
    for z in range(0, shape[0], b):
        slab = np.asarray(labels[z:z + b])
        # Pad to whole blocks with the edge's own labels, which the blocks at the edge hold anyway.
        slab = np.pad(slab, [(0, -n % b) for n in slab.shape], mode="edge")
        nz, ny, nx = (n // b for n in slab.shape)
        for value in np.unique(slab):
            held = (slab == value).reshape(nz, b, ny, b, nx, b).any(axis=(1, 3, 5))
            found = np.argwhere(held).astype(np.int32)
            found[:, 0] += z // b
            blocks.setdefault(int(value), []).append(found)
    return {value: np.concatenate(parts) for value, parts in blocks.items()}


def intensity_bounds(normalize, volume, stride: int) -> tuple[float, float]:
    """The intensities ``normalize`` maps to 0 and 1 for ``volume``, from every ``stride``-th voxel."""
    return normalize.bounds(strided(volume, stride))


def _crop(array, start, size, dtype) -> np.ndarray:
    """``array[..., start : start + size]`` over its last three axes (z, y, x; a first axis, the
    directions' components, whole), padded with 0 past its end."""
    lead = tuple(array.shape[:-3])
    stop = [min(b + p, n) for b, p, n in zip(start, size, array.shape[-3:])]
    key = (slice(None),) * len(lead) + tuple(slice(b, e) for b, e in zip(start, stop))
    data = np.asarray(array[key], dtype=dtype)
    if data.shape != (*lead, *size):
        data = np.pad(data, [(0, p - d) for p, d in zip((*lead, *size), data.shape)])
    return data


def _flipped(target: np.ndarray, axes: tuple) -> np.ndarray:
    """``target`` flipped along the spatial ``axes`` (0 z, 1 y, 2 x). A direction field's (3, z, y,
    x) component along a flipped axis (component 2 - axis: they are x, y, z) changes sign."""
    lead = target.ndim - 3
    out = np.flip(target, tuple(a + lead for a in axes)).copy()
    if lead:
        for a in axes:
            out[2 - a] *= -1
    return out


def patch_shape(patch_size) -> tuple[int, int, int]:
    """``patch_size`` (one positive integer, or (z, y, x) of them) checked, as (z, y, x)."""
    try:
        size = tuple(patch_size)  # (z, y, x)
    except TypeError:  # one number for all three
        size = (patch_size,) * 3
    if len(size) != 3 or not all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n > 0 for n in size):
        raise ConfigError(f"patch_size must be a positive integer or (z, y, x) of them, got {patch_size!r}")
    return tuple(int(n) for n in size)


def _positive(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _whole(name: str, value) -> int:
    """``value`` as an int >= 0 (a seed of numpy's generators: they refuse a negative one), or
    ConfigError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ConfigError(f"{name} must be an integer >= 0, got {value!r}")
    return int(value)


def _target(target, dataset: BuiltDataset, samples: list[int], split) -> str:
    """``target`` checked (:data:`~xrayraster.core.choices.PATCH_TARGETS`), and held by every sample
    of the split: else ConfigError naming the target and the fix."""
    check_choice(target, PATCH_TARGETS, "target", ConfigError)
    lacking = [i for i in samples if target != "classes" and target not in dataset.extra_labels.get(i, ())]
    if lacking:
        which = ("this build's samples have" if len(lacking) == len(samples) else
                 f"{len(lacking)} of the {len(samples)} samples of split {split!r} (sample {lacking[0]} first) have")
        raise ConfigError(f"target {target!r}: {which} no {target}; add \"{target}\" to [scan] labels in the dataset "
                          "file and build again")
    return target


def _shares(class_shares, labels: dict) -> dict:
    if class_shares is None:
        return {}
    if class_shares == "balanced":
        return {label: 1.0 / len(labels) for label in labels}
    if not isinstance(class_shares, dict):
        raise ConfigError(f"class_shares must be 'balanced', None or {{label: share}}, got {class_shares!r}")
    unknown = sorted(set(class_shares) - set(labels))
    if unknown:
        raise ConfigError(f"class_shares: label(s) {unknown} are not in the build (its labels: {labels})")
    if any(isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) for v in class_shares.values()):
        raise ConfigError(f"class_shares: each share a number in [0, 1], got {class_shares}")
    shares = {int(k): float(v) for k, v in class_shares.items()}
    if any(not 0.0 <= v <= 1.0 for v in shares.values()) or sum(shares.values()) > 1.0 + 1e-9:
        raise ConfigError(f"class_shares: each share in [0, 1], summing to at most 1; got {class_shares}")
    return shares
