"""``xrayraster scan SCAN.toml -o DIR``: a virtual scan, sample to reconstruction and labels (docs/scan.md).

``DIR`` is built under a temporary name and moved into place when complete
(:func:`~xrayraster.core.files.atomic_directory`); an existing ``DIR`` is replaced only if it holds
nothing but an earlier ``xrayraster scan`` output (``--force``: its files are replaced, anything
else in it is kept). The scan file and ``DIR`` are checked before any work.
"""

from __future__ import annotations

from pathlib import Path

from ..pipeline import check_scan_output, load_scan_file, scan


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("scan", help="a virtual scan: projections, FDK volume and labels from a scan file")
    parser.add_argument("scan", type=Path, help="scan file (docs/scan.md): a scene file whose sample may be [weave]")
    parser.add_argument("-o", "--out", dest="out", metavar="DIR", type=Path, required=True,
                        help="output directory (replaced only if it holds nothing but an earlier xrayraster scan output)")
    parser.add_argument("--force", action="store_true",
                        help="replace an earlier scan's files in DIR although DIR holds other files (those are kept)")
    parser.add_argument("--save-projections", action="store_true",
                        help="also write the projections (line integrals) as DIR/projections.tif")
    parser.add_argument("--allow-starved", action="store_true",
                        help="scan even when over half the pixels the sample covers detect no photon (docs/scan.md)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("-v", "--verbose", action="store_true")
    parser.set_defaults(run=run)


def run(args) -> int:
    loaded = load_scan_file(args.scan)
    check_scan_output(args.out, overwrite=args.force, projections=args.save_projections,
                      extra_labels=loaded.options.labels[1:])
    result = scan(loaded, progress=not args.quiet, keep_projections=args.save_projections,
                  allow_starved=args.allow_starved)
    result.save(args.out, overwrite=args.force)
    meta = result.metadata
    stages = ", ".join(f"{stage} {s:.2f}" for stage, s in meta["seconds"].items())
    print(f"{args.out}: volume {'x'.join(map(str, meta['volume']['shape']))} ({meta['geometry']['num_views']} views); "
          f"seconds: {stages}; peak memory {meta['peak_rss_mib']:.0f} MiB")
    return 0
