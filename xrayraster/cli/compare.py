"""``xrayraster compare A.tif B.tif``: sim-to-real metrics of two volumes on one grid (docs/compare.md).

Prints the cosine similarity, SSIM, PSNR and the histogram peaks; ``-o DIR`` writes
``DIR/histograms.png`` and ``DIR/compare.json`` (``--png`` and ``--json`` name either file
instead), each atomically, after the checks every command makes (``cli.outputs``). The voxels compared are all, those of ``--mask`` (non-zero), or the
labelled ones of ``--labels`` (``labels.tif`` of ``xrayraster scan``), of ``--class`` only if given.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.errors import ConfigError
from ..core.files import atomic_write_text
from ..core.inputs import read_tiff_file
from ..pipeline.compare import MAX_BINS, compare, label_mask, write_histogram_png
from .options import nonnegative_int, positive_int
from .outputs import check_outputs

PNG_NAME, JSON_NAME = "histograms.png", "compare.json"
UNIT_LABELS = {"1/cm": "cm⁻¹", "1/mm": "mm⁻¹"}


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("compare", help="sim-to-real metrics of two volumes: histograms, cosine "
                                                   "similarity, SSIM, PSNR")
    parser.add_argument("a", type=Path, metavar="A.tif",
                        help="a volume TIFF (z, y, x), e.g. volume.tif of xrayraster scan")
    parser.add_argument("b", type=Path, metavar="B.tif", help="the volume to compare it with, on the same voxel grid")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--mask", type=Path, metavar="M.tif", help="compare the voxels where this TIFF is non-zero")
    where.add_argument("--labels", type=Path, metavar="L.tif",
                       help="compare the labelled (non-zero) voxels of this label volume "
                            "(labels.tif of xrayraster scan)")
    parser.add_argument("--class", dest="classes", action="append", type=nonnegative_int, metavar="K",
                        help="with --labels: only label K (repeat for more; xrayraster scan: matrix 1, weft 2, warp 3)")
    parser.add_argument("-o", "--out", dest="out", type=Path, metavar="DIR",
                        help=f"write DIR/{PNG_NAME} and DIR/{JSON_NAME}")
    parser.add_argument("--png", type=Path, metavar="PATH", help=f"the histogram plot (default DIR/{PNG_NAME} with -o)")
    parser.add_argument("--json", type=Path, metavar="PATH",
                        help=f"the metrics as JSON (default DIR/{JSON_NAME} with -o)")
    parser.add_argument("--bins", type=positive_int,
                        help=f"histogram bins (default: the square root of the voxels compared, at most {MAX_BINS})")
    parser.add_argument("--range", dest="range_", type=float, nargs=2, metavar=("LO", "HI"),
                        help="histogram range (default: the lowest to the highest compared value of both volumes)")
    parser.add_argument("--data-range", type=float, metavar="L",
                        help="the value span L of SSIM and PSNR (default: the width of the histogram's default range)")
    parser.add_argument("-v", "--verbose", action="store_true")
    parser.set_defaults(run=run)


def run(args) -> int:
    if args.classes and args.labels is None:
        raise ConfigError("--class selects classes of --labels L.tif; give --labels too, or use --mask")
    png = args.png or (args.out / PNG_NAME if args.out else None)
    json_path = args.json or (args.out / JSON_NAME if args.out else None)
    _check_suffix(png, PNG_NAME, "--png")
    _check_suffix(json_path, JSON_NAME, "--json")
    outputs = [p for p in (png, json_path) if p is not None]
    if outputs:
        check_outputs(outputs, [p for p in (args.a, args.b, args.mask, args.labels) if p is not None],
                      main_is_tiff=False)
    (a, a_unit), (b, b_unit) = _read_volume(args.a, "volume A"), _read_volume(args.b, "volume B")
    if a_unit and b_unit and a_unit != b_unit:
        raise ConfigError(f"{args.a} is in {a_unit} and {args.b} in {b_unit}; convert one so both share a unit")
    mask, mask_name = _read_mask(args)
    result = compare(a, b, mask, bins=args.bins, range_=args.range_, data_range=args.data_range,
                     names=(str(args.a), str(args.b)), mask_name=mask_name)
    unit = UNIT_LABELS.get(a_unit or b_unit, a_unit or b_unit)
    written = []
    if png is not None:
        xlabel = f"linear attenuation μ ({unit})" if unit else "voxel value"
        written.append(write_histogram_png(png, result, xlabel=xlabel))
    if json_path is not None:
        record = {"generator": "xrayraster compare", "version": __version__, "unit": a_unit or b_unit,
                  **result.to_dict()}
        written.append(atomic_write_text(json_path, json.dumps(record, indent=1) + "\n"))
    peaks = "; ".join(f"{n}: " + (", ".join(f"{p:.3f}" for p in ps) or "none")
                      for n, ps in zip(result.names, result.peaks))
    print(f"{args.a} vs {args.b} over {result.voxels} voxels ({mask_name or 'all'}):\n"
          f"  cosine similarity {result.cosine_similarity:.6f}\n"
          f"  SSIM {result.ssim:.5f} ({result.ssim_window}-voxel window), PSNR {result.psnr_db:.2f} dB, "
          f"data range {result.data_range:.4g}{' ' + unit if unit else ''}\n"
          f"  histogram peaks{f' ({unit})' if unit else ''}, highest first: {peaks}"
          + (f"\n  wrote {', '.join(map(str, written))}" if written else ""))
    return 0


def _check_suffix(path: Path | None, default_name: str, flag: str) -> None:
    """Refuse, before any work, an output of the wrong kind (the rest: :func:`check_outputs`)."""
    suffix = Path(default_name).suffix
    if path is not None and path.suffix.lower() != suffix:
        raise ConfigError(f"{flag} {path}: the file must end in {suffix}; use e.g. {path.with_name(default_name)}")


def _read_tiff(path: Path, what: str) -> tuple[np.ndarray, dict]:
    data, info = read_tiff_file(path, what)
    if data.ndim != 3:
        raise ConfigError(f"{what} {path} holds an array of shape {data.shape}; give a volume (z, y, x)")
    return data, info


def _read_volume(path: Path, what: str) -> tuple[np.ndarray, str | None]:
    """The volume and its unit (None for a TIFF that does not say, one from another program)."""
    data, info = _read_tiff(path, what)
    return data, info.get("units")


def _read_mask(args) -> tuple[np.ndarray | None, str | None]:
    if args.mask is not None:
        mask, _ = _read_tiff(args.mask, "--mask")
        return mask != 0, f"--mask {args.mask}"
    if args.labels is not None:
        labels, _ = _read_tiff(args.labels, "--labels")
        classes = sorted(set(args.classes)) if args.classes else None
        selected = f"classes {', '.join(map(str, classes))}" if classes else "labelled voxels"
        return label_mask(labels, classes, name=f"--labels {args.labels}"), f"--labels {args.labels}, {selected}"
    return None, None
