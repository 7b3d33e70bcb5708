"""``xrayraster fit REAL.tif SCAN.toml -o FITTED.toml``: the scan file whose simulation looks like a
real reconstruction (docs/fit.md). Writes FITTED.toml, FITTED.fit.json (the report) and
FITTED.fit.png (real, starting and fitted histograms, noise spectra and edge profiles), each
atomically, after the checks every command makes (``cli.outputs``)."""

from __future__ import annotations

from pathlib import Path

from ..core.errors import ConfigError
from ..core.inputs import read_tiff_file
from ..pipeline.fit import fit
from ..pipeline.fit_report import report_paths, write_fit
from .options import positive_int
from .outputs import check_outputs


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("fit", help="fit a scan file to a real reconstruction: class attenuation, noise, "
                                               "sharpness, rings")
    parser.add_argument("real", type=Path, metavar="REAL.tif",
                        help="the real reconstruction (z, y, x; cm⁻¹) on the scan file's [volume] grid")
    parser.add_argument("scan", type=Path, metavar="SCAN.toml", help="a scan file describing the scanner and sample")
    parser.add_argument("-o", "--out", type=Path, required=True, metavar="FITTED.toml",
                        help="the fitted scan file; its report goes beside it (FITTED.fit.json, FITTED.fit.png)")
    parser.add_argument("--labels", type=Path, metavar="L.tif",
                        help="region labels of the real volume on the same grid (the scan's label values, 0 the air); "
                             "without them the classes come from a Gaussian mixture of the real volume's values")
    parser.add_argument("--keep-weave", action="store_true",
                        help="keep the [weave] cell as the file gives it (default: its spacings, thickness, yarn widths "
                             "and the weft's share are fitted to the real volume, and bright tracer yarns found)")
    parser.add_argument("--rounds", type=positive_int, default=3, help="rounds of updates at most (default 3)")
    parser.add_argument("-v", "--verbose", action="store_true")
    parser.set_defaults(run=run)


def run(args) -> int:
    if args.out.suffix.lower() != ".toml":
        raise ConfigError(f"-o {args.out}: the fitted scan file must end in .toml; use e.g. -o "
                          f"{args.out.with_suffix('.toml')}")
    inputs = [p for p in (args.real, args.scan, args.labels) if p is not None]
    check_outputs([args.out, *report_paths(args.out)], inputs, main_is_tiff=False)
    real, _ = read_tiff_file(args.real, "the real volume")
    labels = read_tiff_file(args.labels, "--labels")[0] if args.labels is not None else None
    result = fit(real, args.scan, labels=labels, rounds=args.rounds, weave=not args.keep_weave)
    written = write_fit(result, args.out, real_name=str(args.real), scan_name=str(args.scan))
    rows = [f"  {key}: {start:.6g} → {fitted:.6g}" for key, (start, fitted) in result.parameters.items()]
    errors = [f"  {name}: {_percent(a)} → {_percent(b)}" for name, (a, b) in result.errors.items()]
    if result.weave:
        agreement = result.weave["agreement"]
        rows.append(f"  the cell's labels agree with the real classes in {agreement['start']:.1%} → "
                    f"{agreement['fitted']:.1%} of the field of view")
        rows += [f"  tracer {t['yarn']}: {t['fibre']} fibres at {t['fibre_fraction']:.3g} of the yarn"
                 for t in result.weave["tracers"]]
    print(f"{args.out}: {'converged' if result.converged else 'not converged; the best run kept'} after "
          f"{len(result.runs)} runs in {result.seconds:.0f} s\n"
          "fitted:\n" + "\n".join(rows) + "\nrelative errors of the figures, start → fitted:\n" + "\n".join(errors)
          + "\nnot fitted:\n" + "\n".join(f"  {k}: {why}" for k, why in result.unidentified.items())
          + f"\nwrote {', '.join(map(str, written))}")
    return 0


def _percent(value: float) -> str:
    return "n/a" if value != value else f"{value:+.1%}"
