"""TLS for the device server, and the rule that keeps it off the network by accident.

Plaintext is for loopback: a server bound to any other address must have TLS and tokens, or
be started with --insecure on purpose (DESIGN.md section 10: secure defaults).
"""
from __future__ import annotations

import ipaddress
from pathlib import Path

import grpc

from landscape.server.config import SecurityConfig


class TlsError(ValueError):
    """Certificate files that cannot be used; the message names the file."""


def is_loopback(address: str) -> bool:
    """True for 127.0.0.0/8, ::1 and "localhost"; anything else (a wildcard, a name) is not."""
    host = address.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def exposure_problem(address: str, security: SecurityConfig) -> str | None:
    """Why the server must not listen on `address` with these settings, or None."""
    if is_loopback(address) or security.insecure:
        return None
    missing = [what for what, there in (("TLS (--tls-cert, --tls-key)", security.tls_enabled),
                                        ("tokens (--tokens)", security.tokens is not None))
               if not there]
    if not missing:
        return None
    return (f"refusing to listen on {address} without {' and '.join(missing)}: anyone on the "
            f"network could command the arm; add them (`landscape-cell certs`, `landscape-cell "
            f"tokens`), listen on 127.0.0.1, or pass --insecure if this network is yours alone")


def _read(path: str, what: str) -> bytes:
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise TlsError(f"cannot read the {what} {path}: {error.strerror}") from None
    if b"-----BEGIN" not in data:
        raise TlsError(f"the {what} {path} is not PEM")
    return data


def server_credentials(security: SecurityConfig) -> grpc.ServerCredentials:
    """The server's certificate and key; with mTLS, clients must show a certificate signed by
    security.tls_ca."""
    if not security.tls_key:
        raise TlsError("a certificate needs its key (--tls-key)")
    if security.mtls and not security.tls_ca:
        raise TlsError("mutual TLS needs the CA that signs the clients' certificates (--tls-ca)")
    pair = (_read(security.tls_key, "TLS key"), _read(security.tls_cert, "TLS certificate"))
    if security.mtls:
        return grpc.ssl_server_credentials([pair], _read(security.tls_ca, "client CA"),
                                           require_client_auth=True)
    return grpc.ssl_server_credentials([pair])
