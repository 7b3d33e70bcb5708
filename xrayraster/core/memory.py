"""How much memory the machine has free: every stage checks a request against it before work starts."""

from __future__ import annotations

#: The share of the available memory one request may plan to use: the rest is for the stages'
#: temporaries, which the estimates leave out, and for the other processes of the machine.
PLAN_SHARE = 0.5


def available_memory() -> int | None:
    """Bytes of memory available to this process (Linux), or None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def size_text(nbytes: float) -> str:
    """``nbytes`` for people: GiB from 1 GiB up, else MiB."""
    return f"{nbytes / 2**30:.2f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


def check_fits(need: int, what: str, fix: str, error: type[Exception]) -> None:
    """Refuse with ``error`` (one line: ``what`` needs so much, more than half the memory available;
    ``fix``) when ``need`` bytes exceed :data:`PLAN_SHARE` of :func:`available_memory`. ``what``
    names the request (a key and its value), ``fix`` says what to change."""
    free = available_memory()
    if free is not None and need > free * PLAN_SHARE:
        raise error(f"{what} needs {size_text(need)}, more than half the {size_text(free)} available; {fix}")
