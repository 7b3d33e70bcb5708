"""Text of the GLSL and OpenCL C sources in ``shaders/`` (shipped in the wheel as ``xrayraster.shaders``)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def read_shader(name: str) -> str:
    """Text of ``shaders/<name>`` (GLSL or OpenCL C), from the installed package or a checkout."""
    try:
        return resources.files("xrayraster.shaders").joinpath(name).read_text()
    except (ModuleNotFoundError, FileNotFoundError):
        # Running from a source checkout that is not installed: shaders/ sits beside the package.
        return (Path(__file__).resolve().parents[2] / "shaders" / name).read_text()
