"""Ctrl-C (SIGINT) and SIGTERM end a command the same way at any moment: as a ``KeyboardInterrupt``.

Raising it (SIGTERM too, as :class:`Terminated`) unwinds the stack, so every ``finally`` and
``except BaseException`` runs: the atomic writes remove their temporaries. Third-party code does
not always let it through, so an interrupt is made to arrive however it is handled on the way:

- imported under :func:`deferred`: a library caught mid-import swallows the interrupt (a bare
  ``except``) or crashes; the signal is held until the imports are done;
- turned into another exception (SpekPy reports a data file it was loading as unreadable):
  :func:`received` says that an interrupt came, and the command line reports that instead;
- swallowed, or raised inside a ``__del__`` or weakref callback (Python prints "Exception ignored"
  and drops it): the exception object dies before the command line has caught it, and a weakref
  on it delivers the signal again (:func:`_redeliver`); :func:`_unraisable` keeps it off stderr.

A repeated signal while one is on its way out is ignored: raising again could cut its cleanup short.

When the command line is the process (the console script, ``python -m xrayraster``), a signal
after the command has finished is ignored too (:func:`exit_when_done`): the process's teardown
(the GL and OpenCL drivers unloading) can take a moment, and Python restores the default action
of its signals while it shuts down, so a Ctrl-C then would kill a finished command (exit -2,
nothing said) instead of letting it exit with its own status.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
import weakref
from contextlib import contextmanager

__all__ = ["Terminated", "deferred", "done", "exit_when_done", "handled", "install", "received"]


class Interrupted(KeyboardInterrupt):
    """SIGINT. A subclass (the built-in cannot be weakly referenced) so a lost one can be noticed."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so the same cleanup runs."""


_signum: int | None = None  # the first signal received
_deferring = False
_held = False  # a signal came while deferred
_redelivering = False
_handled = False
_watch: weakref.ref | None = None  # the exception last raised for the signal
_exiting = False  # the command line is the process: ignore signals once the command is done
_done = False
_REDELIVERY_DELAY_S = 0.01


def install() -> None:
    """Handle SIGINT and SIGTERM as the module docstring says, and hide dropped interrupts.

    For the rest of the process (so also while it shuts down); each call starts afresh, as the
    tests call the command line more than once in one process.
    """
    global _signum, _deferring, _held, _redelivering, _handled, _watch, _done
    _signum, _deferring, _held, _redelivering, _handled, _watch, _done = None, False, False, False, False, None, False
    signal.signal(signal.SIGINT, _handler)
    signal.signal(signal.SIGTERM, _handler)
    sys.unraisablehook = _unraisable


def received() -> int | None:
    """The signal number of the first SIGINT or SIGTERM received, or None."""
    return _signum


def handled() -> None:
    """The command line has caught the interrupt (or reported its substitute): deliver it no more."""
    global _handled
    _handled = True


def exit_when_done() -> None:
    """The process ends when the command does (the console script): from :func:`done` on, ignore
    SIGINT and SIGTERM for the rest of the process."""
    global _exiting
    _exiting = True


def done() -> None:
    """The command has finished: its outputs are complete, or its interrupt or error reported.
    Only where :func:`exit_when_done` was called: signals are ignored from here on (an in-process
    caller, such as a test, keeps its handlers)."""
    global _done
    if _exiting:
        _done = True  # first, so a signal arriving inside this function is ignored too
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Python leaves ignored signals so at shutdown
        signal.signal(signal.SIGTERM, signal.SIG_IGN)


@contextmanager
def deferred():
    """Hold a signal that comes inside the block until the block ends, then raise it."""
    global _deferring
    _deferring = True
    try:
        yield
    finally:
        _deferring = False
    if _held:
        _raise()


def _handler(signum, frame) -> None:
    global _signum, _held, _redelivering
    if _done:
        return  # the command has finished (done)
    if _signum is not None and not _redelivering:
        return  # a repeat
    _signum = _signum or signum
    _redelivering = False
    if _deferring:
        _held = True
        return
    _raise()


def _raise() -> None:
    # No local name here holds the exception: its traceback holds this frame, and that cycle would
    # keep a swallowed exception alive, so the weakref would not notice that it was dropped.
    raise _watched((Terminated if _signum == signal.SIGTERM else Interrupted)())


def _watched(exc: KeyboardInterrupt) -> KeyboardInterrupt:
    global _watch
    _watch = weakref.ref(exc, _redeliver)
    return exc


def _redeliver(_ref) -> None:
    """The exception died before the command line caught it: simulate the signal again.

    From another thread, a moment later: handled inside this callback, it would be dropped again.
    """
    global _redelivering
    if not _handled:
        _redelivering = True
        timer = threading.Timer(_REDELIVERY_DELAY_S, _deliver_again)
        timer.daemon = True
        timer.start()


def _deliver_again() -> None:
    if not _handled:
        _thread.interrupt_main(_signum)


def _unraisable(unraisable) -> None:
    if isinstance(unraisable.exc_value, (Interrupted, Terminated)):
        return  # dropped: delivered again when it dies
    sys.__unraisablehook__(unraisable)
