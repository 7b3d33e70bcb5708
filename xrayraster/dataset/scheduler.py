"""Whether a Dask scheduler answers at an address (``xrayraster build --scheduler``), asked before a
build writes anything: Dask waits for ever on a server that says nothing and misreads another
protocol's bytes (an SSH banner as a 2.8 EiB message), so the address is tried here, bounded."""

from __future__ import annotations

from ..core.errors import ConfigError

#: Seconds to reach a Dask scheduler and hear it answer, as long as Dask waits on a closed port.
SCHEDULER_TIMEOUT_S = 30.0
_SCHEDULER_FIX = ("start one with `dask scheduler` and give the address it prints (such as tcp://10.0.0.5:8786), "
                  "or build on this machine with --workers N")


def require_distributed():
    """The ``distributed`` package, or ConfigError saying how to install it."""
    try:
        import distributed
    except ImportError:
        raise ConfigError("building on Dask needs the dask extra: pip install \"xrayraster[dask]\"") from None
    return distributed


def check_scheduler(address, timeout: float = SCHEDULER_TIMEOUT_S) -> None:
    """Refuse, within about ``timeout`` seconds, an ``address`` where no Dask scheduler answers:
    not an address, nothing listening, a server that says nothing (Dask would wait for ever) or
    speaks another protocol (SSH, HTTP), a Dask worker. ConfigError, one line naming the address."""
    require_distributed()
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from distributed.comm import connect
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.security import Security

    where = f"--scheduler {address!r}"
    try:
        if not isinstance(address, str):
            raise ValueError(f"an address is a string, got {type(address).__name__}")
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls"):
            parse_host_port(location)
    except ValueError as exc:
        raise ConfigError(f"{where} is not a Dask scheduler's address ({exc}); {_SCHEDULER_FIX}") from None

    async def identity():
        comm = await connect(address, timeout=timeout, **Security().get_connection_args("client"))
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def ask():  # bounded as a whole: Dask's own timeout covers connecting, not a server that never answers
        return asyncio.run(asyncio.wait_for(identity(), timeout))

    try:
        with ThreadPoolExecutor(1) as thread:  # its own event loop, whatever loop the caller runs (Jupyter)
            reply = thread.submit(ask).result()
    except TimeoutError:
        raise ConfigError(f"{where}: no Dask scheduler answered within {timeout:g} s; {_SCHEDULER_FIX}") from None
    except OSError as exc:  # nothing listening, the connection closed
        raise ConfigError(f"{where}: no Dask scheduler there ({' '.join(str(exc).split())}); "
                          f"{_SCHEDULER_FIX}") from None
    except Exception:  # what another protocol's bytes make of Dask's framing: absurd sizes, bad msgpack
        raise ConfigError(f"{where}: the server there does not speak Dask's protocol (an SSH or web server?); "
                          f"{_SCHEDULER_FIX}") from None
    kind = reply.get("type") if isinstance(reply, dict) else None
    if kind != "Scheduler":
        raise ConfigError(f"{where}: the server there is {'a Dask ' + str(kind) if kind else 'not Dask'}, not a "
                          f"scheduler; {_SCHEDULER_FIX}")
