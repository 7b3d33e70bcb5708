"""The xrayraster command line, one module per command; nothing in the package imports it.

Exit status: 0 done; 2 bad input (the message names the file, field or flag and the fix);
130 interrupted (Ctrl-C), 143 terminated (SIGTERM); 1 anything else: a file-system failure during
the work (disk full), or a bug. Every failure is one line on stderr; a bug's traceback is printed
with ``-v``.

Only the standard library is imported here, so :func:`main` handles signals (:mod:`.interrupts`)
before the second of imports the commands need (numpy, trimesh, OpenCL...), and ``--version``
answers without them.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import traceback
import warnings

from .. import __version__
from ..core.errors import XrayrasterError, XrayrasterWarning  # standard library only
from ..core.heap import keep_freed_memory  # standard library only
from . import interrupts

EXIT_OK, EXIT_UNEXPECTED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


def one_line(text) -> str:
    """``text`` on one line (its lines joined with '; ')."""
    return "; ".join(line.strip() for line in str(text).splitlines() if line.strip())


def main(argv=None) -> int:
    interrupts.install()
    argv = sys.argv[1:] if argv is None else list(argv)
    verbose = "-v" in argv or "--verbose" in argv  # for a failure before the arguments are parsed
    try:
        if argv == ["--version"]:  # answered before the commands' second of imports
            print(f"xrayraster {__version__}")
            return EXIT_OK
        with interrupts.deferred():  # a library interrupted mid-import may swallow it, or crash
            from . import build, compare, fit, info, preview, reconstruct, render, scan, voxelize, weave
        keep_freed_memory()  # the command owns the process (core/heap.py)
        parser = argparse.ArgumentParser(prog="xrayraster", description="X-ray CT simulation from triangle meshes.")
        parser.add_argument("--version", action="version", version=f"xrayraster {__version__}")
        subparsers = parser.add_subparsers(dest="command", required=True)
        for command in (scan, build, weave, render, preview, reconstruct, voxelize, compare, fit, info):
            command.add_parser(subparsers)
        args = parser.parse_args(argv)
        verbose = args.verbose
        logging.basicConfig(level=logging.INFO if verbose else logging.WARNING, format="%(message)s")
        with warnings.catch_warnings():  # restores showwarning for a caller of main (tests)
            warnings.showwarning = _show_warning
            warnings.simplefilter("always", XrayrasterWarning)  # each run says it, not only a process's first
            return args.run(args)
    except KeyboardInterrupt as exc:
        return _interrupted(exc)
    except Exception as exc:
        if interrupts.received():  # third-party code turned the interrupt into another exception
            return _interrupted()
        return _failed(exc, verbose)
    finally:
        interrupts.done()


def run() -> int:
    """The console script and ``python -m xrayraster``: :func:`main` as the whole process, so a
    signal after the command has finished (while the process shuts down) is ignored.

    A thread the command abandoned, still running (marked ``abandoned``: the preview's render
    thread, stopped mid-frame, which Python cannot stop), may be inside a C library: tearing the
    interpreter down under it prints that library's leak reports or waits on its driver, so the
    process then ends at once with the command's status, its output flushed."""
    interrupts.exit_when_done()
    status = main()
    if any(getattr(thread, "abandoned", False) and thread.is_alive() for thread in threading.enumerate()):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status


def _interrupted(exc: BaseException | None = None) -> int:
    """Say so; what the command kept is the interrupt's note (a dataset build's finished samples),
    by default nothing under its final name."""
    interrupts.handled()
    signum = interrupts.received() or signal.SIGINT  # a KeyboardInterrupt raised without a signal
    what = "terminated" if signum == signal.SIGTERM else "interrupted"
    kept = "; ".join(getattr(exc, "__notes__", ())) or "no output written under its final name"
    print(f"xrayraster: {what}; {one_line(kept)}", file=sys.stderr)
    return 128 + signum


def _failed(exc: Exception, verbose: bool) -> int:
    if isinstance(exc, XrayrasterError):
        print(f"xrayraster: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if verbose:
        traceback.print_exc()
    if isinstance(exc, OSError):  # the file system during the work: disk full, a directory removed meanwhile
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"xrayraster: error: {one_line(exc.strerror or exc)}{where}", file=sys.stderr)
        return EXIT_UNEXPECTED
    hint = "" if verbose else "; run with -v for the traceback"
    print(f"xrayraster: unexpected error (a bug, please report it): {type(exc).__name__}: {one_line(exc)}{hint}",
          file=sys.stderr)
    return EXIT_UNEXPECTED


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """xrayraster's own warnings as one line on stderr, like its errors; others as Python prints them."""
    if issubclass(category, XrayrasterWarning):
        print(f"xrayraster: warning: {one_line(message)}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))
