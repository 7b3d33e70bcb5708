"""Up-front plans of long jobs: their time and memory, estimated before any work.

A stage that can run for long (a scan, ``render --views all``, a woven sample's meshes, a tube
spectrum's bins) describes it as a job (:class:`Planned`: a small frozen dataclass of the sizes that
matter, in the stage's own module) whose :meth:`~Planned.estimate` is an :class:`Estimate`, and
passes it through the one gate, :func:`plan`: it refuses what cannot fit in memory
(:meth:`Estimate.check`, one line naming the key to change) and prints the estimate of a long job
when asked (:meth:`Estimate.announce`). The rates behind the times are measured on the development
machine (2 slow cores, llvmpipe, PoCL) and only claim the right order of magnitude.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from .memory import check_fits, size_text

#: A job estimated to take longer than this (seconds) has its estimate printed before it starts.
LONG_SECONDS = 60.0


@dataclass(frozen=True)
class Part:
    """One thing a job holds: ``what`` (for people), its ``bytes``, the ``key`` that sets its size
    (with its value, e.g. ``"[volume] shape = [512, 512, 512]"``) and the ``fix`` that shrinks it."""

    what: str
    bytes: int
    key: str
    fix: str


@dataclass(frozen=True)
class Estimate:
    """A ``job``'s wall time in ``seconds`` and the memory of its ``parts`` (:class:`Part`)."""

    job: str
    seconds: float
    parts: tuple[Part, ...]

    @property
    def bytes(self) -> int:
        return sum(p.bytes for p in self.parts)

    @property
    def long(self) -> bool:
        return self.seconds > LONG_SECONDS

    def line(self) -> str:
        """One line: the job, its time and memory, the largest parts."""
        largest = sorted(self.parts, key=lambda p: -p.bytes)[:3]
        held = ", ".join(f"{p.what}{f' {size_text(p.bytes)}' if len(self.parts) > 1 else ''}" for p in largest)
        return (f"estimate: {self.job}: about {duration_text(self.seconds)} and {size_text(self.bytes)} of memory "
                f"({held}); the rates are one slow 2-core machine's, right to an order of magnitude")

    def check(self, error: type[Exception], where: str = "") -> None:
        """Refuse with ``error`` when the parts together cannot fit in memory (over half of what is
        available), naming the largest part's key, its size and its fix; ``where`` prefixes the key."""
        if not self.parts:
            return
        largest = max(self.parts, key=lambda p: p.bytes)
        share = f" {size_text(largest.bytes)} of it" if len(self.parts) > 1 else ""
        check_fits(self.bytes, f"{where}{largest.key}: the {self.job} ({largest.what}{share})", largest.fix, error)

    def announce(self, stream=None) -> None:
        """Print :meth:`line` on ``stream`` (default stderr) when the job is :attr:`long`."""
        if self.long:
            print(self.line(), file=stream or sys.stderr, flush=True)


@runtime_checkable
class Planned(Protocol):
    """A job described by its sizes alone, before any work: what :func:`plan` estimates and gates."""

    def estimate(self) -> Estimate:
        """The job's time and memory, from its sizes alone (no meshing, rendering or allocation)."""
        ...


def plan(job: Planned, error: type[Exception], where: str = "", *, announce: bool = False) -> Estimate:
    """The gate every stage passes a job through before its work: ``job``'s :class:`Estimate`,
    refused with ``error`` when it cannot fit in memory (:meth:`Estimate.check`; ``where`` prefixes
    the key, e.g. the file's path and a space) and, with ``announce``, printed on stderr when long
    (:meth:`Estimate.announce`). Returns the estimate."""
    estimate = job.estimate()
    estimate.check(error, where)
    if announce:
        estimate.announce()
    return estimate


def duration_text(seconds: float) -> str:
    """``seconds`` for people: s below two minutes, then min, then h, then days."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.0f} {unit}"
    return f"{seconds:.0f} s"
