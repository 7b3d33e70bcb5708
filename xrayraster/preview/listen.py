"""Whether the preview's server can listen at a host and port, asked before it starts: a port in
use, a host that is not this machine's, refused in one line instead of uvicorn's tracebacks."""

from __future__ import annotations

import errno
import socket

from ..core.errors import ConfigError

MAX_PORT = 65535


def check_listen(host: str, port: int, names: tuple[str, str] = ("--host", "--port")) -> None:
    """Refuse, before the server starts, an address it could not listen on (a ConfigError naming
    the host or port as ``names`` call them, and the fix): a port in use or reserved, a host that is
    no address of this machine. Bound as uvicorn binds (SO_REUSEADDR: a port a closed server left
    is free)."""
    host_name, port_name = names
    try:
        family, kind, proto, _, where = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                                           flags=socket.AI_PASSIVE)[0]
    except (socket.gaierror, UnicodeError) as exc:
        raise ConfigError(f"{host_name} {host}: not a name or address of this machine ({exc}); give one of its "
                          "addresses, e.g. 127.0.0.1 (the default) or 0.0.0.0 (all)") from None
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(where)
        except OSError as exc:
            raise ConfigError(_why_not(host, port, exc, host_name, port_name)) from None


def _why_not(host: str, port: int, exc: OSError, host_name: str, port_name: str) -> str:
    """The one-line refusal of ``host``:``port`` for the error binding it raised."""
    if exc.errno == errno.EADDRINUSE:
        return (f"{port_name} {port}: already in use on {host} (another preview, or another server); give "
                f"another, e.g. {port_name} {port + 1 if port < MAX_PORT else 8000}, or stop the program that holds it")
    if exc.errno == errno.EACCES:
        return f"{port_name} {port}: this user may not listen on it (ports below 1024 need privileges); give one above 1023"
    if exc.errno == errno.EADDRNOTAVAIL:
        return (f"{host_name} {host}: not an address of this machine; give one of its addresses, e.g. 127.0.0.1 "
                "(the default) or 0.0.0.0 (all)")
    return (f"{host_name} {host} {port_name} {port}: cannot listen there ({exc.strerror or exc}); give another "
            f"{host_name} or {port_name}")
