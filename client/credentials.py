"""Channels to a device server that may want TLS and a role token.

    tls = ClientTLS(ca="var/certs/ca.pem")
    with open_channel("arm1.lan:50051", tls, read_token("var/tokens/operator.tokens")) as ch:
        with Session(ch, "cell-supervisor") as session: ...

With TLS the token rides on gRPC's call credentials; on a plaintext channel (loopback) an
interceptor adds the same `authorization: Bearer <token>` header. `add_arguments` and
`from_arguments` give every client program (the CRCL gateway, the web supervisor, probes) the
same flags.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import grpc


AUTHORIZATION = "authorization"


@dataclass(frozen=True)
class ClientTLS:
    """PEM files: the CA that signs the server's certificate (None: the system's roots), and
    this client's certificate and key for mutual TLS. server_name: the name to check in the
    server's certificate when the target's host is not in it (an IP address, say)."""

    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    server_name: str | None = None

    def credentials(self) -> grpc.ChannelCredentials:
        def read(path):
            return Path(path).read_bytes() if path else None
        return grpc.ssl_channel_credentials(read(self.ca), read(self.key), read(self.cert))

    def options(self) -> list[tuple[str, str]]:
        return [("grpc.ssl_target_name_override", self.server_name)] if self.server_name else []


@dataclass(frozen=True)
class Endpoint:
    """How to reach a device server: "host:port", TLS (None: plaintext) and the role token to
    present (None: none). A client core opens its channels from it, one per event loop."""

    target: str
    tls: ClientTLS | None = None
    token: str | None = None

    def aio_channel(self, options=()) -> grpc.aio.Channel:
        """A channel on the running loop (grpc.aio binds a channel to its loop)."""
        return open_aio_channel(self.target, self.tls, self.token, options)


def bearer(token: str | None) -> tuple[tuple[str, str], ...]:
    """The call metadata that presents `token` (none without one): for a program that calls
    for several people on one channel opened without a token, each call with its person's."""
    return ((AUTHORIZATION, f"Bearer {token}"),) if token else ()


def read_token(path: str | Path) -> str:
    """The first token in a token file (one a line, `<token> [name]`, `#` comments): the
    format of the server's role files, so a development file serves both sides."""
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        words = line.split("#", 1)[0].split()
        if words:
            return words[0]
    raise ValueError(f"{path}: holds no token")


def _credentials(tls: ClientTLS, token: str | None) -> grpc.ChannelCredentials:
    """TLS, with the token on every call if given (gRPC sends call credentials only over TLS)."""
    credentials = tls.credentials()
    if token:
        credentials = grpc.composite_channel_credentials(
            credentials, grpc.access_token_call_credentials(token))
    return credentials


def open_channel(target: str, tls: ClientTLS | None = None, token: str | None = None,
                 options=()) -> grpc.Channel:
    """A synchronous channel: plaintext without `tls`, the token on every call if given."""
    options = [*options, *(tls.options() if tls else ())]
    if tls is not None:
        return grpc.secure_channel(target, _credentials(tls, token), options)
    channel = grpc.insecure_channel(target, options)
    return grpc.intercept_channel(channel, _Bearer(token)) if token else channel


def open_aio_channel(target: str, tls: ClientTLS | None = None, token: str | None = None,
                     options=()) -> grpc.aio.Channel:
    """The grpc.aio twin of `open_channel`."""
    options = [*options, *(tls.options() if tls else ())]
    if tls is not None:
        return grpc.aio.secure_channel(target, _credentials(tls, token), options)
    interceptors = _AioBearer.every_kind(token) if token else None
    return grpc.aio.insecure_channel(target, options, interceptors=interceptors)


# The flags every client program takes (argparse here, click in the CLI): name, help.
FLAGS = (
    ("--tls-ca", "TLS: PEM CA that signs the device server's certificate"),
    ("--tls-cert", "mutual TLS: this client's PEM certificate"),
    ("--tls-key", "mutual TLS: the PEM key of --tls-cert"),
    ("--tls-server-name", "TLS: the name to expect in the server's certificate"),
    ("--token-file", "file holding the role token to present"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--tls-ca, --tls-cert, --tls-key, --tls-server-name, --token-file."""
    group = parser.add_argument_group("connecting to the device server")
    for flag, help_text in FLAGS:
        group.add_argument(flag, help=help_text)


def from_arguments(args: argparse.Namespace) -> tuple[ClientTLS | None, str | None]:
    """(tls, token) from the flags of `add_arguments`."""
    return from_values(args.tls_ca, args.tls_cert, args.tls_key, args.tls_server_name,
                       args.token_file)


def from_values(tls_ca=None, tls_cert=None, tls_key=None, tls_server_name=None,
                token_file=None) -> tuple[ClientTLS | None, str | None]:
    """(tls, token) from the FLAGS' values; TLS is on when any TLS flag is given."""
    tls = None
    if tls_ca or tls_cert or tls_server_name:
        tls = ClientTLS(tls_ca, tls_cert, tls_key, tls_server_name)
    return tls, read_token(token_file) if token_file else None


class _Bearer(grpc.UnaryUnaryClientInterceptor, grpc.UnaryStreamClientInterceptor,
              grpc.StreamUnaryClientInterceptor, grpc.StreamStreamClientInterceptor):
    """Adds the token to every call of a plaintext synchronous channel."""

    def __init__(self, token: str):
        self._header, = bearer(token)

    def _details(self, d):
        return CallDetails(d.method, d.timeout, [*(d.metadata or ()), self._header],
                            d.credentials, d.wait_for_ready, d.compression)

    def intercept_unary_unary(self, continuation, details, request):
        return continuation(self._details(details), request)

    intercept_unary_stream = intercept_unary_unary

    def intercept_stream_unary(self, continuation, details, request_iterator):
        return continuation(self._details(details), request_iterator)

    intercept_stream_stream = intercept_stream_unary


class _AioBearer:
    """Adds the token to every call of a plaintext grpc.aio channel."""

    def __init__(self, token: str):
        self._header, = bearer(token)

    async def intercept(self, continuation, details, request):
        metadata = grpc.aio.Metadata(*(details.metadata or ()), self._header)
        return await continuation(details._replace(metadata=metadata), request)

    @staticmethod
    def every_kind(token: str) -> list:
        """One interceptor per kind of call: grpc.aio files an interceptor under the first
        kind it is only."""
        return [_AioBearerUnaryUnary(token), _AioBearerUnaryStream(token),
                _AioBearerStreamUnary(token), _AioBearerStreamStream(token)]


class _AioBearerUnaryUnary(_AioBearer, grpc.aio.UnaryUnaryClientInterceptor):
    intercept_unary_unary = _AioBearer.intercept


class _AioBearerUnaryStream(_AioBearer, grpc.aio.UnaryStreamClientInterceptor):
    intercept_unary_stream = _AioBearer.intercept


class _AioBearerStreamUnary(_AioBearer, grpc.aio.StreamUnaryClientInterceptor):
    intercept_stream_unary = _AioBearer.intercept


class _AioBearerStreamStream(_AioBearer, grpc.aio.StreamStreamClientInterceptor):
    intercept_stream_stream = _AioBearer.intercept


class CallDetails(grpc.ClientCallDetails):
    """A call's details with other metadata, for the synchronous channels' interceptors."""

    def __init__(self, method, timeout, metadata, credentials, wait_for_ready, compression):
        self.method, self.timeout, self.metadata = method, timeout, metadata
        self.credentials, self.wait_for_ready, self.compression = (credentials, wait_for_ready,
                                                                   compression)
