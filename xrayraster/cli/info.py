"""``xrayraster info [--json] [--no-bench]``: what a user asks first on a new machine.

One line each: the OpenGL context the renderer gets (backend, driver, version), the OpenCL devices
and the one the reconstruction picks, the memory, the software, and a short self-benchmark (views a
second of a small woven sample, FDK voxel updates a second), with the environment variables that
change the choice. A missing driver is a fact like any other: its line says so, with the fix the
package's own error names, and the command still exits 0; only bad arguments exit 2 (argparse).
"""

from __future__ import annotations

import ctypes
import dataclasses
import importlib.metadata
import json
import math
import os
import platform
import time

import numpy as np

from .. import __version__
from ..core.errors import GLContextError, OpenCLError
from ..core.geometry import ConeBeamGeometry, full_circle
from ..core.memory import available_memory
from ..core.transform import Transform
from ..core.volume import VolumeGeometry
from ..gl.context import GLContext
from ..gl.pathlengths import PathLengthRenderer
from ..recon import opencl  # called through the module, so a test can stand in for a machine without a driver
from ..recon.fdk import fdk
from ..weave.sample import Sample
from ..weave.spec import UnitCell

GL_ENV, CL_ENV = "XRAYRASTER_GL", "XRAYRASTER_CL_DEVICE"  # the package's own choices (gl/context.py, recon/opencl.py)
# Read by the drivers' loaders, not by xrayraster, yet they change which GL or OpenCL driver it gets
# (glvnd's EGL vendor, Mesa's Gallium driver, the OpenCL ICD loader, PoCL's devices, the GPUs CUDA
# and ROCm show): listed on their line when set, as the likely reason for a surprising choice.
LOADER_ENV = {
    "gl": ("__EGL_VENDOR_LIBRARY_FILENAMES", "__EGL_VENDOR_LIBRARY_DIRS", "EGL_PLATFORM", "LIBGL_ALWAYS_SOFTWARE",
           "GALLIUM_DRIVER", "MESA_LOADER_DRIVER_OVERRIDE"),
    "opencl": ("OCL_ICD_VENDORS", "OCL_ICD_FILENAMES", "POCL_DEVICES", "CUDA_VISIBLE_DEVICES", "ROCR_VISIBLE_DEVICES"),
}
DISTRIBUTIONS = ("numpy", "moderngl", "pyopencl", "trimesh", "manifold3d")  # what the GL, OpenCL and mesh work runs on

# The self-benchmark: small enough to take a few seconds on a 2-core CPU, big enough that start-up
# costs (shader and kernel compiles, uploads) are kept out of the times by a warm-up each.
BENCH_PIXELS = 256  # detector rows and columns
BENCH_VIEWS = 64  # over a full circle: rendered, then reconstructed
BENCH_VOXELS = 128  # the FDK grid's side
# Each figure is the best of several passes: another process's load only ever slows a pass down.
VIEW_PASSES = 2  # over every view
FDK_CALLS = 3  # warm calls (after one that builds the kernels; the first warm one was still up to 2x slower here)
BENCH_MU_PER_MM = 0.05  # turns the summed path lengths into line integrals; the FDK's time does not depend on it
# GL_NVX_gpu_memory_info's free video memory (kB), and GL_ATI_meminfo's free texture memory (kB, the first
# of four): the only ways OpenGL tells free GPU memory (NVIDIA; AMD). Mesa's llvmpipe offers neither.
GL_NVX_FREE_KB, GL_ATI_TEXTURE_FREE_KB = 0x9049, 0x87FC


def add_parser(subparsers) -> None:
    info = subparsers.add_parser("info", help="the GL and OpenCL devices picked, memory, versions and a short benchmark")
    info.add_argument("--json", action="store_true", help="one JSON object with the same facts (numbers as numbers)")
    info.add_argument("--no-bench", dest="bench", action="store_false",
                      help="skip the self-benchmark (a few seconds on a 2-core CPU)")
    info.add_argument("-v", "--verbose", action="store_true")
    info.set_defaults(run=run)


def run(args) -> int:
    gl, gl_error = open_gl()
    try:
        facts = {
            "gl": gl_facts(gl, gl_error),
            "opencl": opencl_facts(),
            "memory": memory_facts(),
            "host": host_facts(),
            "python": python_facts(),
        }
        facts["bench"] = bench(gl, facts["opencl"]["picked"]) if args.bench else None
    finally:
        if gl is not None:
            gl.release()
    if args.json:
        print(json.dumps(facts, indent=1))
    else:
        print("\n".join(lines(facts)))
    return 0


# -- facts ------------------------------------------------------------------------------------------


def open_gl() -> tuple[GLContext | None, str | None]:
    """The context a ``Renderer`` would get (the same backends, in the same order), or None and why."""
    try:
        return GLContext(), None
    except GLContextError as exc:
        return None, str(exc)


def gl_facts(gl: GLContext | None, error: str | None) -> dict:
    facts = {"backend": None, "renderer": None, "vendor": None, "version": None, "version_code": None,
             "free_video_memory_bytes": None, "error": error, "env": env_facts(GL_ENV, LOADER_ENV["gl"])}
    if gl is not None:
        with gl.current():
            info = gl.ctx.info
            facts.update(backend=gl.backend, renderer=info["GL_RENDERER"], vendor=info["GL_VENDOR"],
                         version=info["GL_VERSION"], version_code=gl.ctx.version_code,
                         free_video_memory_bytes=gl_free_video_memory_bytes(gl))
    return facts


def gl_integers(gl: GLContext, name: int, count: int = 1) -> list[int] | None:
    """``glGetIntegerv(name)``: ``count`` integers, or None where the driver lacks the entry point or
    does not know ``name``. moderngl answers only the names of its ``info``; this reaches the others."""
    with gl.current():
        get = gl.function("glGetIntegerv", None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_int)])
        if get is None:
            return None
        values = (ctypes.c_int * max(count, 4))()  # some names write four; never let the driver write past the end
        for _ in range(8):  # an error earlier work left pending would read as ours; each read clears one flag
            if gl.ctx.error == "GL_NO_ERROR":
                break
        get(name, values)
        known = gl.ctx.error == "GL_NO_ERROR"  # reading it also clears ours, which later GL calls would meet
    return list(values[:count]) if known else None


def gl_free_video_memory_bytes(gl: GLContext) -> int | None:
    """Free GPU memory as the GL driver reports it (NVIDIA, AMD), None where it cannot (Mesa's llvmpipe)."""
    extensions = gl.ctx.extensions
    name = (GL_NVX_FREE_KB if "GL_NVX_gpu_memory_info" in extensions
            else GL_ATI_TEXTURE_FREE_KB if "GL_ATI_meminfo" in extensions else None)
    values = gl_integers(gl, name) if name is not None else None
    return values[0] * 1024 if values and values[0] > 0 else None


def opencl_facts() -> dict:
    """Every OpenCL device and the one :func:`~xrayraster.recon.opencl.choose_device` picks (``None``
    and the package's error, with its fix, where there is no driver or none compiles)."""
    facts = {"devices": [], "picked": None, "error": None, "env": env_facts(CL_ENV, LOADER_ENV["opencl"])}
    try:
        facts["devices"] = [dataclasses.asdict(d) for d in opencl.list_devices()]
        facts["picked"] = dataclasses.asdict(opencl.choose_device()[0])
    except OpenCLError as exc:
        facts["error"] = str(exc)
    return facts


def env_facts(own: str, loaders: tuple[str, ...]) -> dict:
    """The package's variable (None when unset) and those of the loaders that are set."""
    return {own: os.environ.get(own), **{name: os.environ[name] for name in loaders if name in os.environ}}


def memory_facts() -> dict:
    try:  # POSIX; the total is for scale only
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        total = None
    return {"available_bytes": available_memory(), "total_bytes": total}


def host_facts() -> dict:
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"system": f"{platform.system()} {platform.release()}", "machine": platform.machine(),
            "cpu": cpu_model(), "cores": os.cpu_count(), "cores_usable": usable}


def cpu_model() -> str | None:
    """The CPU's name (Linux), which the benchmark's figures depend on; ``platform.processor()`` is often empty."""
    try:
        with open("/proc/cpuinfo") as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), None)
    except OSError:
        return platform.processor() or None


def python_facts() -> dict:
    versions = {}
    for name in DISTRIBUTIONS:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return {"python": platform.python_version(), "xrayraster": __version__, **versions}


# -- the self-benchmark -----------------------------------------------------------------------------


def bench_sample() -> tuple[Sample, Transform]:
    """One cell of the default angle-interlock weave (10 × 10 × 4 mm), meshed as coarsely as
    examples/scan_small.toml meshes it, and the transform that centres it on the rotation axis."""
    sample = Sample(UnitCell(), cells=(1, 1), points_per_section=12, samples_per_mm=2.0)
    return sample, Transform.translation(-np.mean(sample.box, axis=0))


def bench_geometry(box: np.ndarray) -> tuple[ConeBeamGeometry, VolumeGeometry]:
    """A square detector of :data:`BENCH_PIXELS` that sees the whole sample from every angle, as
    ``ConeBeamGeometry.framing`` places it (source at five radii, magnification 2), and a cubic grid
    of :data:`BENCH_VOXELS` across the circle the sample turns in."""
    radius = float(np.linalg.norm(np.ptp(box[:, :2], axis=0))) / 2
    sod, sdd = 5 * radius, 10 * radius
    pixel = 2.04 * sdd * radius / math.sqrt(sod * sod - radius * radius) / BENCH_PIXELS
    geometry = ConeBeamGeometry(sod, sdd, (BENCH_PIXELS, BENCH_PIXELS), pixel, full_circle(BENCH_VIEWS))
    return geometry, VolumeGeometry((BENCH_VOXELS,) * 3, 2 * radius / BENCH_VOXELS)


def bench(gl: GLContext | None, picked: dict | None) -> dict:
    """Render every view of the sample (path lengths, as ``xrayraster render --path-lengths --views all``)
    and reconstruct them with FDK on the picked device; each timed after a warm-up. Without GL the
    FDK reconstructs zeros of the same shape (its time does not depend on the values); a part whose
    driver is missing is None."""
    start = time.perf_counter()
    sample, centre = bench_sample()
    geometry, volume = bench_geometry(sample.box)
    facts = {"detector_pixels": BENCH_PIXELS, "views": BENCH_VIEWS, "voxels": BENCH_VOXELS, "triangles": None,
             "render_method": None, "views_per_s": None, "fdk_voxel_updates_per_s": None, "fdk_first_call_s": None,
             "view_passes": VIEW_PASSES, "fdk_calls": FDK_CALLS}
    lines = np.zeros((BENCH_VIEWS, BENCH_PIXELS, BENCH_PIXELS), np.float32)
    if gl is not None:
        facts.update(bench_views(gl, sample.scene(transform=centre), geometry, lines))
    if picked is not None:
        facts.update(bench_fdk(lines, geometry, volume, picked["index"]))
    facts["seconds"] = time.perf_counter() - start
    return facts


def bench_views(gl: GLContext, scene, geometry: ConeBeamGeometry, lines: np.ndarray) -> dict:
    """Views a second of :meth:`PathLengthRenderer.path_lengths`, every view read back to the host,
    the best of :data:`VIEW_PASSES` passes over every view; ``lines`` gets their line integrals for the FDK."""
    with PathLengthRenderer(geometry, context=gl) as renderer:
        renderer.path_lengths(scene, 0)  # compiles the shaders, uploads the meshes, settles the method
        passes = []
        for _ in range(VIEW_PASSES):
            start = time.perf_counter()
            for view in range(BENCH_VIEWS):
                lines[view] = BENCH_MU_PER_MM * renderer.path_lengths(scene, view).sum(axis=0)
            passes.append(time.perf_counter() - start)
        return {"triangles": scene.num_triangles, "render_method": renderer.last_method,
                "views_per_s": BENCH_VIEWS / min(passes)}


def bench_fdk(lines: np.ndarray, geometry: ConeBeamGeometry, volume: VolumeGeometry, device: str) -> dict:
    """FDK voxel updates a second (voxels × views / seconds of the whole warm ``xr.fdk``: filter,
    upload, backprojection, read-back), as BENCHMARKS.md counts them, the best of :data:`FDK_CALLS`;
    the first call, which builds the kernels, timed apart."""
    with opencl.CLContext(device) as cl:
        passes = []
        for _ in range(1 + FDK_CALLS):
            start = time.perf_counter()
            fdk(lines, geometry, volume, context=cl)
            passes.append(time.perf_counter() - start)
    return {"fdk_voxel_updates_per_s": math.prod(volume.shape) * BENCH_VIEWS / min(passes[1:]),
            "fdk_first_call_s": passes[0]}


# -- text -------------------------------------------------------------------------------------------


def lines(facts: dict) -> list[str]:
    out = [gl_line(facts["gl"]), opencl_line(facts["opencl"]), memory_line(facts["memory"], facts["gl"]),
           host_line(facts["host"]), python_line(facts["python"])]
    if facts["bench"] is not None:
        out.append(bench_line(facts["bench"], facts["gl"], facts["opencl"]))
    return out


def gl_line(gl: dict) -> str:
    forced = gl["env"][GL_ENV]
    how = f"{GL_ENV}={forced}: forced" if forced else f"{GL_ENV} unset: EGL, else OSMesa; egl or osmesa forces one"
    how += "".join(f"; {k}={v}" for k, v in gl["env"].items() if k != GL_ENV)
    if gl["backend"] is None:
        return f"gl: none: {gl['error']} ({how})"
    return f"gl: {gl['backend'].upper()}, {gl['renderer']} by {gl['vendor']}, OpenGL {gl['version']} ({how})"


def opencl_line(cl: dict) -> str:
    chosen = cl["env"][CL_ENV]
    how = (f"{CL_ENV}={chosen}" if chosen else f'{CL_ENV} unset: the fastest that compiles; "P:D" or part of a name '
                                               "picks one")
    how += "".join(f"; {k}={v}" for k, v in cl["env"].items() if k != CL_ENV)
    listing = ", ".join(f"{d['index']} {d['name']} ({d['kind']})" for d in cl["devices"])
    if cl["picked"] is None:
        found = f"; found {len(cl['devices'])}: {listing}" if cl["devices"] else ""
        return f"opencl: none: {cl['error']}{found} ({how})"
    p = cl["picked"]
    return (f"opencl: picked {p['index']} {p['name']} on {p['platform']} ({p['kind']}, {p['compute_units']} compute "
            f"units, {p['clock_mhz']} MHz, {gib(p['global_mem'])} GiB) of {len(cl['devices'])}: {listing} ({how})")


def memory_line(memory: dict, gl: dict) -> str:
    free, total = memory["available_bytes"], memory["total_bytes"]
    text = "memory: " + (f"{gib(free)} GiB free" if free is not None else "free unknown (no /proc/meminfo)")
    text += f" of {gib(total)} GiB" if total else ""
    if gl["free_video_memory_bytes"] is not None:
        text += f"; GPU (GL driver): {gib(gl['free_video_memory_bytes'])} GiB free"
    return text


def host_line(host: dict) -> str:
    return (f"host: {host['system']} {host['machine']}, {host['cores_usable']} CPU cores usable of {host['cores']}"
            + (f", {host['cpu']}" if host["cpu"] else ""))


def python_line(python: dict) -> str:
    others = ", ".join(f"{k} {v or 'missing'}" for k, v in python.items() if k not in ("python", "xrayraster"))
    return f"python: {python['python']}, xrayraster {python['xrayraster']}, {others}"


def bench_line(b: dict, gl: dict, cl: dict) -> str:
    side = f"{b['detector_pixels']}²"
    if b["views_per_s"] is None:
        views = "views: no GL"
    else:
        views = (f"{b['views_per_s']:.1f} views/s at {side} of a woven sample (1 cell, {b['triangles']} triangles, "
                 f"path lengths, {b['render_method']}, {gl['renderer']}, best of {b['view_passes']} passes)")
    if b["fdk_voxel_updates_per_s"] is None:
        recon = "FDK: no OpenCL device"
    else:
        recon = (f"FDK {b['fdk_voxel_updates_per_s'] / 1e9:.2f} G voxel updates/s ({b['voxels']}³ from {b['views']} "
                 f"views of {side}, {cl['picked']['name']}, best of {b['fdk_calls']} warm calls after one of "
                 f"{b['fdk_first_call_s']:.2f} s that builds the kernels)")
    return f"bench: {views}, {recon}; {b['seconds']:.1f} s in all"


def gib(nbytes: float) -> str:
    return f"{nbytes / 2**30:.1f}"
