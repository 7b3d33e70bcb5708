"""``xrayraster fit`` against scans whose values it is not told: how close it comes, and how long it takes.

    python -m scripts.bench_fit            # four 256³ cases (~50 min on 2 cores)
    python -m scripts.bench_fit --cases woven   # one of them (~18 min)
    python -m scripts.bench_fit --quick    # the bundled small scan, one case (~15 s)

Each case makes a "real" scan with hidden values (its own noise seed), then fits the start scan file
to that volume, once with the real scan's label volume as the user's region labels and once
without. The start is the twin's scan file (``examples/twin.toml``) at half its size: 256² detector
pixels, 400 views, a 256³ grid. The cases:

* **twin**: fewer photons, a detector blur, a denser matrix and lighter wefts;
* **shifted scanner**: the scanner of ``examples/ml_shifted.toml`` (50 kV through 1 mm Al, told to
  the fit as a user knows the tube's settings), 0.6 mAs, a 40 µm focal spot, 10 noisy flats, 0.5 %
  gain variation and 0.5 px of blur, none of which the fit is told;
* **rings**: 1 % gain variation with a little blur;
* **woven**: another cell (wefts 16 % wider apart, warps 8 % closer, a thinner stack, other yarn
  widths and weft share) with a glass tracer weft, none of which the fit is told.

Printed per case: every fitted value against the hidden one, each figure's relative error before and
after, what was not fitted, and the seconds. Writes out/bench_fit.json.
"""

from __future__ import annotations

import copy
import tempfile
import time
import tomllib
from pathlib import Path

import tomli_w

import xrayraster as xr
from xrayraster.io.scan_keys import set_key

from .common import announce, conclude, outputs, parser, say

ROOT = Path(__file__).resolve().parents[1]
HALF_TWIN = {"geometry.detector_shape": [256, 256], "geometry.pixel_size": 0.269734, "geometry.num_views": 400,
             "volume.shape": [256, 256, 256], "volume.voxel_size": 0.1156}
CASES = {
    "twin": ({}, {"source.mas": 0.8, "detector.blur_sigma_px": 0.7, "materials.matrix.density": 1.12,
                  "materials.weft_carbon.density": 1.70}),
    "shifted scanner": ({"source.kvp": 50.0, "source.filters": {"Al": 1.0}},
                        {"source.mas": 0.6, "source.focal_spot_mm": 0.04, "detector.flat_fields": 10,
                         "detector.gain_variation": 0.005, "detector.blur_sigma_px": 0.5}),
    "rings": ({}, {"detector.gain_variation": 0.01, "detector.blur_sigma_px": 0.3}),
    "woven": ({}, {"weave.weft_spacing": 2.9, "weave.warp_spacing": 2.3, "weave.thickness": 3.75,
                   "weave.weft_width_fraction": 0.84, "weave.warp_width_fraction": 0.9, "weave.weft_share": 0.55,
                   "weave.materials.tracers": [{"yarn": "weft_c0_l1_y1",
                                                "material": {"fibre": "e_glass", "fibre_fraction": 0.6}}]}),
}
QUICK = {"small": ({"geometry.detector_shape": [44, 64], "volume.shape": [40, 64, 64], "source.mas": 0.0005},
                   {"source.mas": 0.0002, "detector.blur_sigma_px": 0.8, "materials.matrix.density": 1.15,
                    "detector.gain_variation": 0.003})}


def case(name: str, told: dict, hidden: dict, base: Path, folder: Path) -> dict:
    table = tomllib.loads(base.read_text())
    for key, value in told.items():
        set_key(table, key, value)
    start = folder / f"{name}_start.toml"
    start.write_text(tomli_w.dumps(table))
    real_table = copy.deepcopy(table)
    for key, value in hidden.items():
        set_key(real_table, key, value)
    set_key(real_table, "scan.seed", 1234)
    (folder / f"{name}_real.toml").write_text(tomli_w.dumps(real_table))
    t0 = time.perf_counter()
    real = xr.scan(folder / f"{name}_real.toml")
    scan_s = time.perf_counter() - t0
    row = {"case": name, "told": told, "hidden": hidden, "real_scan_s": scan_s}
    for mode, labels in (("labels", real.labels.data), ("mixture", None)):
        result = xr.fit(real.volume.data, start, labels=labels)
        fitted = {key: {"start": a, "fitted": b, "hidden": hidden.get(key, a)} for key, (a, b) in result.parameters.items()}
        row[mode] = {"fitted": fitted, "errors": result.errors, "not_fitted": result.unidentified,
                     "converged": result.converged, "runs": len(result.runs), "seconds": result.seconds,
                     "weave": result.weave}
        say(f"{name}, {mode}: {'converged' if result.converged else 'not converged'} in {len(result.runs)} runs, "
            f"{result.seconds:.0f} s (the real scan took {scan_s:.0f} s)")
        for key, values in fitted.items():
            off = values["fitted"] / values["hidden"] - 1 if values["hidden"] else values["fitted"]
            say(f"    {key}: start {values['start']:.5g}, fitted {values['fitted']:.5g}, hidden "
                f"{values['hidden']:.5g} ({off:+.1%})")
        say("    figures, start → fitted: " + ", ".join(f"{k} {a:+.1%} → {b:+.1%}" for k, (a, b) in result.errors.items()))
        say("    not fitted: " + "; ".join(f"{k}: {v}" for k, v in result.unidentified.items()))
        if result.weave:
            say(f"    the cell: agreement {result.weave['agreement']['start']:.3f} → "
                f"{result.weave['agreement']['fitted']:.3f} in {result.weave['seconds']:.0f} s; tracers "
                + (", ".join(f"{t['yarn']} at {t['fibre_fraction']:.3f}" for t in result.weave["tracers"]) or "none"))
    return row


def main() -> None:
    ap = parser(__doc__, "the bundled small scan, one case", plots=False)
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES), help="the 256³ cases to run")
    args = outputs(ap.parse_args(), "bench_fit")
    t_start = time.perf_counter()
    command, machine = announce()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.quick:
            base, cases = ROOT / "examples" / "scan_small.toml", QUICK
        else:
            table = tomllib.loads((ROOT / "examples" / "twin.toml").read_text())
            for key, value in HALF_TWIN.items():
                set_key(table, key, value)
            base, cases = folder / "half_twin.toml", {name: CASES[name] for name in args.cases}
            base.write_text(tomli_w.dumps(table))
        rows = []
        for name, (told, hidden) in cases.items():
            rows.append(case(name, told, hidden, base, folder))
    conclude(args.json, {"command": command, "machine": machine, "rows": rows}, machine, t_start)


if __name__ == "__main__":
    main()
