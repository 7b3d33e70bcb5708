"""The preview in a Jupyter notebook: ``xr.preview(path)`` serves the page from a thread of the
kernel's process and shows it inline, in an IFrame on that server (one server a file, kept until
the kernel exits); outside a notebook it returns the running server, whose ``url`` a browser opens."""

from __future__ import annotations

import atexit
import socket
from pathlib import Path

from .server import Background

_RUNNING: dict[str, Background] = {}


def preview(path, *, port: int | None = None, height: int = 900):
    """Serve the preview of the scene or scan file ``path`` (once per file) and show it: an
    ``IPython.display.IFrame`` of the page where IPython is installed, else the
    :class:`~.server.Background` server itself. ``port``: default a free one."""
    key = str(Path(path).resolve())
    server = _RUNNING.get(key)
    if server is None:
        server = _RUNNING[key] = Background(path, port=port or free_port())
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
