"""Which shift costs the trained network its Dice: the shifted set (examples/ml_shifted.toml) with
one of its shifts taken back at a time, scored by the network scripts/train_segmentation.py saved
(docs/ml.md, "What limits it").

    python -m scripts.ml_shift_ablation            # 3 samples a variant, ~6 min on 2 cores
    python -m scripts.ml_shift_ablation --quick    # 1 sample a variant, with the --quick run's network
    python -m scripts.ml_shift_ablation --check    # only check the variants against the example files

Each variant is the shifted dataset file with some lines replaced (VARIANTS: the training set's
value or range, or the line removed), built with its own 3 samples (the same seeds as the shifted
set's first 3: the draws of the keys left alone are the same) into out/ml_ablation/, and scored as
scripts/train_segmentation.py scores (the network and the baselines, tracer voxels left out).
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import xrayraster as xr

from .common import OUT, ROOT, announce, conclude, outputs, parser, say
from .train_segmentation import NAMES, best_baseline, load_model, score_set

TRAINING_WEAVE = {  # examples/ml_train.toml's ranges
    '"weave.weft_spacing" = { choice = [2.1, 2.9] }': '"weave.weft_spacing" = { uniform = [2.35, 2.65] }',
    '"weave.warp_spacing" = { uniform = [2.8, 3.0] }': '"weave.warp_spacing" = { uniform = [2.35, 2.65] }',
    '"weave.weft_width_fraction" = { uniform = [0.8, 0.85] }': '"weave.weft_width_fraction" = { uniform = [0.85, 0.95] }',
    '"weave.warp_width_fraction" = { uniform = [0.95, 0.98] }': '"weave.warp_width_fraction" = { uniform = [0.85, 0.95] }',
    '"weave.weft_share" = { uniform = [0.6, 0.65] }': '"weave.weft_share" = { uniform = [0.45, 0.6] }',
    '"weave.thickness" = { uniform = [3.7, 3.8] }': '"weave.thickness" = { uniform = [3.8, 4.2] }',
}
IMPERFECTIONS = [r'"source.focal_spot_mm" = .*\n', r'"detector.flat_fields" = .*\n', r'"detector.gain_variation" = .*\n',
                 r'"detector.blur_sigma_px" = .*\n', r'"mount" = .*\n']
VARIANTS = {  # name → {pattern: replacement}
    "all shifts": {},
    "no tracer": {r'"weave.materials.tracers" = .*\n': ""},
    "no holder": {r'"mount" = .*\n': ""},
    "no gain rings, exact flats": {r'"detector.gain_variation" = .*\n': "", r'"detector.flat_fields" = .*\n': ""},
    "the training tube (40 kV, 2 mm Al, 1.25 mAs)": {r'"source.kvp" = .*\n': '"source.kvp" = 40.0\n',
                                                     r'"source.filters" = .*\n': '"source.filters" = { Al = 2.0 }\n',
                                                     r'"source.mas" = .*\n': '"source.mas" = 1.25\n'},
    "no scanner imperfections (spot, flats, rings, blur, holder)": {p: "" for p in IMPERFECTIONS},
    "the training weave's ranges": {re.escape(k): v for k, v in TRAINING_WEAVE.items()},
    "no tracer, no imperfections": {r'"weave.materials.tracers" = .*\n': "", **{p: "" for p in IMPERFECTIONS}},
}


def variant_text(base: str, edits: dict, count: int) -> str:
    text = base.replace("count = 10", f"count = {count}")
    text = text.replace('base = "scan_small.toml"', f'base = "{ROOT / "examples" / "scan_small.toml"}"')
    for pattern, replacement in edits.items():
        text, n = re.subn(pattern, lambda m, r=replacement: r, text)
        assert n == 1, f"{pattern!r} matched {n} lines of examples/ml_shifted.toml"
    return text


def check() -> int:
    """0 when every variant takes back what it says (:func:`variant_text` asserts that each pattern
    matches one line) and TRAINING_WEAVE's ranges are those of examples/ml_train.toml; 1 otherwise."""
    base = (ROOT / "examples" / "ml_shifted.toml").read_text()
    train = (ROOT / "examples" / "ml_train.toml").read_text()
    failures = []
    for name, edits in VARIANTS.items():
        try:
            text = variant_text(base, edits, 3)
        except AssertionError as exc:
            failures.append(f"{name}: {exc}")
            continue
        if "count = 3" not in text or text == base:
            failures.append(f"{name}: the variant changes nothing")
    failures += [f"not in examples/ml_train.toml: {r}" for r in TRAINING_WEAVE.values() if r not in train]
    for line in failures:
        say(f"FAILED: {line}")
    say(f"{len(VARIANTS)} variants checked: " + ("FAILED" if failures else "ok"))
    return 1 if failures else 0


def main(argv=None) -> int:
    ap = parser(__doc__, "1 sample a variant, with the --quick run's network (out/ml_quick/model.pt)")
    ap.add_argument("--trained", type=Path, help="the training run's folder (default out/ml; --quick: out/ml_quick)")
    ap.add_argument("--out", type=Path, help="the variants' builds (default out/ml_ablation; --quick: out/ml_ablation_quick)")
    ap.add_argument("--check", action="store_true", help="only check that every variant's patterns match one line "
                    "each of examples/ml_shifted.toml and the training weave's ranges are examples/ml_train.toml's")
    args = outputs(ap.parse_args(argv), "ml_shift_ablation")
    if args.check:
        return check()
    t_start = time.perf_counter()
    command, machine = announce()
    model, patch, order, normalize = load_model(args.trained or OUT / ("ml_quick" if args.quick else "ml"))
    base = (ROOT / "examples" / "ml_shifted.toml").read_text()
    folder = args.out or OUT / ("ml_ablation_quick" if args.quick else "ml_ablation")
    results = {}
    for name, edits in VARIANTS.items():
        slug = re.sub(r"\W+", "_", name).strip("_")
        path = folder / f"{slug}.toml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(variant_text(base, edits, 1 if args.quick else 3))
        xr.build(path, folder / slug, workers=2)
        scores, _ = score_set(model, folder / slug, "test", patch, order, normalize)
        results[name] = {m: {"mean_dice": r["mean_dice"], "dice": r["dice"]} for m, r in scores.items()}
        best = best_baseline(scores)
        net = scores["network"]
        say(f"{name}: network {net['mean_dice']:.3f} ("
            + ", ".join(f"{n} {net['dice'][n]:.3f}" for n in NAMES.values())
            + f"); best baseline {scores[best]['mean_dice']:.3f} ({best})")
    conclude(args.json, {"command": command, "machine": machine, "results": results}, machine, t_start)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
