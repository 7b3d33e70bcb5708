"""``xrayraster preview FILE.toml``: a live radiograph of a scene or scan file in a web page (docs/preview.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io.optional import optional_module
from ..preview.listen import MAX_PORT, check_listen


def add_parser(subparsers) -> None:
    preview = subparsers.add_parser("preview", help="tune a scan by looking at its radiographs, live, in a web page")
    preview.add_argument("file", type=Path, help="scene file (docs/scene-format.md), scan file (docs/scan.md) or "
                         "weave file (docs/weave.md: scanned with the tube xrayraster weave gives its scene file)")
    preview.add_argument("--host", default="127.0.0.1",
                         help="address to listen on (default 127.0.0.1: this machine only; reach it over SSH with "
                              "ssh -L 8000:127.0.0.1:8000). Any other needs the printed address's token")
    preview.add_argument("--port", type=port, default=8000, help="port (default 8000)")
    preview.add_argument("--open", action="store_true", help="open the page in this machine's web browser")
    preview.add_argument("-v", "--verbose", action="store_true")
    preview.set_defaults(run=run)


def port(text: str) -> int:
    """An argparse type: a TCP port, 1 to 65535."""
    lo, hi = 1, MAX_PORT
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"must be a port, an integer {lo} to {hi}, got {text!r}")
    return value


def run(args) -> int:
    for module in ("starlette", "uvicorn", "websockets"):
        optional_module(module, "preview", "xrayraster preview")
    from ..preview.server import serve

    check_listen(args.host, args.port)  # one line and exit 2, before the file is opened
    serve(args.file, host=args.host, port=args.port, open_browser=args.open)
    return 0
