"""A woven sample's size before it is meshed: its triangles, the memory and time they take.

Every yarn's tube has ``2 × points_per_section`` triangles a ring, and its rings come at about
``samples_per_mm`` a mm (dense in the binders' bends, sparse along straight yarns: the adaptive
spacing of :func:`~xrayraster.weave.sweep.adaptive_params`), so the sample has about
``TRIANGLES_PER_RING_MM × 2 · points_per_section · samples_per_mm`` triangles per mm of yarn, and its
yarn length is the cells' (wefts along x, warps along y) times the cells and layers of cells.
"""

from __future__ import annotations

from ..core.estimate import Estimate, Part

#: Triangles per (points of a section × samples per mm × mm of yarn): measured 0.38–0.62 on the
#: default cell (1 × 1 to 3 × 3 cells, 12–24 points, 2–8 samples a mm, with and without distortion).
TRIANGLES_PER_POINT_SAMPLE_MM = 0.5
#: Bytes a triangle holds: while the sample is meshed for a scene (the tubes, their clipped copies,
#: the scene's; ~360 B from the twin's scan, pipeline/plan.py), while ``xrayraster weave`` exports it
#: with overlaps left to priorities (the interpenetration measured and each family merged: 1.6 KB
#: measured at 6 × 6 cells, 602 k triangles, 1,063 MiB peak), and with ``resolve="boolean"`` (every
#: pair's boolean: ~2.1 KB at 8 × 8 cells, 2,316 MiB, BENCHMARKS.md bench_weave), rounded up.
BYTES_PER_TRIANGLE = {"meshes": 400, "priority": 1600, "boolean": 2500}
#: Seconds a triangle takes to sweep and clip (1.2e-5 to 4.5e-5 measured under load on 1 × 1 to
#: 3 × 3 cells, 7e-6 at 8 × 8), and the factor of a whole ``xrayraster weave`` export on top
#: (6 × 6 cells under load: 46 s, 7.6e-5 a triangle; booleans: 50 s for 8 × 8 cells, bench_weave).
SECONDS_PER_TRIANGLE = 1.5e-5
EXPORT_FACTOR = {"meshes": 1.0, "priority": 5.0, "boolean": 7.0}


def yarn_length_mm(sample) -> float:
    """The sample's yarns' summed length (mm) along their runs: wefts along x, warps along y."""
    c = sample.cell
    sx, sy, _ = c.size
    wefts = len(c.weft_layer_z) * len(c.weft_y)
    warps = len(c.binder_x) + len(c.stuffer_x) * len(c.stuffer_gaps)
    nx, ny = sample.cells
    return sample.layers_of_cells * nx * ny * (wefts * sx + warps * sy)


def estimated_triangles(sample) -> int:
    """About how many triangles the sample's yarns will have (module docstring), before meshing."""
    return int(TRIANGLES_PER_POINT_SAMPLE_MM * sample.points_per_section * sample.samples_per_mm
               * yarn_length_mm(sample))


def mesh_part(sample, bytes_per_triangle: int = BYTES_PER_TRIANGLE["meshes"]) -> Part:
    """The sample's meshes as a part of a job's memory, named after ``cells`` (their main knob)."""
    triangles = estimated_triangles(sample)
    layers = f", layers_of_cells = {sample.layers_of_cells}" if sample.layers_of_cells > 1 else ""
    return Part(f"meshes of ~{triangles:.2g} triangles", triangles * bytes_per_triangle,
                f"cells = {list(sample.cells)}{layers}",
                "use fewer cells (or layers_of_cells) or a coarser mesh (points_per_section, samples_per_mm)")


def weave_estimate(sample, resolve: str = "priority", export: bool = True) -> Estimate:
    """The time and memory of meshing the sample with overlaps left to priorities or resolved by
    booleans (``resolve``); ``export``: and measuring and writing it, as ``xrayraster weave`` does."""
    stage = resolve if export or resolve == "boolean" else "meshes"
    seconds = estimated_triangles(sample) * SECONDS_PER_TRIANGLE * EXPORT_FACTOR[stage]
    nx, ny = sample.cells
    return Estimate(f"woven sample of {nx} × {ny} × {sample.layers_of_cells} cells", seconds,
                    (mesh_part(sample, BYTES_PER_TRIANGLE[stage]),))
