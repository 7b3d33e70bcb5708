"""What every benchmark script shares: the machine it ran on, timing, JSON results, time-vs-error plots.

Nothing here imports a peer (gvxr, RTK, VTK) or matplotlib at import time: the peers live in
:mod:`scripts.peers` and load their libraries on first use, matplotlib is loaded by
:func:`pyplot` when a plot is drawn.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shlex
import sys
import tempfile
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

import xrayraster as xr

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "out"  # JSON results, caches and the plots of --quick runs
DOCS = ROOT / "docs"  # the published plots (BENCHMARKS.md shows them)

# Peer (machine-info key, distribution name): their versions are read without importing them.
PEERS = (("gvxr", "gvxr"), ("rtk", "itk-rtk"), ("vtk", "vtk"))


def say(*args) -> None:
    print(*args, flush=True)


# ---------------------------------------------------------------------------------------------
# Command line and output paths
# ---------------------------------------------------------------------------------------------


def command_line() -> str:
    """How this process was started, as a shell command (``python -m scripts.x ...`` for modules)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    argv = [sys.executable, "-m", spec.name, *sys.argv[1:]] if spec is not None else [sys.executable, *sys.argv]
    return shlex.join(argv)


def parser(doc: str, quick_help: str, *, plots: bool = False) -> argparse.ArgumentParser:
    """An argument parser with the options every script has: ``--quick`` and ``--json``, and with
    ``plots``, ``--plots-dir``. :func:`outputs` fills in their defaults."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=quick_help)
    ap.add_argument("--json", type=Path, help="results file (default out/NAME.json; --quick: out/NAME_quick.json)")
    if plots:
        ap.add_argument("--plots-dir", type=Path, help="where the PNG plots go (default docs/; --quick: out/, so a smoke "
                        "test never overwrites the published plots)")
    return ap


def outputs(args: argparse.Namespace, name: str) -> argparse.Namespace:
    """Default ``args.json`` (and ``args.plots_dir`` where the parser has it) for script ``name``."""
    args.json = args.json or json_path(name, args.quick)
    if hasattr(args, "plots_dir"):
        args.plots_dir = args.plots_dir or plots_dir(args.quick)
    return args


def json_path(name: str, quick: bool) -> Path:
    """out/NAME.json, or out/NAME_quick.json for a smoke test (never overwrites a full run's)."""
    return OUT / f"{name}{'_quick' if quick else ''}.json"


def plots_dir(quick: bool) -> Path:
    """docs/ for a full run (BENCHMARKS.md shows those plots), out/ for a smoke test."""
    return OUT if quick else DOCS


def write_json(path: Path, payload: dict) -> None:
    """Write atomically: a reader never sees a half-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(payload, f, indent=1)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


# ---------------------------------------------------------------------------------------------
# Machine
# ---------------------------------------------------------------------------------------------


def cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), "unknown")
    except OSError:
        return platform.processor() or "unknown"


def cores() -> int:
    """CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def package_version(distribution: str) -> str | None:
    try:
        return version(distribution)
    except PackageNotFoundError:
        return None


def machine_info(gl: xr.GLContext | None = None, cl: xr.CLContext | None = None) -> dict:
    """CPU, cores, Python and package versions, the GL renderer and OpenCL device in use, load."""
    info = {"cpu": cpu_name(), "nproc": cores(), "python": platform.python_version(), "numpy": np.__version__,
            "xrayraster": xr.__version__, "platform": platform.platform()}
    if gl is not None:
        info.update(gl_renderer=gl.ctx.info["GL_RENDERER"], gl_version=gl.ctx.info["GL_VERSION"], gl_backend=gl.backend)
    if cl is not None:
        info.update(opencl_device=str(cl.info), pyopencl=package_version("pyopencl"))
    info.update({key: package_version(dist) for key, dist in PEERS})
    info["loadavg_start"] = os.getloadavg()
    return info


def print_machine(machine: dict, command: str) -> None:
    say(f"command: {command}")
    line = f"machine: {machine['cpu']}, {machine['nproc']} CPUs"
    if "gl_renderer" in machine:
        line += f"; GL: {machine['gl_renderer']} ({machine['gl_version']}, {machine['gl_backend']})"
    if "opencl_device" in machine:
        line += f"; OpenCL: {machine['opencl_device']} (pyopencl {machine['pyopencl']})"
    say(line)
    say(f"python {machine['python']}, numpy {machine['numpy']}, xrayraster {machine['xrayraster']}; peers installed: "
        + ", ".join(f"{dist} {machine[key]}" for key, dist in PEERS))
    say("load average at start (1/5/15 min): " + ", ".join(f"{x:.2f}" for x in machine["loadavg_start"])
        + " (times are only comparable on an otherwise idle machine)")


def finish(machine: dict) -> str:
    """Record the load at the end in ``machine``; the line that reports it."""
    machine["loadavg_end"] = os.getloadavg()
    return "load average at end (1/5/15 min): " + ", ".join(f"{x:.2f}" for x in machine["loadavg_end"])


def announce(gl: xr.GLContext | None = None, cl: xr.CLContext | None = None) -> tuple[str, dict]:
    """(command line, machine info) of this run, both printed: the first lines of a script's output."""
    command = command_line()
    machine = machine_info(gl=gl, cl=cl)
    print_machine(machine, command)
    return command, machine


def conclude(path: Path, payload: dict, machine: dict, t_start: float, *, top_level_load: bool = False) -> None:
    """The last lines of a run: its total time (``payload["total_s"]``, from ``t_start``,
    perf_counter), the load at the end, the results written to ``path``. ``top_level_load``:
    also copy the end load to ``payload["loadavg_end"]``."""
    payload["total_s"] = time.perf_counter() - t_start
    say(finish(machine))
    if top_level_load:
        payload["loadavg_end"] = machine["loadavg_end"]
    write_json(path, payload)
    say(f"results: {path}")
    say(f"total {payload['total_s']:.1f} s")


# ---------------------------------------------------------------------------------------------
# Timing
# ---------------------------------------------------------------------------------------------


def repeat(fn, repeats: int, budget_s: float = math.inf, *, free_previous: bool = False) -> tuple[list[float], object]:
    """(seconds of each call, last result): up to ``repeats`` calls of ``fn()``, fewer once
    ``budget_s`` is spent. ``free_previous``: drop the previous result before the next call
    starts (for outputs too large to hold twice); otherwise it is freed when the new one is
    assigned, inside the timed span."""
    times, out, start = [], None, time.perf_counter()
    for _ in range(repeats):
        if free_previous:
            out = None
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
        if time.perf_counter() - start > budget_s:
            break
    return times, out


def best_of(fn, repeats: int, budget_s: float = math.inf) -> tuple[float, object]:
    """(best seconds, last result) of :func:`repeat`."""
    times, out = repeat(fn, repeats, budget_s)
    return min(times), out


def median_of(fn, repeats: int, budget_s: float = math.inf) -> tuple[float, object]:
    """(median seconds, last result) of :func:`repeat`."""
    times, out = repeat(fn, repeats, budget_s)
    return float(np.median(times)), out


def next_fits(start: float, done: int, budget_s: float) -> bool:
    """After ``done`` equal steps since ``start`` (perf_counter), would one more stay in ``budget_s``?"""
    return (time.perf_counter() - start) * (done + 1) / done <= budget_s


# ---------------------------------------------------------------------------------------------
# Plots (matplotlib, loaded on first use)
# ---------------------------------------------------------------------------------------------


def pyplot():
    """matplotlib.pyplot on the Agg backend, or None (and a line saying so) without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        say(f"plots skipped: matplotlib unavailable ({exc})")
        return None
    return plt


def curve(ax, x, y, labels=(), *, color, marker="o", label=None, offset=(4, 4), fontsize=7, **style) -> None:
    """One series, each point annotated with its entry of ``labels`` (e.g. the error beside a time)."""
    ax.plot(x, y, marker=marker, color=color, label=label, **style)
    for text, xi, yi in zip(labels, x, y):
        ax.annotate(text, (xi, yi), textcoords="offset points", xytext=offset, fontsize=fontsize, color=color)


def log_axes(ax, xlabel: str, ylabel: str, title: str | None = None, *, xbase: float = 10, ylog: bool = True,
             legend: int | None = 7) -> None:
    """Log-log (``ylog=False``: log-linear) axes with labels, a grid and a legend (``legend``: its font size; None: none)."""
    ax.set_xscale("log", base=xbase)
    if ylog:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    if legend:
        ax.legend(fontsize=legend)


def save(fig, path: Path) -> Path:
    """Write ``fig`` as PNG (110 dpi) and close it."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
