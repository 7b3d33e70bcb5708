"""``xrayraster render SCENE.toml -o OUT.tif``: radiographs (or ``--path-lengths``) of a scene file's views."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from ..core.choices import OVERLAP_MODES, RADIOGRAPH_OUTPUTS
from ..core.errors import ConfigError
from ..core.estimate import plan
from ..core.projections import Projections
from ..core.tiff import quicklook_path
from ..io.scene_file import load_scene_file
from ..physics.detector import Detector
from ..physics.starvation import starved_share, warn_if_starved
from ..simulate.estimate import RenderJob
from ..simulate.renderer import Renderer
from .options import nonnegative_int, positive_int
from .outputs import check_outputs
from .views import parse_views


def add_parser(subparsers) -> None:
    render = subparsers.add_parser("render", help="render one or more views of a TOML scene")
    render.add_argument("scene", type=Path, help="scene file (docs/scene-format.md)")
    render.add_argument("-o", "--out", dest="out", metavar="OUT.tif", type=Path, required=True,
                        help="float32 TIFF to write (a PNG quick-look goes beside it)")
    render.add_argument("--output", choices=RADIOGRAPH_OUTPUTS, default=None,
                        help="radiograph quantity: raw detector signal, transmission, or lineint = -ln(transmission) (default lineint)")
    render.add_argument("--noise", action="store_true", help="add quantum (Poisson) and electronic noise")
    render.add_argument("--seed", type=nonnegative_int, default=None, help="noise seed (default 0; needs --noise)")
    render.add_argument("--path-lengths", action="store_true",
                        help="write per-material path lengths in mm instead of radiographs")
    render.add_argument("--views", default="0", help="comma-separated view indices, or 'all' (default: 0)")
    render.add_argument("--supersampling", type=positive_int, default=1, help="k×k rays per pixel (default 1)")
    render.add_argument("--overlap", choices=OVERLAP_MODES, default="auto", help="overlap handling (default auto)")
    render.add_argument("-v", "--verbose", action="store_true")
    render.set_defaults(run=run)


def run(args) -> int:
    check_outputs([args.out, quicklook_path(args.out)], [args.scene])
    if args.path_lengths:
        ignored = [flag for flag, given in (("--output", args.output is not None), ("--noise", args.noise),
                                             ("--seed", args.seed is not None)) if given]
        if ignored:
            raise ConfigError(f"{', '.join(ignored)} appl(y/ies) to radiographs, not to --path-lengths; drop one or the other")
        return _render_path_lengths(args)
    if args.seed is not None and not args.noise:
        raise ConfigError("--seed needs --noise (without noise the radiograph is the expected value)")
    return _render_radiographs(args)


def _render_path_lengths(args) -> int:
    loaded = load_scene_file(args.scene)
    geometry, scene = loaded.geometry, loaded.scene
    views = parse_views(args.views, geometry.num_views)
    _planned(views, geometry, scene, len(scene.materials), args.supersampling)
    start = time.perf_counter()
    with Renderer(geometry, supersampling=args.supersampling, overlap=args.overlap) as renderer:
        projections = renderer.path_lengths_all(scene, views)
    seconds = time.perf_counter() - start
    stack, method, driver = projections.data, projections.provenance["method"], projections.provenance["renderer"]
    out = _with_scene_file(projections, args.scene).save(args.out)
    png = quicklook_path(out)
    print(
        f"{out}: {len(views)} view(s) × {len(scene.materials)} material(s) × {stack.shape[2]}×{stack.shape[3]} "
        f"px, max {stack.max():.4f} mm, {method} pass, {seconds:.2f} s on {driver}; quick-look {png}"
    )
    return 0


def _planned(views: list[int], geometry, scene, channels: int, supersampling: int) -> None:
    """Refuse a stack that cannot fit in memory and print the estimate of a long render, before the GL starts."""
    plan(RenderJob(len(views), geometry.detector_shape, scene.num_triangles, channels, supersampling), ConfigError,
         announce=True)


def _render_radiographs(args) -> int:
    loaded = load_scene_file(args.scene)
    missing = [what for what, absent in (
        ("a [source] table (the X-ray spectrum)", loaded.spectrum is None),
        ("a [materials] table (composition and density of every object's material)", loaded.materials is None),
    ) if absent]
    if missing:
        raise ConfigError(
            f"{args.scene}: radiographs need {' and '.join(missing)}; add {'them' if len(missing) > 1 else 'it'} "
            "(docs/scene-format.md), or pass --path-lengths to write path lengths only"
        )
    geometry, scene, spectrum = loaded.geometry, loaded.scene, loaded.spectrum
    detector = loaded.detector if loaded.detector is not None else Detector()
    output = args.output or "lineint"
    # The flats' noise and the gain map are drawn from the seed, with or without the views' noise.
    seed = (0 if args.seed is None else args.seed) if args.noise or loaded.realism.needs_seed else None
    views = parse_views(args.views, geometry.num_views)
    _planned(views, geometry, scene, 1, args.supersampling)
    start = time.perf_counter()
    with Renderer(geometry, supersampling=args.supersampling, overlap=args.overlap) as renderer:
        projections = renderer.project_all(scene, spectrum, views, detector=detector, output=output, noise=args.noise,
                                           seed=seed, realism=loaded.realism)
    seconds = time.perf_counter() - start
    stack, units, facts = projections.data, projections.unit, projections.provenance
    starved, method, driver = facts["starved_pixels"], facts["method"], facts["renderer"]
    out = _with_scene_file(projections, args.scene).save(args.out)
    warn_if_starved(starved_share(facts["starved_covered_pixels"], facts["covered_pixels"]), str(args.scene))
    png = quicklook_path(out)
    extras = []
    if args.noise:
        extras.append(f"noise seed {seed}")
    if any(starved):
        extras.append(f"{sum(starved)} starved pixel(s) clamped ({', '.join(map(str, starved))} per view)")
    print(
        f"{out}: {len(views)} view(s) × {stack.shape[1]}×{stack.shape[2]} px {output} radiograph"
        f" [{units}], range {stack.min() + 0.0:.4g} to {stack.max() + 0.0:.4g}, {facts['bins_used'][0]} energy bins"
        + "".join(f", {e}" for e in extras)
        + f", {method} pass, {seconds:.2f} s on {driver}; quick-look {png}"
    )
    return 0


def _with_scene_file(projections: Projections, scene_file) -> Projections:
    return dataclasses.replace(projections, provenance={**projections.provenance, "scene_file": str(scene_file)})
