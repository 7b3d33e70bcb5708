"""A dataset's gallery for the README: the first samples of ``examples/dataset_small.toml``, drawn
and scanned as a build draws and scans them, in one picture (:func:`xrayraster.core.pictures.write_gallery`):
each sample's central z slice in one grey window, its labels, and a caption with its split and a
few of its drawn values. About a second a sample.

Usage::

    python -m scripts.dataset_gallery [--dataset examples/dataset_small.toml] [--count 4] \
        [--out docs/images/dataset_gallery.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import xrayraster as xr
from xrayraster.core.pictures import write_gallery
from xrayraster.dataset import draw, load_dataset_file
from xrayraster.weave.yarn import LABELS

from .common import DOCS, ROOT, say

# A woven sample's label names, for scans whose metadata does not name its labels yet.
WOVEN_NAMES = {str(label): family for family, label in LABELS.items()}


def caption(index: int, drawn) -> str:
    """``sample 00003 (train): 40.1 kV, weft share 0.52, ram-lak filter``: drawn values that tell the rows apart."""
    values = drawn.values
    facts = [f"{values['source.kvp']:.1f} kV" if "source.kvp" in values else None,
             f"weft share {values['weave.weft_share']:.2f}" if "weave.weft_share" in values else None,
             f"{values['scan.filter']} filter" if "scan.filter" in values else None]
    return f"sample {index:05d} ({drawn.split}): " + ", ".join(f for f in facts if f)


def main(argv=None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path, default=ROOT / "examples" / "dataset_small.toml")
    parser.add_argument("--count", type=int, default=4, help="the first COUNT samples (default 4)")
    parser.add_argument("--out", type=Path, default=DOCS / "images" / "dataset_gallery.png")
    args = parser.parse_args(argv)
    dataset = load_dataset_file(args.dataset)
    samples = []
    for index in range(args.count):
        drawn = draw(dataset, index)
        result = xr.scan(drawn.scan)
        samples.append((result.volume.data, result.labels.data, result.metadata.get("labels") or WOVEN_NAMES,
                        caption(index, drawn)))
        say(samples[-1][3])
    path = write_gallery(args.out, samples)
    say(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
