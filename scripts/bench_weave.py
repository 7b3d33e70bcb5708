"""Woven-sample benchmark: generation time, triangles and peak memory of ``xrayraster.weave`` beside TexGen.

The sample
----------
The default layer-to-layer angle-interlock cell (``UnitCell()``, 10 × 10 × 4 mm, the cell of
examples/weave.toml) tiled n × n for n = 1, 2, 4, 8, with the distortion amplitudes of
examples/weave.toml's ``[weave.distortion]`` (read from that file), ``seed=1``, at two resolutions:
*default* (``points_per_section=24``, ``samples_per_mm=4``) and *coarse* (12, 2). TexGen builds the
same layer-to-layer weave, undistorted (its layer-to-layer textile has no random distortions), with
its ``resolution`` (points per cross-section) 24 and 12 (references/texgen.py).

What is timed (one fresh child process per case)
------------------------------------------------
* **ready to scan**: ``Sample(UnitCell(), cells=(n, n), ..., distortion=D, seed=1).scene()``: every
  yarn swept and clipped to the box (manifold3d), the matrix box, the scene built. It does not
  measure the interpenetration (a scan needs none: the scene's priorities settle shared space).
* **boolean**: ``Sample(...).parts(per="yarn", resolve="boolean")`` from a fresh Sample: the yarns as
  above, then every pair of yarns made disjoint and the matrix cut out (``resolve_boolean``).
* **interpenetration**: ``interpenetration(Sample(...).meshes())`` (the ``before`` figure of the
  boolean); timed too, as the cost of measuring it (meshes and measure apart).
* **TexGen**: ``texgen_layer_to_layer(UnitCell(), (n, n), resolution)``; the time compared is
  TexGen's own (textile build plus its meshing, clipping and capping); the read-out of its meshes
  into numpy (SWIG iteration in Python) is reported apart, and its overlap measure is not timed.
Each case runs in its own child process (``python -m scripts.bench_weave --case KIND N RESOLUTION``),
so one case's memory cannot inflate another's. A child repeats its call up to 3 times while it has
spent under a time budget (ready to scan: 12 s; boolean and TexGen: 5 s) and reports the best; the
large cases run once, the interpenetration case always, and the table gives the count. Peak memory is the child's ``ru_maxrss`` (MiB)
after the case, beside the child's after its imports; TexGen's includes the read-out into trimesh
and its overlap measure.

Budget: a case whose predicted time exceeds ``--budget`` (default 120 s for one call) is skipped
and listed. The prediction is the same case at half the cells per side, times 5 (4× the cells;
3–5.5× measured from 2 × 2 to 4 × 4); a case whose smaller one was skipped or failed is skipped too.

The errors beside the times
---------------------------
* **Tessellation error** of our meshes (mm), predicted from geometry by
  :mod:`xrayraster.weave.tessellation` for the undistorted cell (the distortion's ±4 % section
  scale moves it by as much): ``section_error_mm`` (the largest gap between the k-point outline and
  the smooth section, over the weft's and the warp's) plus ``path_error_mm`` (the chords' sagitta on
  the binders' tightest bend, ``binder_bend_radius_mm``, at the warp's half height outside it). Their
  sum is the largest path-length error of one boundary crossing at normal incidence; a ray through
  a yarn crosses twice. TexGen has no such prediction; its error columns are its meshes'.
* **Interpenetration volume** (mm³): the volume yarns share, summed over intersecting pairs (ours:
  ``interpenetration``; ``after`` the boolean, measured as the resolved yarns' summed volume minus
  their union's, ``Resolved.excess``; TexGen: the peer's ``yarn_overlap``, over the
  meshes manifold3d accepts: the ones it refuses are counted and left out). Yarns that share space
  are not a scan error (the priorities decide) but a finite-element mesher needs them disjoint.
* TexGen's watertight fraction (trimesh) and the count of its meshes manifold3d refuses.

Usage::

    python -m scripts.bench_weave           # 7–9 min on 2 cores
    python -m scripts.bench_weave --quick   # 1 × 1 cell, coarse, one call each: a smoke test
    python -m scripts.bench_weave --self-check  # only the budget's predictions

Prints a table, writes out/bench_weave.json (``--quick``: out/bench_weave_quick.json) and plots
docs/bench_weave.png (``--quick``: out/bench_weave_quick.png).
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from scripts import common
from scripts.common import say

CELLS = (1, 2, 4, 8)  # cells per side
RESOLUTIONS = {"default": (24, 4.0), "coarse": (12, 2.0)}  # name: (points_per_section, samples_per_mm)
KINDS = ("scan", "interpenetration", "boolean", "texgen")
TARGETS_S = {"scan": 5.0, "boolean": 30.0}  # the targets for a 4 × 4-cell distorted sample
TARGET_CELLS = 4
REPEATS = 3
REPEAT_BUDGET_S = {"scan": 12.0, "boolean": 5.0, "texgen": 5.0}  # no call starts after this much time
CASE_BUDGET_S = 120.0  # default --budget: skip a case predicted to take longer (one call)
GROWTH = 5.0  # predicted time factor per doubling of the cells per side
WEAVE_FILE = common.ROOT / "examples" / "weave.toml"
SEED = 1
LABELS = {"scan": "ours, ready to scan", "interpenetration": "ours, interpenetration measure",
          "boolean": 'ours, resolve="boolean"', "texgen": "TexGen"}


# ---------------------------------------------------------------------------------------------
# Errors and the budget (parent side)
# ---------------------------------------------------------------------------------------------


def tessellation_error(points_per_section: int, samples_per_mm: float) -> dict:
    """Predicted tessellation error (mm) of the default cell at this resolution (module docstring)."""
    from xrayraster.weave import UnitCell
    from xrayraster.weave.tessellation import binder_bend_radius_mm, path_error_mm, section_error_mm

    cell = UnitCell()
    weft = section_error_mm(cell.weft_section, cell.weft_width, cell.weft_height, points_per_section)
    warp = section_error_mm(cell.warp_section, cell.warp_width, cell.warp_height, points_per_section)
    radius = binder_bend_radius_mm(cell)
    path = path_error_mm(radius, samples_per_mm, cell.warp_height / 2)
    return {"points_per_section": points_per_section, "samples_per_mm": samples_per_mm,
            "weft_section_mm": weft, "warp_section_mm": warp, "section_mm": max(weft, warp),
            "binder_bend_radius_mm": radius, "path_mm": path, "total_mm": max(weft, warp) + path}


def predicted_s(smaller: dict | None, n: int) -> float | None:
    """One call's predicted seconds at n cells per side from the same case at a smaller n (its record,
    None if it was not run): GROWTH per doubling; None without a smaller case; inf if it was skipped."""
    if smaller is None:
        return None
    if "call_s" not in smaller:
        return math.inf
    return smaller["call_s"] * GROWTH ** math.log2(n / smaller["cells"])


def self_check() -> bool:
    """Whether :func:`predicted_s` grows by GROWTH per doubling and skips after a skip (``--self-check``)."""
    smaller = {"cells": 2, "call_s": 3.0}
    checks = {"no smaller case, no prediction": predicted_s(None, 1) is None,
              "one doubling": math.isclose(predicted_s(smaller, 4), 3.0 * GROWTH),
              "two doublings": math.isclose(predicted_s(smaller, 8), 3.0 * GROWTH ** 2),
              "skipped after a skip": predicted_s({"cells": 4, "skipped": True}, 8) == math.inf}
    for name, ok in checks.items():
        say(f"budget self-check, {name}: {'ok' if ok else 'FAILED'}")
    return all(checks.values())


# ---------------------------------------------------------------------------------------------
# One case (child side)
# ---------------------------------------------------------------------------------------------


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux


def run_case(kind: str, n: int, resolution: str, repeats: int) -> dict:
    """Time one case in this process (meant to be a fresh child: see the module docstring)."""
    from xrayraster.io.weave_file import load_weave_file
    from xrayraster.weave import Sample, UnitCell, interpenetration

    k, rate = RESOLUTIONS[resolution]
    distortion = load_weave_file(WEAVE_FILE).sample.distortion
    if kind == "texgen":
        from references import texgen as texgen_peer

        reason = texgen_peer.texgen_available()  # loads pytexgen before the baseline is read
        if reason is not None:
            raise RuntimeError(reason)
    rec = {"kind": kind, "cells": n, "resolution": resolution, "load_1min": os.getloadavg()[0],
           "baseline_mib": _peak_mib()}

    def sample():
        return Sample(UnitCell(), cells=(n, n), points_per_section=k, samples_per_mm=rate, distortion=distortion,
                      seed=SEED)

    if kind == "scan":
        times, scene = common.repeat(lambda: sample().scene(), repeats, REPEAT_BUDGET_S[kind], free_previous=True)
        rec.update(seconds=min(times), all_s=times, call_s=sum(times) / len(times),
                   triangles=scene.num_triangles, yarns=len(scene.objects) - 1)
    elif kind == "interpenetration":
        t0 = time.perf_counter()
        pieces = sample().meshes()
        t1 = time.perf_counter()
        measure = interpenetration(pieces)
        t2 = time.perf_counter()
        rec.update(meshes_s=t1 - t0, seconds=t2 - t1, all_s=[t2 - t1], call_s=t2 - t0,
                   triangles=sum(len(m.faces) for _, m in pieces), yarns=len(pieces),
                   volume_mm3=measure.volume, pairs=measure.pairs, yarn_volume_mm3=measure.yarn_volume,
                   relative=measure.relative)
    elif kind == "boolean":
        times, (parts, facts) = common.repeat(lambda: sample().parts(per="yarn", resolve="boolean"), repeats,
                                                REPEAT_BUDGET_S[kind], free_previous=True)
        rec.update(seconds=min(times), all_s=times, call_s=sum(times) / len(times),
                   triangles=sum(len(p.mesh.faces) for p in parts), yarns=len(parts) - 1,
                   before_mm3=facts["interpenetration_mm3"]["before"], after_mm3=facts["interpenetration_mm3"]["after"],
                   dropped=len(facts["interpenetration_mm3"]["dropped_yarns"]))
    elif kind == "texgen":
        runs = []  # each call's figures, not its meshes: only one call's meshes are alive at a time

        def texgen():
            r = texgen_peer.texgen_layer_to_layer(UnitCell(), (n, n), k)
            runs.append({"seconds": r.seconds, "build_s": r.build_seconds, "mesh_s": r.mesh_seconds,
                         "readout_s": r.convert_seconds, "triangles": r.triangles, "yarns": len(r.meshes),
                         "watertight_fraction": r.watertight_fraction, "refused": r.refused,
                         "volume_mm3": r.interpenetration_mm3})

        walls, _ = common.repeat(texgen, repeats, REPEAT_BUDGET_S[kind])
        rec.update(min(runs, key=lambda r: r["seconds"]), all_s=[r["seconds"] for r in runs],
                   call_s=sum(walls) / len(walls))
    else:
        raise ValueError(f"unknown case kind {kind!r}; one of {KINDS}")
    rec["calls"] = len(rec["all_s"])
    rec["peak_mib"] = _peak_mib()
    return rec


def run_child(kind: str, n: int, resolution: str, repeats: int, timeout_s: float) -> dict:
    """:func:`run_case` in a fresh ``python -m scripts.bench_weave --case`` process; its record, or the error."""
    command = [sys.executable, "-m", "scripts.bench_weave", "--case", kind, str(n), resolution, "--repeats",
               str(repeats)]
    try:
        done = subprocess.run(command, cwd=common.ROOT, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return {"kind": kind, "cells": n, "resolution": resolution, "error": f"timed out after {timeout_s:.0f} s"}
    if done.returncode != 0:
        return {"kind": kind, "cells": n, "resolution": resolution,
                "error": f"exit {done.returncode}: " + done.stderr.strip()[-500:]}
    return json.loads(done.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------------------------
# Table, plot, main
# ---------------------------------------------------------------------------------------------


def _find(records: list[dict], kind: str, n: int, resolution: str) -> dict | None:
    return next((r for r in records if (r["kind"], r["cells"], r["resolution"]) == (kind, n, resolution)), None)


def _cell(rec: dict | None, text, width: int) -> str:
    """``text(rec)``, or what became of the case, right-aligned in ``width`` columns."""
    if rec is None:
        return f"{'—':>{width}}"
    if "skipped" in rec:
        return f"{'skipped':>{width}}"
    if "error" in rec:
        return f"{'failed':>{width}}"
    return text(rec)


def print_tables(records: list[dict], errors: dict, cells, resolutions) -> None:
    say("\nours (time: best of the calls; MiB: the child's peak, after its imports in brackets; "
        "interpenetration: before resolving, % of the yarns' volume)")
    say(f"  {'resolution':<28} {'cells':>5} │ {'ready to scan s':>17} {'triangles':>10} {'MiB':>12} │ "
        f"{'boolean s':>12} {'triangles':>10} {'MiB':>12} {'after mm³':>9} │ {'interpenetration':>22} "
        f"{'measure s':>10} │ tessellation mm")
    for res in resolutions:
        k, rate = RESOLUTIONS[res]
        for n in cells:
            scan, boolean, over = (_find(records, kind, n, res) for kind in ("scan", "boolean", "interpenetration"))
            say(f"  {f'{res} (k={k}, {rate:g}/mm)':<28} {f'{n}×{n}':>5} │ "
                + _cell(scan, lambda r: f"{r['seconds']:>11.2f} (×{r['calls']}) {r['triangles']:>10,} "
                        f"{r['peak_mib']:>6.0f} ({r['baseline_mib']:.0f})", 40) + " │ "
                + _cell(boolean, lambda r: f"{r['seconds']:>7.2f} (×{r['calls']}) {r['triangles']:>10,} "
                        f"{r['peak_mib']:>6.0f} ({r['baseline_mib']:.0f}) {r['after_mm3']:>9.1e}", 46) + " │ "
                + _cell(over, lambda r: f"{r['volume_mm3']:>9.2f} mm³ ({r['relative']:.2%}) "
                        f"{r['meshes_s']:>5.1f}+{r['seconds']:.1f}", 33) + " │ "
                + f"{errors[res]['total_mm']:.4f} ({errors[res]['section_mm']:.4f} + {errors[res]['path_mm']:.4f})")
    if not any(r["kind"] == "texgen" for r in records):
        return
    say("\nTexGen beside ours (TexGen s: build + mesh, its read-out into numpy apart; interpenetration over the "
        "meshes manifold3d accepts)")
    say(f"  {'resolution':<10} {'cells':>5} │ {'TexGen s':>13} {'read-out s':>10} {'triangles':>10} {'MiB':>6} "
        f"{'watertight':>10} {'refused':>8} {'interp. mm³':>11} │ {'ours scan s':>11} {'triangles':>10} "
        f"{'interp. mm³':>11}")
    for res in resolutions:
        for n in cells:
            tg, scan, over = (_find(records, kind, n, res) for kind in ("texgen", "scan", "interpenetration"))
            say(f"  {res:<10} {f'{n}×{n}':>5} │ "
                + _cell(tg, lambda r: f"{r['seconds']:>8.2f} (×{r['calls']}) {r['readout_s']:>10.2f} "
                        f"{r['triangles']:>10,} {r['peak_mib']:>6.0f} {r['watertight_fraction']:>10.1%} "
                        f"{r['refused']:>8} {r['volume_mm3']:>11.2f}", 74) + " │ "
                + _cell(scan, lambda r: f"{r['seconds']:>11.2f} {r['triangles']:>10,}", 22) + " "
                + _cell(over, lambda r: f"{r['volume_mm3']:>11.2f}", 11))


def targets(records: list[dict]) -> list[str]:
    """Lines on the issue's targets: a distorted 4 × 4 sample ready to scan < 5 s, with booleans < 30 s."""
    lines = []
    for res in RESOLUTIONS:
        for kind, limit in TARGETS_S.items():
            rec = _find(records, kind, TARGET_CELLS, res)
            if rec is not None and "seconds" in rec:
                verdict = "met" if rec["seconds"] < limit else "NOT met"
                lines.append(f"target {LABELS[kind]}, {TARGET_CELLS}×{TARGET_CELLS} cells, {res}: "
                             f"{rec['seconds']:.2f} s < {limit:g} s: {verdict}")
    return lines


def plot(records: list[dict], errors: dict, path: Path, title: str) -> Path | None:
    plt = common.pyplot()
    if plt is None:
        return None
    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(12, 6))
    styles = {"default": "-", "coarse": "--"}
    colours = {"scan": "C0", "boolean": "C1", "texgen": "C3"}
    for res, style in styles.items():
        k, rate = RESOLUTIONS[res]
        for kind, colour in colours.items():
            rs = sorted((r for r in records if r["kind"] == kind and r["resolution"] == res and "seconds" in r),
                        key=lambda r: r["cells"])
            if not rs:
                continue
            labels = ()  # at each point, the volume its yarns share
            if kind == "scan":
                name = f"ours ready to scan, k={k}, {rate:g}/mm: tessellation ≤ {errors[res]['total_mm']:.3f} mm"
                measured = [_find(records, "interpenetration", r["cells"], res) for r in rs]
                labels = [f"{m['volume_mm3']:.0f} mm³" if m and "volume_mm3" in m else "" for m in measured]
            elif kind == "boolean":
                name = f'ours resolve="boolean", k={k}, {rate:g}/mm: after ≤ {max(r["after_mm3"] for r in rs):.2g} mm³'
            else:
                name = f"TexGen, resolution {k}: {min(r['watertight_fraction'] for r in rs):.0%} of meshes watertight"
                labels = [f"{r['volume_mm3']:.0f} mm³" for r in rs]
            x = [r["cells"] for r in rs]
            common.curve(ax_t, x, [r["seconds"] for r in rs], labels, color=colour, ls=style, label=name,
                         offset=(5, -10 if res == "coarse" else 5))
            ax_m.plot(x, [r["peak_mib"] for r in rs], marker="o", color=colour, ls=style)
    for kind, limit in TARGETS_S.items():
        ax_t.axhline(limit, color=colours[kind], lw=0.8, ls=":", label=f"target: {TARGET_CELLS}×{TARGET_CELLS} "
                     f"{'ready to scan' if kind == 'scan' else 'with booleans'} < {limit:g} s")
    common.log_axes(ax_t, "cells (n × n)", "time (s), best of the calls", title, xbase=2, legend=None)
    common.log_axes(ax_m, "cells (n × n)", "peak resident memory of the child (MiB)",
                    "peak memory (a fresh process per case)", xbase=2, ylog=False, legend=None)
    cells = sorted({r["cells"] for r in records})
    for ax in (ax_t, ax_m):
        ax.set_xticks(cells, [f"{n}×{n}" for n in cells])
        ax.minorticks_off()
        if len(cells) == 1:
            ax.set_xlim(cells[0] / 1.6, cells[0] * 1.6)
    fig.legend(*ax_t.get_legend_handles_labels(), loc="lower center", bbox_to_anchor=(0.5, 0.03), ncol=3,
               fontsize=7, handlelength=3.5)
    fig.text(0.01, 0.005, "point labels: the volume the yarns share (interpenetration, mm³; ours before resolving, "
             "which a scan leaves to the scene's priorities; TexGen over the meshes manifold3d accepts)",
             fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    return common.save(fig, path)


def main(argv=None) -> int:
    ap = common.parser(__doc__, "1 × 1 cell at the coarse resolution, one call each: a smoke test")
    ap.add_argument("--cells", type=int, nargs="+", choices=CELLS, default=list(CELLS), help="cells per side")
    ap.add_argument("--resolutions", nargs="+", choices=list(RESOLUTIONS), default=list(RESOLUTIONS))
    ap.add_argument("--budget", type=float, default=CASE_BUDGET_S,
                    help="skip a case whose predicted time for one call exceeds this (s)")
    ap.add_argument("--no-texgen", action="store_true", help="do not run TexGen")
    ap.add_argument("--plot", type=Path, help="PNG (default docs/bench_weave.png; --quick: out/bench_weave_quick.png)")
    ap.add_argument("--case", nargs=3, metavar=("KIND", "N", "RESOLUTION"), help="internal: run one case in this "
                    "process and print its record as JSON")
    ap.add_argument("--repeats", type=int, default=REPEATS, help="calls per case at most (default 3; --quick: 1)")
    ap.add_argument("--self-check", action="store_true", help="only check the budget's predictions")
    args = common.outputs(ap.parse_args(argv), "bench_weave")
    if args.self_check:
        return 0 if self_check() else 1
    if args.case:
        kind, n, resolution = args.case
        print(json.dumps(run_case(kind, int(n), resolution, args.repeats)), flush=True)
        return 0
    cells = [1] if args.quick else sorted(args.cells)
    resolutions = ["coarse"] if args.quick else args.resolutions
    repeats = 1 if args.quick else args.repeats
    args.plot = args.plot or (common.OUT / "bench_weave_quick.png" if args.quick else common.DOCS / "bench_weave.png")

    start = time.perf_counter()
    command, machine = common.announce()
    from references import texgen as texgen_peer

    reason = "disabled (--no-texgen)" if args.no_texgen else texgen_peer.texgen_available()
    machine.update({dist: common.package_version(dist) for dist in ("pytexgen", "manifold3d", "trimesh")})
    say(f"manifold3d {machine['manifold3d']}, trimesh {machine['trimesh']}; "
        f"TexGen: {reason or 'pytexgen ' + str(machine['pytexgen'])}")
    from xrayraster.io.weave_file import load_weave_file

    distortion = load_weave_file(WEAVE_FILE).sample.distortion
    errors = {res: tessellation_error(*RESOLUTIONS[res]) for res in RESOLUTIONS}
    say(f"distortion (from {WEAVE_FILE.relative_to(common.ROOT)}), seed {SEED}: {distortion.to_dict()}")
    for res in resolutions:
        e = errors[res]
        say(f"tessellation error, {res}: {e['total_mm']:.4f} mm per crossing = section {e['section_mm']:.4f} (weft "
            f"{e['weft_section_mm']:.4f}, warp {e['warp_section_mm']:.4f}) + path {e['path_mm']:.4f} (binder bend "
            f"radius {e['binder_bend_radius_mm']:.3f} mm)")
    kinds = [kind for kind in KINDS if kind != "texgen" or reason is None]
    payload = {"command": command, "machine": machine,
               "settings": {"cells": cells, "resolutions": {r: RESOLUTIONS[r] for r in resolutions}, "seed": SEED,
                            "distortion": distortion.to_dict(), "repeats": repeats,
                            "repeat_budget_s": REPEAT_BUDGET_S, "budget_s": args.budget, "growth": GROWTH,
                            "targets_s": TARGETS_S, "quick": args.quick},
               "tessellation_error": errors, "texgen": {"available": reason is None, "reason": reason},
               "records": [], "skipped": []}
    records = payload["records"]
    for res in resolutions:
        for i, n in enumerate(cells):
            for kind in kinds:
                smaller = _find(records, kind, cells[i - 1], res) if i else None
                guess = predicted_s(smaller, n)
                if guess is not None and guess > args.budget:
                    records.append({"kind": kind, "cells": n, "resolution": res, "skipped": True,
                                    "predicted_s": guess})
                    payload["skipped"].append(f"{LABELS[kind]}, {n}×{n}, {res}: predicted {guess:.0f} s")
                    say(f"  skipped {LABELS[kind]}, {n}×{n}, {res}: predicted {guess:.0f} s > {args.budget:g} s")
                    continue
                rec = run_child(kind, n, res, repeats, timeout_s=3 * args.budget)
                rec["predicted_s"] = guess
                records.append(rec)
                if "error" in rec:
                    say(f"  {LABELS[kind]}, {n}×{n}, {res}: FAILED: {rec['error']}")
                else:
                    say(f"  {LABELS[kind]}, {n}×{n}, {res}: {rec['seconds']:.2f} s (×{rec['calls']}), "
                        f"{rec['triangles']:,} triangles, peak {rec['peak_mib']:.0f} MiB (load {rec['load_1min']:.2f})")
                common.write_json(args.json, payload)  # after every case: a cut-short run keeps its data

    print_tables(records, errors, cells, resolutions)
    for line in targets(records):
        say(line)
    if payload["skipped"]:
        say(f"skipped (predicted over {args.budget:g} s): " + "; ".join(payload["skipped"]))
    png = plot(records, errors, args.plot, "woven sample, default cell with the distortion of examples/weave.toml")
    if png:
        say(f"plot: {png}")
    common.conclude(args.json, payload, machine, start)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
