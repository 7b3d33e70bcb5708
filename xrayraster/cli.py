"""Command line: ``xrayraster render scene.toml -o out.tif --path-lengths``."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .config import ConfigError, load_scene_file
from .geometry import GeometryError
from .glcontext import GLContextError
from .io import write_quicklook, write_tiff
from .mesh import MeshError
from .render import Renderer, RenderError
from .scene import SceneError

USER_ERRORS = (ConfigError, GeometryError, GLContextError, MeshError, RenderError, SceneError)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="xrayraster", description="X-ray CT simulation from triangle meshes.")
    parser.add_argument("--version", action="version", version=f"xrayraster {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render one or more views of a TOML scene")
    render.add_argument("scene", type=Path, help="scene file (docs/scene-format.md)")
    render.add_argument("-o", "--output", type=Path, required=True, help="float32 TIFF to write (a PNG quick-look goes beside it)")
    render.add_argument("--path-lengths", action="store_true", help="write per-material path lengths in mm")
    render.add_argument("--views", default="0", help="comma-separated view indices, or 'all' (default: 0)")
    render.add_argument("--supersampling", type=int, default=1, help="k×k rays per pixel (default 1)")
    render.add_argument("--overlap", choices=("auto", "sum", "nested", "resolve"), default="auto", help="overlap handling (default auto)")
    render.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        return _render(args)
    except USER_ERRORS as exc:
        print(f"xrayraster: error: {exc}", file=sys.stderr)
        return 2


def _render(args) -> int:
    if not args.path_lengths:
        raise ConfigError("radiograph output needs the physics stage, which is not built yet; pass --path-lengths")
    loaded = load_scene_file(args.scene)
    geometry, scene = loaded.geometry, loaded.scene
    views = _views(args.views, geometry.num_views)
    start = time.perf_counter()
    with Renderer(geometry, supersampling=args.supersampling, overlap=args.overlap) as renderer:
        stack = np.stack([renderer.path_lengths(scene, v) for v in views])
        method, driver = renderer.last_method, renderer.gl.renderer
    seconds = time.perf_counter() - start
    info = {
        "quantity": "path length",
        "units": "mm",
        "axes": "view, material, row, col",
        "materials": [str(m) for m in scene.materials],
        "views": views,
        "geometry": repr(geometry[views]),
        "supersampling": args.supersampling,
        "method": method,
        "renderer": driver,
        "scene_file": str(args.scene),
    }
    out = write_tiff(args.output, stack, axes="TCYX", pixel_size_mm=geometry.pixel_size, info=info)
    png = write_quicklook(args.output.with_suffix(".png"), stack[0].sum(axis=0))
    print(
        f"{out}: {len(views)} view(s) × {len(scene.materials)} material(s) × {stack.shape[2]}×{stack.shape[3]} "
        f"px, max {stack.max():.4f} mm, {method} pass, {seconds:.2f} s on {driver}; quick-look {png}"
    )
    return 0


def _views(text: str, num_views: int) -> list[int]:
    if text == "all":
        return list(range(num_views))
    try:
        views = [int(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(f"--views must be comma-separated integers or 'all', got {text!r}") from None
    bad = [v for v in views if not 0 <= v < num_views]
    if bad:
        raise ConfigError(f"--views {bad} out of range: the scene has {num_views} views (0..{num_views - 1})")
    return views


if __name__ == "__main__":
    sys.exit(main())
