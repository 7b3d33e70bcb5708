"""A preview session: one document, the previewer that renders it, and the one thread that owns its
GL context (:class:`RenderThread`), behind deadlines so that nothing the render thread does can hold
the server (:mod:`.server`) that answers the page."""

from __future__ import annotations

import asyncio
import queue
import threading
import time
from concurrent.futures import Future

from ..core.errors import XrayrasterError
from .controls import controls
from .document import OUTPUTS, Document, View
from .frames import MOVING_PIXELS, Previewer, first_angle_deg, material_names

#: A request (a frame, a save, a quick slice) not answered within this many seconds is answered with
#: an error instead; its work goes on in the background (a thread cannot be stopped), and until it
#: ends, further requests are answered "busy" at once. The small twin's frame takes ~0.2 s, its
#: quick slice ~2 s, meshing a 6 × 6-cell weave ~10 s on the development machine.
FRAME_DEADLINE_S = 30.0
#: How often a request waiting on the render thread looks whether the server is shutting down.
CLOSING_CHECK_S = 0.1
#: How long closing waits for an idle render thread to release the GL context.
CLOSE_WAIT_S = 2.0


class RenderThread:
    """The one thread that renders (a GL context is current in one thread): jobs run in order, each
    answered through a :class:`concurrent.futures.Future`. A daemon thread, so that a job stuck for
    minutes (a huge mesh) never holds the process: Python cannot stop a thread, so shutting down
    leaves it behind instead of joining it (a ThreadPoolExecutor's threads are joined at exit)."""

    def __init__(self, name: str):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._started: float | None = None  # when the running job started; None while idle
        self._thread = threading.Thread(target=self._serve, name=name, daemon=True)
        self._thread.start()

    def submit(self, work, *args) -> Future:
        """``work(*args)`` after the jobs before it; its future (cancelled before it starts, it never runs)."""
        future = Future()
        self._jobs.put((future, work, args))
        return future

    def running_for(self) -> float | None:
        """Seconds the job now running has run; None while idle."""
        started = self._started
        return None if started is None else time.monotonic() - started

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> None:
        """End the thread once the jobs submitted so far are done (never waited for). A job still
        running is abandoned: the thread is marked so (``abandoned``), and the command line ends its
        process without tearing the interpreter down under it (xrayraster/cli/__init__.py, ``run``)."""
        self._thread.abandoned = self.running_for() is not None
        self._jobs.put(None)

    def _serve(self) -> None:
        while (job := self._jobs.get()) is not None:
            future, work, args = job
            if not future.set_running_or_notify_cancel():
                continue  # cancelled while it waited
            self._started = time.monotonic()
            try:
                result = work(*args)
            except BaseException as exc:  # noqa: BLE001 - answered to whoever waits; the thread goes on
                future.set_exception(exc)
            else:
                future.set_result(result)
            finally:
                self._started = None


class Preview:
    """One document served: the previewer and the single thread that renders its frames
    (:class:`RenderThread`). A request waits at most ``deadline_s`` for its answer (:meth:`run`), and
    no longer than the server runs: nothing the render thread does can hold the server.
    ``moving_pixels``: the most pixels of a reduced frame (:class:`~.frames.Previewer`)."""

    def __init__(self, document: Document, threads: int | None = None, deadline_s: float = FRAME_DEADLINE_S,
                 moving_pixels: int = MOVING_PIXELS):
        self.document, self.deadline_s = document, deadline_s
        self._previewer = Previewer(threads, moving_pixels)
        self._render = RenderThread("xrayraster-preview")
        self._closing = False
        # The first message depends on the document alone: made once, first, so that a new page
        # gets it at once even while another page's frame renders.
        self._hello = self._render.submit(self.hello, self._previewer)

    async def greeting(self) -> dict:
        """The first message to a page (:meth:`hello`): the one made at the start, made again only
        if that failed (the failure may have passed)."""
        if self._hello.cancelled() or (self._hello.done() and self._hello.exception() is not None):
            self._hello = self._render.submit(self.hello, self._previewer)
        return await self._awaited(self._hello)

    async def run(self, work, *args):
        """``work(previewer, *args)`` on the render thread. An XrayrasterError instead when the
        answer takes over :attr:`deadline_s` (the work goes on, its answer dropped), while an earlier
        job that took that long still runs ("busy", at once), or when the server shuts down
        (:meth:`abandon`)."""
        running = self._render.running_for()
        if running is not None and running > self.deadline_s:
            raise XrayrasterError(f"busy: a frame has been rendering for {running:.0f} s, longer than its "
                                  f"{self.deadline_s:g} s deadline; the preview answers again when it has finished")
        return await self._awaited(self._render.submit(work, self._previewer, *args))

    async def _awaited(self, job: Future):
        """``job``'s result, awaited without blocking the event loop, within the deadline and while
        the server runs (looked at every :data:`CLOSING_CHECK_S`)."""
        answer = asyncio.wrap_future(job)
        deadline = time.monotonic() + self.deadline_s
        try:
            while not answer.done():
                if self._closing:
                    raise XrayrasterError("the preview server is shutting down")
                left = deadline - time.monotonic()
                if left <= 0:
                    raise XrayrasterError(f"frame took longer than {self.deadline_s:g} s, its deadline: it goes on in "
                                          "the background and the preview answers again when it has finished; a "
                                          "smaller sample or detector renders faster")
                await asyncio.wait({answer}, timeout=min(left, CLOSING_CHECK_S))
            return answer.result()
        finally:
            if not answer.done():
                answer.cancel()  # a job still queued never runs; a running one's answer is dropped

    def abandon(self) -> None:
        """The server is shutting down: every request waiting on the render thread ends now."""
        self._closing = True

    def state(self, message: dict) -> tuple[Document, View]:
        """The document and view a request describes (XrayrasterError naming the field if it cannot)."""
        edits, view = message.get("edits", {}), message.get("view", {})
        if not isinstance(edits, dict) or not isinstance(view, dict):
            raise XrayrasterError("a request's edits and view must be JSON objects")
        return self.document.edited(edits), View.from_dict(view)

    def hello(self, previewer: Previewer) -> dict:
        loaded = previewer.load(self.document)
        materials = material_names(previewer.scene(self.document, loaded))
        view = self.document.initial_view(loaded)
        return {"type": "hello", "file": self.document.path.name, "kind": self.document.kind,
                "controls": controls(self.document, loaded), "outputs": list(OUTPUTS), "materials": materials,
                "view": {"output": view.output, "noise": view.noise, "seed": view.seed,
                         "angle_deg": first_angle_deg(loaded.geometry)}}

    def close(self) -> None:
        """Stop waiting on the render thread and end it once it has released the GL context: at once
        when it is idle; after the job it runs otherwise, which is never waited for (the process
        may end first, and the contexts with it)."""
        self.abandon()
        running = self._render.running_for() is not None
        release = self._render.submit(self._previewer.release)
        if not running:
            try:
                release.result(timeout=CLOSE_WAIT_S)
            except TimeoutError:  # a job came first and runs on: the release follows it
                pass
        self._render.stop()
