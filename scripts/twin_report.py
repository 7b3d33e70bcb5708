"""The reference digital twin's figures for docs/twin.md, from a finished scan.

    xrayraster scan examples/twin.toml -o out/twin
    python -m scripts.twin_report out/twin            # writes docs/images/twin_*.png, prints the table

Prints each stage's wall time, the peak memory and the attenuation histogram's peaks (the whole
sample, and each class alone) beside the reference paper's (yarns ≈ 0.50 cm⁻¹, matrix ≈ 0.42
cm⁻¹); draws the histograms (docs/images/twin_histogram.png) and copies the scan's slice picture
(docs/images/twin_slices.png). The materials are the paper's, never tuned to match its peaks.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import tifffile

from xrayraster.pipeline.compare import histogram, histogram_peaks, label_mask, value_range, write_histogram_png

from .common import machine_info

IMAGES = Path(__file__).resolve().parent.parent / "docs" / "images"
CLASSES = {"matrix": 1, "weft": 2, "warp": 3}
PAPER = {"yarns": 0.50, "matrix": 0.42}  # cm⁻¹, the reference scan's histogram peaks
BINS = 200


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scan", type=Path, help="an xrayraster scan output directory")
    parser.add_argument("--name", default="twin", help="figure names: docs/images/NAME_*.png")
    args = parser.parse_args(argv)
    volume = tifffile.imread(args.scan / "volume.tif")
    labels = tifffile.imread(args.scan / "labels.tif")
    metadata = json.loads((args.scan / "scan.json").read_text())

    sample = label_mask(labels)
    span = value_range(volume, mask=sample)
    curves = {"sample (every labelled voxel)": histogram(volume, sample, BINS, span)}
    for name, label in CLASSES.items():
        curves[name] = histogram(volume, label_mask(labels, [label]), BINS, span)
    histogram_path = write_histogram_png(
        IMAGES / f"{args.name}_histogram.png", curves,
        title=f"{args.scan.name}: attenuation histograms (paper: yarns ≈ {PAPER['yarns']}, matrix ≈ {PAPER['matrix']} cm⁻¹)")
    shutil.copyfile(args.scan / "slices.png", IMAGES / f"{args.name}_slices.png")

    print("machine:", machine_info())
    print(f"grid {metadata['volume']['shape']}, {metadata['geometry']['num_views']} views of "
          f"{metadata['geometry']['detector_shape']}, {metadata['triangles']} triangles, "
          f"mesh {metadata['mesh_resolution']}")
    print("seconds:", metadata["seconds"], f"peak memory {metadata['peak_rss_mib']} MiB")
    print("spectral table:", metadata["projections"]["spectral_table"])
    for name, h in curves.items():
        peaks = ", ".join(f"{p:.3f}" for p in histogram_peaks(h)[:3])
        print(f"{name:>30}: peaks (highest first) {peaks} cm⁻¹")
    for name, label in CLASSES.items():
        inside = volume[labels == label]
        print(f"{name:>30}: mean {inside.mean():.4f}, median {np.median(inside):.4f} cm⁻¹ over {inside.size} voxels")
    print(f"wrote {histogram_path} and {IMAGES / f'{args.name}_slices.png'}")


if __name__ == "__main__":
    main()
