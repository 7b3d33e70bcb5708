"""The preview in a Jupyter notebook: ``xr.preview(path_or_scene)`` serves the page from a thread of
the kernel's process and shows it inline, in an IFrame on that server (one server a file, kept until
the kernel exits); outside a notebook it returns the running server, whose ``url`` a browser opens.

An in-memory :class:`~xrayraster.Scene` is written as a scene file first (its meshes to the last
bit, :mod:`xrayraster.io.scene_writer`) into a new folder, so the page edits, saves and renders it as
it does any scene file: the settings it saves name that folder's meshes, kept after the kernel exits.
"""

from __future__ import annotations

import atexit
import socket
import tempfile
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError
from ..core.geometry import ConeBeamGeometry
from ..io.scene_writer import write_scene_file
from ..io.weave_file import DEFAULT_SOURCE
from ..scene.scene import Scene
from .server import Background

_RUNNING: dict[str, Background] = {}


def preview(what, *, geometry=None, source: dict | None = None, directory=None, port: int | None = None,
            height: int = 900):
    """Serve the preview of ``what`` (once per file) and show it: an ``IPython.display.IFrame`` of
    the page where IPython is installed, else the :class:`~.server.Background` server itself.

    ``what``: a scene, scan or weave file, or an :class:`~xrayraster.Scene`. A scene is seen by
    ``geometry`` (default: a full circle framing it about the rotation axis,
    ``ConeBeamGeometry.framing``) with the tube ``source`` (a scene file's ``[source]`` table;
    default that of ``xrayraster weave``'s scene files: 40 kV, 2 mm Al, 1.25 mAs), written as
    ``scene.toml`` into ``directory`` (new or empty; default a new temporary folder).
    ``port``: default a free one."""
    if isinstance(what, Scene):
        what = _scene_file(what, geometry, source, directory)
    elif (geometry, source, directory) != (None, None, None):
        raise ConfigError("preview: geometry, source and directory are for an xr.Scene; a file sets its own "
                          "(edit them on the page, or in the file)")
    key = str(Path(what).resolve())
    server = _RUNNING.get(key)
    if server is None:
        server = _RUNNING[key] = Background(what, port=port or free_port())
        atexit.register(server.stop)
    try:
        from IPython.display import IFrame
    except ImportError:
        return server
    return IFrame(server.url, width="100%", height=height)


def free_port() -> int:
    """A TCP port free on the loopback now (the system's choice)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _scene_file(scene: Scene, geometry, source, directory) -> Path:
    if directory is None:
        directory = tempfile.mkdtemp(prefix="xrayraster-preview-")
    directory = Path(directory)
    if directory.exists() and (not directory.is_dir() or any(directory.iterdir())):
        raise ConfigError(f"preview: directory {str(directory)!r} is not an empty folder; give a new or empty one "
                          "for the scene file and its meshes (nothing there is overwritten)")
    if geometry is None:
        reach = np.abs(scene.bounds).max(axis=0)  # mm from the axis along x and y, from z = 0 along z
        geometry = ConeBeamGeometry.framing(float(np.hypot(reach[0], reach[1])), float(reach[2]))
    return write_scene_file(directory / "scene.toml", scene, geometry,
                            source=dict(DEFAULT_SOURCE) if source is None else source)
