"""Matrix voids: how long a population takes to draw, against how many voids and how far past the
asked volume fraction it lands.

    python -m scripts.bench_voids            # the default cell's 2 × 2 sample and a plain-weave laminate (~30 s)
    python -m scripts.bench_voids --quick    # the first two cases (~5 s)

Per case: ``Sample.void_meshes`` on the sample's yarn meshes (the default resolution), best of two
calls; the voids placed, the candidates' rate, and the error: the voids' meshed volume over the
matrix box against ``volume_fraction`` (the draw stops at the first void past it, so the error is
under one void's share). The label volume's fraction is checked on 20 seeds by
tests/weave/test_weave_voids.py.
"""

from __future__ import annotations

import time

import numpy as np

from xrayraster.weave import Sample, UnitCell
from xrayraster.weave.voids import Voids

from .common import announce, conclude, outputs, parser, pyplot, say

CASES = (  # name, cell, cells, voids
    ("layer_to_layer 2×2, 0.5 %", UnitCell(), (2, 2), Voids(0.005, 0.1)),
    ("layer_to_layer 2×2, 1 %", UnitCell(), (2, 2), Voids(0.01, 0.1)),
    ("layer_to_layer 2×2, 0.1 %, between yarns", UnitCell(), (2, 2), Voids(0.001, 0.06, placement="between_yarns")),
    ("layer_to_layer 2×2, 2 %", UnitCell(), (2, 2), Voids(0.02, 0.1)),
    ("plain 4×4, 4 plies, 0.4 mm faces, 0.2 %", UnitCell(family="plain", margin_z=0.4), (4, 4),
     Voids(0.002, 0.06, aspect=(1.5, 1.0, 0.7))),
)


def measure(name: str, cell: UnitCell, cells, voids: Voids) -> dict:
    sample = Sample(cell, cells=cells, voids=voids)
    pieces = sample.meshes()
    times, meshes = [], []
    for _ in range(2):
        start = time.perf_counter()
        meshes = sample.void_meshes(pieces)
        times.append(time.perf_counter() - start)
    box = float(np.prod(np.diff(sample.box, axis=0)))
    fraction = sum(m.volume for m in meshes) / box
    row = {"case": name, "voids": len(meshes), "seconds": min(times), "fraction": fraction,
           "asked": voids.volume_fraction, "error": fraction / voids.volume_fraction - 1,
           "yarn_triangles": sum(len(m.faces) for _, m in pieces)}
    say(f"{name}: {len(meshes)} voids in {row['seconds']:.2f} s ({len(meshes) / row['seconds']:.0f} a second); "
        f"fraction {fraction:.5f} for {voids.volume_fraction:g} asked (error {row['error']:+.2%})")
    return row


def plot(rows: list[dict], plots_dir) -> None:
    plt = pyplot()
    if plt is None:
        return
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for r in rows:
        ax.scatter(r["voids"], r["seconds"])
        ax.annotate(f"{r['case']}\nerror {r['error']:+.2%}", (r["voids"], r["seconds"]), fontsize=7,
                    xytext=(4, 2), textcoords="offset points")
    ax.set_xlabel("voids placed")
    ax.set_ylabel("seconds to draw them")
    ax.set_title("Matrix voids: draw time against count (error: the volume past the asked fraction)", fontsize=9)
    fig.tight_layout()
    path = plots_dir / "bench_voids.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    say(f"plot: {path}")


def main() -> None:
    args = outputs(parser(__doc__, "the first two cases", plots=True).parse_args(), "bench_voids")
    t_start = time.perf_counter()
    command, machine = announce()
    rows = [measure(*case) for case in (CASES[:2] if args.quick else CASES)]
    plot(rows, args.plots_dir)
    conclude(args.json, {"command": command, "machine": machine, "rows": rows}, machine, t_start)


if __name__ == "__main__":
    main()
