"""Where a scan's time goes: each stage of ``xr.scan`` and, inside it, each pass.

    python -m scripts.profile_scan                          # examples/twin_small.toml (~10 s)
    python -m scripts.profile_scan examples/twin.toml       # the reference twin (~4 min on 2 cores)
    python -m scripts.profile_scan --quick                  # the same small twin, a smoke test

Runs ``xr.scan`` on the scan file once (after a warm-up scan when ``--warm``), with timers around
its passes. A timed GL or OpenCL pass first waits for the work queued before it and then for its
own (``glFinish``, ``queue.finish``), so each is charged its own work: a profile, a little slower
than a plain run. The stages are those ``scan.json`` reports (``seconds``); the passes:

* **sample**: meshing the weave (or loading the meshes);
* **projections**: the GL crossing passes of every view (``CrossingEngine._record``: the compute
  pass over the triangles and the rasterised pass of the large ones), the overlap pass that sorts
  and sweeps each pixel's crossings (``_resolve``), the CPU physics (``radiograph``: spectral sums,
  noise, flat and log), and the rest (read-back, per-view set-up, the starvation check);
* **fdk**: filtering (weights, ramp, padding), backprojection, and the rest (set-up, copies,
  the result);
* **labels**: the label pass (its own crossing lists and sweep).

Prints the table and writes out/profile_scan.json (``--quick``: out/profile_scan_quick.json).
There is nothing to compare against here, so no error column: the scan's own outputs are those
of a plain run (the timers only wait).
"""

from __future__ import annotations

import functools
import importlib
import time
from contextlib import contextmanager
from pathlib import Path

import xrayraster as xr
from xrayraster.gl.crossings import CrossingEngine
from xrayraster.pipeline import load_scan_file
from xrayraster.recon.fdk_stream import FDKStream

from .common import ROOT, announce, conclude, outputs, parser, say

STAGES = ("sample", "projections", "fdk", "labels")
# The modules themselves (the package re-exports a function named scan over its module).
scan_module = importlib.import_module("xrayraster.pipeline.scan")
renderer_module = importlib.import_module("xrayraster.simulate.renderer")


class Profile:
    """Seconds and calls per (stage, pass); the stage is the one ``xr.scan`` is in."""

    def __init__(self):
        self.stage = "setup"
        self.seconds: dict[tuple[str, str], float] = {}
        self.calls: dict[tuple[str, str], int] = {}

    def add(self, name: str, seconds: float) -> None:
        key = (self.stage, name)
        self.seconds[key] = self.seconds.get(key, 0.0) + seconds
        self.calls[key] = self.calls.get(key, 0) + 1


def _timing(original, name: str, profile: Profile, wait):
    """``original`` timed under ``name``, calling ``wait(first argument or None)`` before and after."""

    @functools.wraps(original)
    def timed(*args, **kwargs):
        wait(args[0] if args else None)
        start = time.perf_counter()
        result = original(*args, **kwargs)
        wait(args[0] if args else None)
        profile.add(name, time.perf_counter() - start)
        return result

    return timed


@contextmanager
def instrumented(profile: Profile):
    """Timers around the passes (module docstring), the stage tracked through scan's ``_timed``;
    everything restored on leaving."""
    original_stage = scan_module._timed

    @contextmanager
    def staged(seconds, stage):
        outer, profile.stage = profile.stage, stage
        try:
            with original_stage(seconds, stage):
                yield
        finally:
            profile.stage = outer

    gl_wait = lambda engine: engine.gl.ctx.finish()  # noqa: E731 - one line each
    cl_wait = lambda stream: stream.ctx.queue.finish()  # noqa: E731
    patches = [(scan_module, "_timed", staged),
               *((owner, attribute, _timing(getattr(owner, attribute), name, profile, wait))
                 for owner, attribute, name, wait in (
                     (CrossingEngine, "_record", "GL crossing passes", gl_wait),
                     (CrossingEngine, "_resolve", "GL overlap/label pass", gl_wait),
                     (renderer_module, "radiograph", "CPU physics", lambda _: None),
                     (FDKStream, "_filter", "filtering", cl_wait),
                     (FDKStream, "_backproject", "backprojection", cl_wait)))]
    originals = [(owner, attribute, getattr(owner, attribute)) for owner, attribute, _ in patches]
    try:
        for owner, attribute, value in patches:
            setattr(owner, attribute, value)
        yield profile
    finally:
        for owner, attribute, value in originals:
            setattr(owner, attribute, value)


def main(argv=None) -> None:
    ap = parser(__doc__, "the small twin (the default file), no warm-up")
    ap.add_argument("scan_file", nargs="?", type=Path, default=ROOT / "examples" / "twin_small.toml")
    ap.add_argument("--warm", action="store_true", help="scan once first (compiled shaders and kernels, caches)")
    args = outputs(ap.parse_args(argv), "profile_scan")
    t_start = time.perf_counter()
    command, machine = announce()
    loaded = load_scan_file(args.scan_file)
    if args.warm and not args.quick:
        xr.scan(loaded)
    with instrumented(Profile()) as profile:
        result = xr.scan(loaded)
    stages = result.metadata["seconds"]
    say(f"{args.scan_file.name}: {result.metadata['triangles']} triangles, {loaded.geometry.num_views} views of "
        f"{loaded.geometry.detector_shape[0]}×{loaded.geometry.detector_shape[1]}, grid {loaded.volume.shape}")
    say(f"{'stage':<12} {'pass':<24} {'s':>8} {'share':>6} {'calls':>6} {'ms a call':>10}")
    rows = []
    for stage in STAGES:
        passes = {name: s for (st, name), s in profile.seconds.items() if st == stage}
        entries = [*passes.items(), ("rest", stages[stage] - sum(passes.values()))]
        for name, seconds in entries:
            calls = profile.calls.get((stage, name), 0)
            rows.append({"stage": stage, "pass": name, "seconds": seconds, "calls": calls})
            per_call = f"{1e3 * seconds / calls:.2f}" if calls else ""
            say(f"{stage:<12} {name:<24} {seconds:>8.3f} {seconds / stages['total']:>6.1%} {calls or '':>6} {per_call:>10}")
    say(f"{'total':<12} {'':<24} {stages['total']:>8.3f}")
    conclude(args.json, {"command": command, "machine": machine, "scan_file": str(args.scan_file), "rows": rows,
                         "stages_s": stages}, machine, t_start)


if __name__ == "__main__":
    main()
