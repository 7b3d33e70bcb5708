"""``xrayraster scan SCAN.toml -o DIR``: a virtual scan, sample to reconstruction and labels (docs/scan.md).

``DIR`` is built under a temporary name and moved into place when complete
(:func:`~xrayraster.core.files.atomic_directory`); an existing ``DIR`` is replaced only if it holds
an earlier ``xrayraster scan`` output. The scan file is checked whole before any work.
"""

from __future__ import annotations

from pathlib import Path

from ..core.files import atomic_directory
from ..pipeline import is_scan_output, load_scan_file, scan


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("scan", help="a virtual scan: projections, FDK volume and labels from a scan file")
    parser.add_argument("scan", type=Path, help="scan file (docs/scan.md): a scene file whose sample may be [weave]")
    parser.add_argument("-o", "--out", dest="out", metavar="DIR", type=Path, required=True,
                        help="output directory (replaced only if it holds an earlier xrayraster scan output)")
    parser.add_argument("--save-projections", action="store_true",
                        help="also write the projections (line integrals) as DIR/projections.tif")
    parser.add_argument("--allow-starved", action="store_true",
                        help="scan even when over half the pixels the sample covers detect no photon (docs/scan.md)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("-v", "--verbose", action="store_true")
    parser.set_defaults(run=run)


def run(args) -> int:
    loaded = load_scan_file(args.scan)
    with atomic_directory(args.out, replaceable=is_scan_output) as tmp:
        result = scan(loaded, progress=not args.quiet, keep_projections=args.save_projections,
                      allow_starved=args.allow_starved)
        result.save(tmp)
    meta = result.metadata
    stages = ", ".join(f"{stage} {s:.2f}" for stage, s in meta["seconds"].items())
    print(f"{args.out}: volume {'x'.join(map(str, meta['volume']['shape']))} ({meta['geometry']['num_views']} views); "
          f"seconds: {stages}; peak memory {meta['peak_rss_mib']:.0f} MiB")
    return 0
