"""What a stage reads from its surroundings: shader and kernel sources, free memory."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def read_shader(name: str) -> str:
    """Text of ``shaders/<name>`` (GLSL or OpenCL C), from the installed package or a checkout."""
    try:
        return resources.files("xrayraster.shaders").joinpath(name).read_text()
    except (ModuleNotFoundError, FileNotFoundError):
        # Running from a source checkout that is not installed: shaders/ sits beside the package.
        return (Path(__file__).resolve().parent.parent / "shaders" / name).read_text()


def available_memory() -> int | None:
    """Bytes of memory available to this process (Linux), or None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None
