"""The preview's web server: Starlette on uvicorn, the page and its assets from the package, frames
over a WebSocket.

* ``GET /``: the page (``static/index.html``); ``/static/...``: its script and style (package data:
  no CDN, so it works offline).
* ``WS /frames``: the page sends requests ``{"id", "edits", "view", "moving"}``, each the whole
  state (the file's key edits so far and the :class:`~.document.View`), ``moving`` true while the
  input moves (a reduced frame, :meth:`~.frames.Previewer.frame`; the page asks for the full frame
  once it stops); the server answers each it renders with a binary frame (:mod:`.encoding`) or
  ``{"id", "error"}``. Requests that arrive while a frame renders replace each other: the next
  frame is the newest request's, the superseded ones are dropped unanswered, never queued. The first message is ``{"type": "hello", ...}``: the file, its controls, outputs and
  materials, and the view it opens with.
* ``POST /save/settings.toml``, ``/save/view.tif``, ``/save/view.png``: the state in the body,
  the file to download in the answer.
* ``POST /slice`` (scan files): the state in the body; the answer, the middle slice of the grid
  from a cut-down scan with its labels (:mod:`.quick_slice`, :func:`.encoding.encode_slice`).

Frames render one at a time on one thread that owns the GL context (:class:`~.frames.Previewer`,
:class:`~.session.RenderThread`); an error in a request (a bad value, a weave whose yarns do not fit) is
answered, never raised, so no request stops the server. The event loop never waits on that thread:
a request is answered with an error past its deadline (:data:`~.session.FRAME_DEADLINE_S`), a new page gets
the hello made once at the start, and Ctrl-C or SIGTERM stop the server whatever a frame is doing.
Requests from another origin are refused, and so are requests that name another host (DNS
rebinding); a server bound beyond loopback needs ``?token=`` on every request, which the printed
address carries.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import secrets
import socket
import tempfile
import threading
import time
import warnings
import webbrowser
from importlib import resources
from pathlib import Path
from urllib.parse import urlsplit

import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, PlainTextResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from ..core.errors import XrayrasterError, XrayrasterWarning
from ..core.tiff import quicklook_path
from .document import Document, View
from .encoding import encode, encode_slice
from .frames import MOVING_PIXELS, Previewer
from .listen import check_listen
from .session import FRAME_DEADLINE_S, Preview

log = logging.getLogger("xrayraster")

LOOPBACK = ("127.0.0.1", "localhost", "::1")
SAVES = ("settings.toml", "view.tif", "view.png")


def make_app(preview: Preview, *, host: str = "127.0.0.1", port: int = 8000, token: str | None = None) -> Starlette:
    """The Starlette app serving ``preview`` at ``host``:``port`` (the names it answers to)."""
    static = resources.files("xrayraster.preview") / "static"
    hosts = {f"{h}:{port}" for h in (*LOOPBACK, "[::1]", host)}

    def refused(connection) -> str | None:
        """Why a request (or WebSocket) is refused: None when it is not. On loopback (no token) a
        request must name this server (no DNS rebinding); bound beyond it, the token admits a
        request whatever name of the machine it uses (a browser elsewhere knows it by its own)."""
        headers, query = connection.headers, connection.query_params
        if token is None and headers.get("host") not in hosts:
            return "unknown host"
        origin = headers.get("origin")
        if origin is not None and urlsplit(origin).netloc != headers.get("host"):
            return "cross-origin request"
        if token is not None and not hmac.compare_digest(query.get("token", ""), token):
            return "missing or wrong token"
        return None

    def refusal(request: Request) -> Response | None:
        why = refused(request)
        return None if why is None else PlainTextResponse(f"refused: {why}", status_code=403)

    async def page(request: Request):
        return refusal(request) or FileResponse(str(static / "index.html"))

    async def frames(ws: WebSocket):
        why = refused(ws)
        if why is not None:
            await ws.close(code=1008, reason=why)
            return
        await ws.accept()
        await ws.send_json(await preview.greeting())
        newest: list = []  # the one request waiting (a newer one replaces it)
        arrived = asyncio.Event()

        async def listen():
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    raise WebSocketDisconnect(message.get("code", 1000))
                newest[:] = [message.get("text")]  # None for a binary message: answered with an error
                arrived.set()

        listener = asyncio.create_task(listen())
        try:
            while True:
                waiting = asyncio.create_task(arrived.wait())
                await asyncio.wait({listener, waiting}, return_when=asyncio.FIRST_COMPLETED)
                if listener.done():
                    waiting.cancel()
                    break
                arrived.clear()
                text = newest.pop()
                await _answer(ws, preview, text)
        except WebSocketDisconnect:
            pass
        finally:
            listener.cancel()

    async def save(request: Request):
        if (answer := refusal(request)) is not None:
            return answer
        what = request.path_params["what"]
        if what not in SAVES:
            return PlainTextResponse(f"no such file: {what} (one of {', '.join(SAVES)})", status_code=404)
        try:
            document, view = preview.state(_request(await request.body()))
            if what == "settings.toml":
                text = await preview.run(lambda previewer: document.settings(view, what, previewer.load(document)))
                return _download(text, what, "application/toml")
            return _download(await preview.run(_saved_view, document, view, what), what,
                             "image/tiff" if what.endswith(".tif") else "image/png")
        except (XrayrasterError, ValueError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)

    async def cut(request: Request):
        if (answer := refusal(request)) is not None:
            return answer
        try:
            document, view = preview.state(_request(await request.body()))
            body = await preview.run(lambda previewer: encode_slice(previewer.quick_slice(document, view)))
            return Response(body, media_type="application/octet-stream")
        except (XrayrasterError, ValueError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)

    routes = [
        Route("/", page),
        Route("/save/{what:str}", save, methods=["POST"]),
        Route("/slice", cut, methods=["POST"]),
        WebSocketRoute("/frames", frames),
        Mount("/static", app=StaticFiles(directory=str(static)), name="static"),
    ]
    return Starlette(routes=routes)


def _request(body: str | bytes | None) -> dict:
    """The JSON object a request's body or WebSocket message holds (``{id, edits, view}``; None: a
    binary message); XrayrasterError saying what it must be otherwise."""
    if body is None:
        raise XrayrasterError("a request must be a text message holding JSON, not binary: {id, edits, view}")
    try:
        message = json.loads(body)
    except (ValueError, RecursionError) as exc:  # not JSON, not UTF-8, or nested beyond reason
        raise XrayrasterError(f"a request must be JSON: {exc}") from None
    if not isinstance(message, dict):
        raise XrayrasterError("a request must be a JSON object: {id, edits, view}")
    return message


async def _answer(ws: WebSocket, preview: Preview, text: str | None) -> None:
    """Render one request (``text``; None: a binary message) and send its frame, or its error (the
    page keeps its last good frame)."""
    request_id = None
    try:
        message = _request(text)
        request_id = message.get("id")
        document, view = preview.state(message)
        moving = message.get("moving", False)
        if not isinstance(moving, bool):
            raise XrayrasterError(f"a request's moving must be true or false, got {moving!r:.40}")
        frame = await preview.run(lambda previewer: previewer.frame(document, view, moving))
        await ws.send_bytes(encode(frame, request_id, {"command": document.command("settings.toml", view)}))
    except (XrayrasterError, ValueError) as exc:  # a bad value: the user's to fix
        await ws.send_json({"id": request_id, "error": str(exc)})
    except WebSocketDisconnect:
        raise
    except Exception as exc:  # noqa: BLE001 - a bug must not stop the server; it is logged whole
        log.exception("preview: request %s failed", request_id)
        await ws.send_json({"id": request_id, "error": f"{type(exc).__name__}: {exc}"})


def _saved_view(previewer: Previewer, document: Document, view: View, what: str) -> bytes:
    """The TIFF (float32, with the render command's metadata) or its PNG quick-look, as bytes."""
    with tempfile.TemporaryDirectory() as tmp:
        tif = previewer.projections(document, view).save(Path(tmp) / "view.tif")
        return (tif if what.endswith(".tif") else quicklook_path(tif)).read_bytes()


def address(host: str, port: int, token: str | None) -> str:
    """The page's address as a browser opens it: a server bound to every address (``0.0.0.0``,
    ``::``, which no browser can open) by this machine's name; with its token when it needs one."""
    if host in ("0.0.0.0", "::", ""):
        host = socket.gethostname()
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/" + (f"?token={token}" if token else "")


def _download(body, name: str, media_type: str) -> Response:
    return Response(body, media_type=media_type, headers={"Content-Disposition": f'attachment; filename="{name}"'})


def serve(path, *, host: str = "127.0.0.1", port: int = 8000, open_browser: bool = False,
          threads: int | None = None, deadline_s: float = FRAME_DEADLINE_S) -> None:
    """Serve the preview of the scene or scan file ``path`` at ``host``:``port`` until Ctrl-C (or
    SIGTERM), which uvicorn turns into a clean shutdown: within a second or so whatever a frame is
    doing (a frame still running is left behind, on a daemon thread). A bad file fails here, before
    the server starts. Bound beyond loopback, every request needs the printed address's token.
    ``deadline_s``: how long a request waits for its frame (:class:`Preview`)."""
    server, preview, url = _server(path, host, port, threads, deadline_s)

    async def main():
        task = asyncio.create_task(server.serve())
        while not server.started and not task.done():
            await asyncio.sleep(0.02)
        if server.started:
            print(f"preview of {preview.document.path} at {url}  (Ctrl-C stops it)", flush=True)
            if open_browser:
                webbrowser.open(url)
        await task

    try:
        asyncio.run(main())
    finally:
        preview.close()


class Background:
    """A preview served from a thread of this process (a notebook's, a test's): ``url``, and
    :meth:`stop` (or leaving a ``with`` block) shuts it down."""

    def __init__(self, path, *, host: str = "127.0.0.1", port: int = 8000, threads: int | None = None,
                 deadline_s: float = FRAME_DEADLINE_S, moving_pixels: int = MOVING_PIXELS):
        check_listen(host, port, names=("host", "port"))
        self._server, self._preview, self.url = _server(path, host, port, threads, deadline_s, moving_pixels)
        self._thread = threading.Thread(target=lambda: asyncio.run(self._server.serve()), daemon=True,
                                        name="xrayraster-preview-server")
        self._thread.start()
        while not self._server.started:
            if not self._thread.is_alive():
                self._preview.close()
                raise OSError(f"the preview server could not listen on {host}:{port} (the port may be taken)")
            time.sleep(0.02)

    def stop(self) -> None:
        self._server.should_exit = True
        self._thread.join()
        self._preview.close()

    def __enter__(self) -> "Background":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _server(path, host: str, port: int, threads: int | None, deadline_s: float = FRAME_DEADLINE_S,
            moving_pixels: int = MOVING_PIXELS):
    """The uvicorn server of ``path``'s preview, the preview and its address (with the token a
    server beyond loopback needs)."""
    document = Document.open(path)
    token = None if host in LOOPBACK else secrets.token_urlsafe(16)
    if token is not None:
        warnings.warn(XrayrasterWarning(f"the preview listens on {host}, beyond this machine's loopback: anyone who "
                                        "can reach it and has the address with its token can use it; prefer the "
                                        "default 127.0.0.1 and an SSH tunnel"), stacklevel=3)
    preview = Preview(document, threads, deadline_s, moving_pixels)
    app = make_app(preview, host=host, port=port, token=token)
    url = address(host, port, token)
    # An open page keeps its WebSocket: shutting down waits a second for it, then closes it. No
    # per-message deflate: zlib took 25 ms of a 512² frame (of noisy levels it barely shrinks).
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", ws="websockets-sansio",
                            ws_per_message_deflate=False, timeout_graceful_shutdown=1)
    return _Server(config, preview), preview, url


class _Server(uvicorn.Server):
    """uvicorn's server, which on shutting down first ends the preview's requests that wait on the
    render thread (:meth:`Preview.abandon`): their handlers return at once, so the shutdown never
    waits on a frame, nor cancels a handler (uvicorn logs each with a traceback)."""

    def __init__(self, config: uvicorn.Config, preview: Preview):
        super().__init__(config)
        self._preview = preview

    async def shutdown(self, sockets=None) -> None:
        self._preview.abandon()
        await super().shutdown(sockets)
