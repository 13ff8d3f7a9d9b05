"""Where the device server listens, and why it cannot: light enough (sockets only) for
`python -m landscape.server` to refuse a taken port before it loads the simulation."""
from __future__ import annotations

import errno
import os
import socket


def listen_address(address: str, port: int) -> str:
    """host:port as gRPC wants it: an IPv6 literal in brackets (``::1`` -> ``[::1]``)."""
    if ":" in address and not address.startswith("["):
        address = f"[{address}]"
    return f"{address}:{port}"


def listen_problem(address: str, port: int) -> str | None:
    """Why the server cannot listen on address:port, in one line naming the cause (from the
    errno of a trial bind, with SO_REUSEADDR as gRPC binds) and the fix; None if it can."""
    host = address.strip("[]")
    where = listen_address(address, port)
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as error:
        return (f"cannot listen on {where}: {host!r} is not a known host name or address "
                f"({error.strerror}); choose another with --address")
    family, kind, proto, _, sockaddr = infos[0]
    try:
        with socket.socket(family, kind, proto) as trial:
            trial.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            trial.bind(sockaddr)
            trial.listen()
    except OSError as error:
        return f"cannot listen on {where}: {_cause(error.errno, host, port)}"
    return None


def _cause(number: int | None, host: str, port: int) -> str:
    if number == errno.EADDRINUSE:
        return (f"port {port} is in use (another device server?); stop that one, or choose "
                f"another port with --port (0: any free one)")
    if number == errno.EADDRNOTAVAIL:
        return (f"{host} is not an address of this machine; choose one of its addresses with "
                f"--address (127.0.0.1: this machine only)")
    if number == errno.EACCES:
        return f"port {port} needs privileges; choose one above 1023 with --port"
    why = os.strerror(number) if number else "the system refused"
    return f"{why}; choose another with --address / --port"
