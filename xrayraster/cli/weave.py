"""``xrayraster weave WEAVE.toml -o DIR``: a woven sample's meshes, report, scene file and voxel grid.

``DIR`` is built under a temporary name and moved into place when complete
(:func:`~xrayraster.core.files.atomic_directory`); an existing ``DIR`` is replaced only if it holds
an earlier ``xrayraster weave`` output. It then holds the mesh files, ``report.json``,
``scene.toml`` (``xrayraster render DIR/scene.toml``) and ``scan.json``, a voxel grid over the
sample at the scene's magnified pixel pitch (``xrayraster voxelize DIR/scene.toml --scan-file
DIR/scan.json``).
"""

from __future__ import annotations

import time
from pathlib import Path

from ..core.choices import EXPORT_PER, MESH_FORMATS, WEAVE_RESOLVE
from ..core.files import atomic_directory
from ..io.weave_file import framing_geometry, load_weave_file, sample_grid, write_scan_file, write_scene_file
from ..weave.export import is_export
from ..weave.size import weave_estimate

SCENE_NAME, SCAN_NAME = "scene.toml", "scan.json"


def add_parser(subparsers) -> None:
    weave = subparsers.add_parser("weave", help="generate a woven sample (meshes, report, scene file) from a weave file")
    weave.add_argument("weave", type=Path, help="weave file (docs/weave.md): a [weave] table")
    weave.add_argument("-o", "--out", dest="out", metavar="DIR", type=Path, required=True,
                       help="output directory (replaced only if it holds an earlier xrayraster weave output)")
    weave.add_argument("--per", choices=EXPORT_PER, default="family",
                       help="one mesh file per yarn family (default) or per yarn")
    weave.add_argument("--format", choices=MESH_FORMATS, default="stl", help="mesh file format (default stl)")
    weave.add_argument("--resolve", choices=WEAVE_RESOLVE, default="priority",
                       help="priority (default: overlaps settled by the scene's priorities, as the renderer does) "
                            "or boolean (disjoint meshes, for finite-element tools)")
    weave.add_argument("--quiet", action="store_true", help="no progress bar")
    weave.add_argument("-v", "--verbose", action="store_true")
    weave.set_defaults(run=run)


def run(args) -> int:
    loaded = load_weave_file(args.weave)
    weave_estimate(loaded.sample, args.resolve).announce()
    start = time.perf_counter()
    with atomic_directory(args.out, replaceable=is_export) as tmp:
        report = loaded.sample.export(tmp, materials=loaded.materials, per=args.per, fmt=args.format,
                                      resolve=args.resolve, progress=not args.quiet)
        geometry = framing_geometry(report["box_mm"])
        write_scene_file(tmp / SCENE_NAME, report, geometry)
        write_scan_file(tmp / SCAN_NAME, sample_grid(report["box_mm"], geometry))
    seconds = time.perf_counter() - start
    fractions = ", ".join(f"{k} {v:.3f}" for k, v in report["volume_fraction"].items())
    print(f"{args.out}: {len(report['parts'])} mesh files ({report['triangles']} triangles), {report['yarns']['total']} "
          f"yarns; volume fractions {fractions}; {seconds:.2f} s.\n  render:   xrayraster render "
          f"{args.out / SCENE_NAME} -o radiograph.tif\n  voxelize: xrayraster voxelize {args.out / SCENE_NAME} "
          f"--scan-file {args.out / SCAN_NAME} -o labels.tif")
    return 0
