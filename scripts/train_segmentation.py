"""Train a 3-D U-Net on a dataset build and score it on scans it never saw, beside the classical
methods users try first (docs/ml.md).

    python -m scripts.train_segmentation           # the experiment of docs/ml.md (~25 min on 2 cores)
    python -m scripts.train_segmentation --quick   # a smoke run: 12 samples, 30 iterations (~1 min)

1. **Data.** ``xr.build`` of examples/ml_train.toml (60 scans; its ``train`` split trains the
   network, its ``test`` split scores it) and of examples/ml_shifted.toml (10 scans outside every
   training range: scanner imperfections, 50 kV, other cells and distortions, a PMMA holder, a glass
   tracer), into out/ml/ unless already there (a build resumes). Also a fresh draw of the shifted
   set (its seed + 1000: 10 other scans from the same ranges), scored only after every choice here
   (the normalisation, the post-processing) was fixed by the shifted set's scores: a choice fitted
   to those 10 scans would show as a gap between the two. ``--train-file`` trains on another dataset
   file instead: a name in examples/ (docs/ml.md: ml_train_scanner.toml, ml_train_randomized.toml) or a path
   (scripts/train_around_fit.py writes one around a fit).
2. **Network.** MONAI's 3-D ``UNet`` (``--channels``: the width of each level, 16-128 by default;
   strides 2, two residual units), one input channel (0 cm⁻¹ mapped to 0 and the median of the
   volume's material to 1, clipped to -0.25 and 1.5: ``xr.ml.MaterialScale()``), one output per
   label of the training build (air, matrix, weft, warp); Dice + cross-entropy loss (MONAI's
   ``DiceCELoss``), Adam at 2e-3 with cosine decay, ``--iterations`` batches of ``--batch`` patches of ``--patch``³
   voxels (:class:`xrayraster.ml.PatchDataset`: balanced over the labels, flipped). Seeded, with
   deterministic kernels and a fixed thread count, so a rerun trains the same network.
   ``--augment`` (off by default: it scored lower here, docs/ml.md) adds MONAI's transforms after
   nnU-Net's (:func:`augmentation`): each patch read 1.25 times as wide and resampled to
   ``--patch``³ at a scale of 0.85-1.15 along each axis, its intensities scaled (x0.85-1.15),
   shifted (±0.1), given a gamma (0.8-1.25), blurred (σ 0.5-1 voxel) and given noise (σ up to
   0.05), each with a probability of 0.3-0.5. ``--scale LO,HI`` draws the scale in LO-HI instead
   (a scale s shows the patch's content 1/s as large; nnU-Net draws 0.7-1.4), each patch read HI
   times as wide (at least 1.25); without ``--augment``, the resampling is all the augmentation: a cell's size
   varies, its attenuation steps stay as built.
3. **Scores.** Each test volume segmented whole (:func:`xrayraster.ml.predict_volume`, windows
   overlapping by half) and its largest body kept (:func:`xrayraster.ml.largest_component`: the
   specimen is one body; every method's labels get the same step, and the network's are also scored
   without it), then per volume Dice of matrix, weft and warp and their mean, and the
   confusion matrix (voxels by true and predicted label), summed over each set. The shifted set's
   tracer voxels (label 4, a class the network cannot know) are left out of every score.
4. **Baselines**, on the same volumes: multi-Otsu thresholds (scikit-image) and a Gaussian mixture
   of four components (scikit-learn) on the attenuation, each after a 3³ median or a σ = 1 voxel
   Gaussian filter; their classes are ordered by their mean attenuation and matched to the labels
   in the order of the training set's mean attenuation per label.

Writes out/ml/model.pt and model.json (the weights; the patch and the label order),
out/train_segmentation.json, docs/ml_curve.png and docs/ml_slices.png (--quick: out/ml_quick/,
out/train_segmentation_quick.json and the plots in out/).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

import xrayraster as xr
from references.segmentation import baseline, confusion, dice_from_confusion
from xrayraster.dataset.dataset_file import load_dataset_file

from .common import OUT, ROOT, announce, conclude, cores, outputs, parser, pyplot, save, say

NAMES = {1: "matrix", 2: "weft", 3: "warp"}  # the scored labels
UNFILTERED = "network, every body kept"  # the network's labels scored without largest_component
SCORED = tuple(NAMES)
SCALE = (0.85, 1.15)  # --augment's scales along each axis, unless --scale is given (augmentation)
READ = 1.25  # a resampled patch is read at least this many times as wide (augmentation)
NORMALIZE = xr.ml.MaterialScale()  # the network's input (module docstring)
BUILDS = {  # folder under --out: (dataset file in examples/, added to its seed, samples with --quick)
    "train": ("ml_train.toml", 0, 9),  # --quick: the 9th sample is the first of the test split
    "shifted": ("ml_shifted.toml", 0, 2),
    "fresh": ("ml_shifted.toml", 1000, 1),
}


def main(argv=None) -> int:
    ap = parser(__doc__, "a smoke run: 12 samples, 30 iterations (~1 min)", plots=True)
    ap.add_argument("--iterations", type=int, help="training batches (default 3000: about 22 min on 2 cores; --quick: 30)")
    ap.add_argument("--batch", type=int, default=2, help="patches a batch (default 2)")
    ap.add_argument("--patch", type=int, help="patch side in voxels (default 64; --quick: 32)")
    ap.add_argument("--seed", type=int, default=0, help="the training's seed (default 0)")
    ap.add_argument("--channels", default="16,32,64,128",
                    help="the U-Net's channels at each level, comma-separated (default 16,32,64,128)")
    ap.add_argument("--augment", action="store_true", help="augment each patch (module docstring; off by default)")
    ap.add_argument("--scale", type=_scales, help="LO,HI: resample each patch at a scale drawn in LO-HI along each "
                    "axis (module docstring; --augment alone: 0.85,1.15)")
    ap.add_argument("--train-file", default=BUILDS["train"][0],
                    help="the training set's dataset file: a name in examples/ (default ml_train.toml) or a path")
    ap.add_argument("--out", type=Path, help="the builds and model.pt (default out/ml; --quick: out/ml_quick)")
    args = outputs(ap.parse_args(argv), "train_segmentation")
    iterations = args.iterations or (30 if args.quick else 3000)
    patch = args.patch or (32 if args.quick else 64)
    t_start = time.perf_counter()
    command, machine = announce()

    import torch

    torch.manual_seed(args.seed)
    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(cores())
    folder = args.out or OUT / ("ml_quick" if args.quick else "ml")
    builds, seconds = {}, {}
    for name, (file, reseed, count) in BUILDS.items():
        dataset = load_dataset_file(_dataset_path(args.train_file if name == "train" else file))
        dataset = dataclasses.replace(dataset, seed=dataset.seed + reseed, count=count if args.quick else dataset.count)
        start = time.perf_counter()
        xr.build(dataset, folder / name, workers=min(2, dataset.count))  # no more processes than samples
        seconds[f"build {name}"] = time.perf_counter() - start
        builds[name] = folder / name
        say(f"build {name}: {dataset.count} samples in {seconds[f'build {name}']:.0f} s (0 s: built before)")

    scales = args.scale or (SCALE if args.augment else None)
    read = round(patch * max(READ, scales[1])) if scales else patch
    train = xr.ml.PatchDataset(builds["train"], read, split="train", patches_per_sample=max(8, iterations),
                               flips=True, seed=args.seed, normalize=NORMALIZE).prepare()
    classes = max(train.dataset.labels) + 1
    augment = augmentation(patch, args.seed, scales, args.augment) if scales else None
    channels = tuple(int(c) for c in args.channels.split(","))
    start = time.perf_counter()
    model, losses = fit(torch, train, classes, channels, iterations, args.batch, args.seed, augment)
    seconds["training"] = time.perf_counter() - start
    say(f"training: {iterations} batches of {args.batch} × {patch}³ in {seconds['training']:.0f} s "
        f"({seconds['training'] / iterations:.2f} s a batch); loss {np.mean(losses[:20]):.3f} → {np.mean(losses[-20:]):.3f}")
    order = label_order(train)
    save_model(model, folder, patch, order, channels, NORMALIZE)
    sets = {"test split": (builds["train"], "test"), "shifted": (builds["shifted"], "test"),
            "shifted, fresh draw": (builds["fresh"], "test")}
    results, examples = {}, {}
    for set_name, (root, split) in sets.items():
        start = time.perf_counter()
        results[set_name], examples[set_name] = score_set(model, root, split, patch, order, NORMALIZE)
        seconds[f"scoring {set_name}"] = time.perf_counter() - start
        for method, r in results[set_name].items():
            dice = ", ".join(f"{NAMES[c]} {r['dice'][NAMES[c]]:.3f}" for c in SCORED)
            say(f"{set_name}: {method}: mean Dice {r['mean_dice']:.3f} ({dice}); {r['seconds']:.1f} s")
    plots = curve_plot(losses, args.plots_dir / "ml_curve.png"), slices_plot(examples["shifted"], results["shifted"],
                                                                             args.plots_dir / "ml_slices.png")
    payload = {"command": command, "machine": machine, "iterations": iterations, "batch": args.batch, "patch": patch,
               "seed": args.seed, "channels": channels, "train_file": args.train_file, "augment": args.augment, "scale": scales,
               "normalize": repr(NORMALIZE), "classes": classes, "train_samples": len(train.samples),
               "seconds": seconds,
               "loss_first_20": float(np.mean(losses[:20])), "loss_last_20": float(np.mean(losses[-20:])),
               "results": results, "plots": [str(p) for p in plots if p]}
    conclude(args.json, payload, machine, t_start)
    return 0


def _dataset_path(name: str) -> Path:
    """examples/``name`` where that file exists, else ``name`` as a path."""
    shipped = ROOT / "examples" / name
    return shipped if shipped.is_file() else Path(name)


def fit(torch, train, classes: int, channels: tuple, iterations: int, batch: int, seed: int, augment=None):
    """MONAI's UNet trained for ``iterations`` batches (module docstring), each patch passed through
    ``augment`` (:func:`augmentation`) when given; returns the network and the losses."""
    from monai.losses import DiceCELoss

    model = make_model(classes, channels)
    loss_of = DiceCELoss(to_onehot_y=True, softmax=True)
    optimiser = torch.optim.Adam(model.parameters(), lr=2e-3)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, iterations)
    data = train.torch()
    loader = torch.utils.data.DataLoader(data, batch_size=batch, shuffle=True, drop_last=True,
                                         generator=torch.Generator().manual_seed(seed))
    losses, epoch = [], 0
    model.train()
    while len(losses) < iterations:
        data.set_epoch(epoch)
        for image, labels in loader:
            if augment is not None:
                image, labels = augmented(torch, augment, image, labels)
            optimiser.zero_grad()
            loss = loss_of(model(image), labels[:, None])
            loss.backward()
            optimiser.step()
            schedule.step()
            losses.append(loss.item())
            if len(losses) % 200 == 0:
                say(f"  batch {len(losses)}: loss {np.mean(losses[-200:]):.3f}")
            if len(losses) == iterations:
                break
        epoch += 1
    return model, losses


def augmentation(patch: int, seed: int, scales: tuple[float, float] = SCALE, intensities: bool = True):
    """The augmentation of the module docstring: MONAI dictionary transforms of ``image`` (1, z, y, x)
    and ``label`` (1, z, y, x) read wider than ``patch``, giving ``patch``³, at ``scales`` (low,
    high) along each axis, then, with ``intensities``, the intensity transforms; seeded."""
    from monai import transforms as t

    resample = t.RandAffined(("image", "label"), spatial_size=(patch,) * 3, prob=1.0,
                             scale_range=((scales[0] - 1, scales[1] - 1),) * 3,  # MONAI adds 1
                             mode=("bilinear", "nearest"), padding_mode="zeros")
    sigma = (0.5, 1.0)
    steps = [resample] + ([
        t.RandScaleIntensityd("image", factors=0.15, prob=0.5),
        t.RandShiftIntensityd("image", offsets=0.1, prob=0.5),
        t.RandAdjustContrastd("image", gamma=(0.8, 1.25), prob=0.3),
        t.RandGaussianSmoothd("image", sigma_x=sigma, sigma_y=sigma, sigma_z=sigma, prob=0.3),
        t.RandGaussianNoised("image", std=0.05, prob=0.3),
    ] if intensities else [])
    return t.Compose(steps).set_random_state(seed)


def _scales(text: str) -> tuple[float, float]:
    """--scale's LO,HI, checked."""
    try:
        low, high = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--scale takes two numbers, LO,HI (say 0.7,1.4), not {text!r}") from None
    if not 0 < low <= high:
        raise argparse.ArgumentTypeError(f"--scale {text}: LO,HI must satisfy 0 < LO <= HI (say 0.7,1.4)")
    return low, high


def augmented(torch, augment, image, labels):
    """A batch (N, 1, z, y, x) and its labels (N, z, y, x), each patch passed through ``augment``."""
    items = [augment({"image": i, "label": lab[None]}) for i, lab in zip(image, labels)]
    return (torch.stack([d["image"].as_tensor() for d in items]),
            torch.stack([d["label"].as_tensor()[0] for d in items]).long())


def make_model(classes: int, channels: tuple):
    """The network (module docstring) with ``channels`` at its levels, untrained."""
    from monai.networks.nets import UNet

    return UNet(spatial_dims=3, in_channels=1, out_channels=classes, channels=channels,
                strides=(2,) * (len(channels) - 1), num_res_units=2)


def save_model(model, folder: Path, patch: int, order: list[int], channels: tuple, normalize) -> None:
    """``model.pt`` (the weights) and ``model.json`` (what scoring needs: the patch, the label order,
    the network's channels and the normalisation)."""
    import torch

    torch.save(model.state_dict(), folder / "model.pt")
    info = {"patch": patch, "order": order, "channels": list(channels),
            "normalize": [type(normalize).__name__, dataclasses.asdict(normalize)]}
    (folder / "model.json").write_text(json.dumps(info) + "\n")


def load_model(folder: Path):
    """(model, patch, label order, normalisation) as :func:`save_model` left them in ``folder``."""
    import torch

    info = json.loads((folder / "model.json").read_text())
    model = make_model(len(info["order"]), tuple(info["channels"]))
    model.load_state_dict(torch.load(folder / "model.pt"))
    kind, fields = info["normalize"]
    normalize = getattr(xr.ml, kind)(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})
    return model.eval(), info["patch"], info["order"], normalize


def label_order(train) -> list[int]:
    """The labels in the order of their mean attenuation in the training build (air first)."""
    sums, counts = {}, {}
    for sample in train.samples:
        volume, labels = (np.asarray(a) for a in train.dataset.arrays(sample))
        for label in train.dataset.labels:
            mask = labels == label
            sums[label] = sums.get(label, 0.0) + float(volume[mask].sum())
            counts[label] = counts.get(label, 0) + int(mask.sum())
    return sorted(sums, key=lambda label: sums[label] / max(counts[label], 1))


def score_set(model, root, split: str, patch: int, order: list[int], normalize):
    """{method: scores} over the set's volumes, and the first volume's middle slices for the figure."""
    dataset = xr.ml.PatchDataset(root, patch, split=split)
    methods = {"network": lambda v: xr.ml.predict_volume(model, v, patch, overlap=0.5, normalize=normalize),
               **{f"{name}, {smooth}": baseline(name, smooth, order) for name in ("multi-Otsu", "Gaussian mixture")
                  for smooth in ("median 3³", "Gaussian σ 1")}}
    results = {m: {"confusion": np.zeros((len(order), len(order)), np.int64), "per_volume": [], "seconds": 0.0}
               for m in (*methods, UNFILTERED)}
    example = None
    for sample in dataset.samples:
        volume, truth = (np.asarray(a) for a in dataset.dataset.arrays(sample))
        keep = truth < len(order)  # a tracer (label 4) is no class the network knows: not scored
        middle = volume.shape[0] // 2
        if example is None:
            example = {"volume": volume[middle], "truth": truth[middle], "predicted": {}}
        for method, segment in methods.items():
            start = time.perf_counter()
            predicted = segment(volume)
            segmented = time.perf_counter()
            outputs = {method: xr.ml.largest_component(predicted)}
            results[method]["seconds"] += time.perf_counter() - start
            if method == "network":
                outputs[UNFILTERED] = predicted
                results[UNFILTERED]["seconds"] += segmented - start
            for name, labels in outputs.items():
                counts = confusion(truth[keep], labels[keep], len(order))
                results[name]["confusion"] += counts
                results[name]["per_volume"].append(dice_from_confusion(counts, SCORED))
                example["predicted"].setdefault(name, labels[middle])
    for r in results.values():
        total = dice_from_confusion(r["confusion"], SCORED)
        r["dice"] = {NAMES[c]: total[c] for c in SCORED}
        r["mean_dice"] = float(np.mean([total[c] for c in SCORED]))
        r["mean_dice_per_volume"] = [float(np.mean([d[c] for c in SCORED])) for d in r["per_volume"]]
        r["per_volume"] = [{NAMES[c]: d[c] for c in SCORED} for d in r["per_volume"]]
        r["confusion"] = r["confusion"].tolist()
    return results, example


def best_baseline(results: dict) -> str:
    """The method other than the network with the highest mean Dice in ``results``."""
    return max((m for m in results if not m.startswith("network")), key=lambda m: results[m]["mean_dice"])


def curve_plot(losses: list[float], path: Path) -> Path | None:
    plt = pyplot()
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(6, 3.2))
    window = max(1, len(losses) // 50)
    smooth = np.convolve(losses, np.ones(window) / window, mode="valid")
    ax.plot(np.arange(len(losses)) + 1, losses, color="0.8", lw=0.6, label="batch")
    ax.plot(np.arange(len(smooth)) + window, smooth, color="C0", label=f"mean of {window}")
    ax.set_xlabel("batch")
    ax.set_ylabel("Dice + cross-entropy loss")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path)


def slices_plot(example: dict, results: dict, path: Path) -> Path | None:
    """A shifted scan's middle slice: image, truth, the network, the best baseline."""
    plt = pyplot()
    if plt is None:
        return None
    from matplotlib.colors import ListedColormap

    best = best_baseline(results)
    colours = ListedColormap(["black", "#4c72b0", "#dd8452", "#55a868", "#c44e52"])
    panels = [("scan (cm⁻¹)", example["volume"], "gray", None), ("truth", example["truth"], colours, 4),
              (f"network: mean Dice {results['network']['mean_dice']:.3f}", example["predicted"]["network"], colours, 4),
              (f"{best}: {results[best]['mean_dice']:.3f}", example["predicted"][best], colours, 4)]
    fig, axes = plt.subplots(1, 4, figsize=(12, 3.4))
    for ax, (title, image, cmap, top) in zip(axes, panels):
        ax.imshow(image, cmap=cmap, vmin=0 if top else None, vmax=top, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.suptitle("shifted test scan, middle slice: air black, matrix blue, weft orange, warp green, tracer red",
                 fontsize=9)
    fig.tight_layout()
    return save(fig, path)


if __name__ == "__main__":
    raise SystemExit(main())
