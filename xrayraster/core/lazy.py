"""Public names of a package resolved on first use (PEP 562), so importing the package is cheap.

``import xrayraster`` would otherwise load numpy, trimesh, SpekPy and OpenCL (about a second)
before anything, the command line's signal handling included, can run.
"""

from __future__ import annotations

import importlib


def lazy_names(namespace: dict, homes: dict[str, tuple[str, ...]]):
    """The ``__getattr__`` and ``__dir__`` of the package whose globals are ``namespace``: ``homes``
    maps a module (relative to the package) to the public names it defines. A name is imported on
    first use, then kept in the package."""
    package = namespace["__name__"]
    home = {name: module for module, names in homes.items() for name in names}

    def __getattr__(name: str):
        if name not in home:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(home[name], package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(home))

    return __getattr__, __dir__
