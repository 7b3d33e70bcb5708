"""``xrayraster weave WEAVE.toml -o DIR``: a woven sample's meshes, report, scene file and voxel grid.

What ``xr.weave(WEAVE.toml).save(DIR)`` does (:mod:`xrayraster.pipeline.woven`). ``DIR`` is built
under a temporary name and moved into place when complete; an existing ``DIR`` is replaced only if
it holds nothing but an earlier ``xrayraster weave`` output (``--force``: its files are replaced,
anything else in it is kept), which is checked before any work. It then holds
the mesh files, ``report.json``, ``scene.toml`` (``xrayraster render DIR/scene.toml``) and
``grid.json``, a grid file: the voxel grid over the sample at the scene's magnified pixel pitch
(``xrayraster voxelize DIR/scene.toml --grid DIR/grid.json``).
"""

from __future__ import annotations

import time
from pathlib import Path

from ..core.choices import EXPORT_PER, MESH_FORMATS, WEAVE_RESOLVE
from ..core.errors import WeaveError
from ..core.estimate import plan
from ..io.weave_file import load_weave_file
from ..pipeline.woven import GRID_NAME, SCENE_NAME, output_directory, weave
from ..weave.size import WeaveJob


def add_parser(subparsers) -> None:
    weave = subparsers.add_parser("weave", help="generate a woven sample (meshes, report, scene file) from a weave file")
    weave.add_argument("weave", type=Path, help="weave file (docs/weave.md): a [weave] table")
    weave.add_argument("-o", "--out", dest="out", metavar="DIR", type=Path, required=True,
                       help="output directory (replaced only if it holds nothing but an earlier xrayraster weave output)")
    weave.add_argument("--force", action="store_true",
                       help="replace an earlier weave's files in DIR although DIR holds other files (those are kept)")
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
    # WeaveError: the refusal Sample.parts would give the same meshes later (the file's sizes were planned as it
    # loaded, but --resolve boolean holds more).
    plan(WeaveJob(loaded.sample, args.resolve), WeaveError, announce=True)
    start = time.perf_counter()
    # Entered first: an output it may not replace is refused before any work.
    with output_directory(args.out, overwrite=args.force) as tmp:
        result = weave(loaded, per=args.per, fmt=args.format, resolve=args.resolve, progress=not args.quiet)
        result.write(tmp)
    report = result.report
    seconds = time.perf_counter() - start
    fractions = ", ".join(f"{k} {v:.3f}" for k, v in report["volume_fraction"].items())
    print(f"{args.out}: {len(report['parts'])} mesh files ({report['triangles']} triangles), {report['yarns']['total']} "
          f"yarns; volume fractions {fractions}; {seconds:.2f} s.\n  render:   xrayraster render "
          f"{args.out / SCENE_NAME} -o radiograph.tif\n  voxelize: xrayraster voxelize {args.out / SCENE_NAME} "
          f"--grid {args.out / GRID_NAME} -o labels.tif")
    return 0
