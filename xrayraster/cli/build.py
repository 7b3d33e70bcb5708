"""``xrayraster build DATASET.toml -o DIR``: a dataset of randomised labelled tomograms (docs/dataset.md).

Resumable: a rerun skips the finished samples and redoes partial ones; ``count`` may grow; any
other change of the dataset file against ``DIR`` is refused unless ``--force``. ``--plan`` draws and
checks every sample and prints their parameters with the predicted time and disk use, scanning
nothing; a line a sample as it is drawn, and above 50 samples the first 50 with the totals
extrapolated. Exit status 1 when a sample failed (``DIR/failed.csv`` says which and why); 2 when an
input is refused, before anything is written.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from ..core.errors import ConfigError
from ..dataset.build import build
from ..dataset.dataset_file import load_dataset_file
from ..dataset.plan import plan_lines
from .options import positive_int


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("build", help="a dataset: many randomised labelled tomograms from a dataset file")
    parser.add_argument("dataset", type=Path, help="dataset file (docs/dataset.md): a base scan, [dataset] and [vary]")
    parser.add_argument("-o", "--out", dest="out", metavar="DIR", type=Path,
                        help="output directory (resumed if it holds a build of the same dataset file)")
    parser.add_argument("--workers", type=positive_int, default=1,
                        help="processes building samples at once (default 1; each gets cores / N threads)")
    parser.add_argument("--dask", action="store_true", help="run the workers on a local Dask cluster of processes")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="join an existing Dask cluster (its workers write into DIR: a shared file system)")
    parser.add_argument("--plan", action="store_true",
                        help="draw and check every sample, print their parameters, time and disk use; build nothing")
    parser.add_argument("--force", action="store_true",
                        help="DIR holds a build of a changed dataset file: remove that build's samples and start again")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no line a sample")
    parser.add_argument("-v", "--verbose", action="store_true", help="one log line per sample, and tracebacks")
    parser.set_defaults(run=run)


def run(args) -> int:
    if not args.quiet:  # the build's line a sample, without the stages' own details (those with -v)
        logging.getLogger(build.__module__).setLevel(logging.INFO)
    dataset = load_dataset_file(args.dataset)
    if args.plan:
        for line in plan_lines(dataset):  # each sample's line as it is drawn (0.4 s a draw)
            print(line, flush=True)
        return 0
    if args.out is None:
        raise ConfigError("-o DIR is required: the directory to build into (or --plan, to build nothing)")
    report = build(dataset, args.out, workers=args.workers, dask=args.dask, scheduler=args.scheduler,
                   force=args.force, progress=not args.quiet)
    print(f"{report.directory}: {len(report.built)} samples built, {report.skipped} finished before, "
          f"{len(report.failed)} failed; {report.seconds:.1f} s"
          + (f" ({3600 * len(report.built) / report.seconds:.0f} samples/h)" if report.built and report.seconds else ""))
    if report.failed:
        print(f"xrayraster: error: {len(report.failed)} samples failed; see {report.directory / 'failed.csv'} "
              "(rerun the same command to retry them)", file=sys.stderr)
        return 1
    return 0
