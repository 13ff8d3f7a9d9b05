"""The OPC UA bridge's process: one asyncua server for a cell, each arm as OPC 40010 models a
motion device (model.py), kept up to date from its device's state stream and status.

    python -m landscape.bridges.opcua --device arm1=127.0.0.1:50051 [--device ...]

Off by default (the cell file's [opcua]). Read-only: no variable is writable, so a client's
write is refused (BadNotWritable; BadUserAccessDenied where the user may not write at all),
and there are no methods. Who may connect: on loopback, anyone (anonymous); on any other
address, only a user of the users file (`<name> <SHA-256 of the password, hex>` a line) or
a client whose certificate is listed (--trusted-cert), over Basic256Sha256 with signing
and encryption, with the server's own certificate and key.
"""
from __future__ import annotations

import argparse
import asyncio
import hashlib
import hmac
import logging
import signal
from pathlib import Path

from asyncua import Server, ua
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import rsa
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.server.user_managers import CertificateUserManager

from landscape.bridges.device_feed import Callbacks, DeviceFeed, device_targets
from landscape.bridges.opcua.model import (AUTOMATIC_EXTERNAL, MANUAL_REDUCED_SPEED, ArmNodes,
                                           RoboticsModel)
from landscape.client import credentials
from landscape.server.security.tls import is_loopback
from landscape.v1 import types_pb2

log = logging.getLogger("landscape.bridges.opcua")

DEFAULT_PORT = 4840
RATE_HZ = 10.0      # state samples a second per arm: what a plant's SCADA reads


class UsersError(ValueError):
    """A users file that cannot be used; the message names the file and line."""


def load_users(path: str | Path) -> dict[str, bytes]:
    """{name: SHA-256 digest of the password} from a file of `<name> <hex digest>` lines."""
    users = {}
    for number, line in enumerate(Path(path).read_text(encoding="utf-8").splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        try:
            name, digest = words
            users[name] = bytes.fromhex(digest)
            assert len(users[name]) == 32
        except (ValueError, AssertionError):
            raise UsersError(f"{path}:{number}: expected `<name> <SHA-256 of the password, "
                             f"64 hex digits>`") from None
    return users


class CellUsers:
    """asyncua's user manager: anonymous only where allowed (loopback), users by password
    digest (compared in constant time), clients by a listed certificate; each a reader."""

    def __init__(self, users: dict[str, bytes], certificates: CertificateUserManager | None,
                 anonymous: bool):
        self.users, self.certificates, self.anonymous = users, certificates, anonymous

    def get_user(self, iserver, username=None, password=None, certificate=None):
        if certificate is not None and self.certificates is not None:
            return self.certificates.get_user(iserver, certificate=certificate)
        if username is not None:
            digest = self.users.get(username)
            given = hashlib.sha256((password or "").encode()).digest()
            if digest is not None and hmac.compare_digest(digest, given):
                return User(role=UserRole.User, name=username)
            return None
        return User(role=UserRole.User, name="anonymous") if self.anonymous else None


class ArmFeed:
    """What one device's feed writes into its arm's nodes."""

    def __init__(self, model: RoboticsModel, name: str):
        self.model, self.name = model, name
        self.nodes: ArmNodes | None = None

    def callbacks(self) -> Callbacks:
        return Callbacks(self.connected, self.sample, _ignore, _ignore, self.lost, self.status)

    async def connected(self, description) -> None:
        if self.nodes is None:
            self.nodes = await self.model.add_arm(self.name, description.robot_type,
                                                  description.joint_names)
        await self.nodes.connected.write_value(True)

    async def sample(self, sample) -> None:
        nodes = self.nodes
        for node, value in zip(nodes.positions, sample.joint_positions):
            await node.write_value(value, ua.VariantType.Double)
        for node, value in zip(nodes.speeds, sample.joint_velocities):
            await node.write_value(value, ua.VariantType.Double)
        await nodes.emergency_stop.write_value(sample.estop)
        await nodes.device_state.write_value(types_pb2.DeviceState.Name(sample.device_state))
        await nodes.command_id.write_value(sample.command_id)

    async def status(self, status) -> None:
        nodes = self.nodes
        await nodes.lock_holder.write_value(status.lock_holder)
        manual = status.manual_control not in ("", "off")
        await nodes.operational_mode.write_value(ua.Variant(
            MANUAL_REDUCED_SPEED if manual else AUTOMATIC_EXTERNAL, ua.VariantType.Int32))
        await nodes.protective_stop.write_value(
            status.state == types_pb2.DEVICE_STATE_ERROR and not status.estop)

    async def lost(self, why: str) -> None:
        log.warning("lost %s; connecting again", why)
        if self.nodes is not None:
            await self.nodes.connected.write_value(False)


def _ignore(*_) -> None:
    pass


def application_uri(certificate: str) -> str | None:
    """The application URI an OPC UA certificate (PEM or DER) names (OPC UA Part 6, 6.2.2),
    None if it names none; ValueError for a key Basic256Sha256 cannot use (it needs RSA)."""
    data = Path(certificate).read_bytes()
    cert = (x509.load_pem_x509_certificate(data) if data.lstrip().startswith(b"-----")
            else x509.load_der_x509_certificate(data))
    if not isinstance(cert.public_key(), rsa.RSAPublicKey):
        raise ValueError(f"{certificate}: OPC UA's Basic256Sha256 needs an RSA key, this "
                         f"certificate's is not (`landscape-cell certs` writes an RSA pair, "
                         f"opcua-server.pem and opcua-server-key.pem)")
    try:
        names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return None
    uris = names.get_values_for_type(x509.UniformResourceIdentifier)
    return uris[0] if uris else None


class OpcUaBridge:
    """The server and one ArmFeed per device ({name: target}). Off loopback it needs
    `certificate` and `key` (PEM), and users or trusted client certificates."""

    def __init__(self, devices: dict[str, str], host: str = "127.0.0.1",
                 port: int = DEFAULT_PORT, cell: str = "cell", *, users: dict | None = None,
                 trusted: tuple[str, ...] = (), certificate: str | None = None,
                 key: str | None = None, tls=None, token=None, rate_hz: float = RATE_HZ):
        self.devices, self.host, self.port, self.cell = devices, host, port, cell
        self.users, self.trusted = dict(users or {}), tuple(trusted)
        self.certificate, self.key = certificate, key
        self.tls, self.token, self.rate_hz = tls, token, rate_hz
        self.loopback = is_loopback(host)
        if not self.loopback and not (certificate and key and (self.users or trusted)):
            raise ValueError(f"off loopback ({host}) the OPC UA server needs its certificate "
                             f"and key, and users or trusted client certificates: anonymous "
                             f"access is for loopback only")
        self.application_uri = certificate and application_uri(certificate)
        self.server: Server | None = None
        self.feeds: list[DeviceFeed] = []
        self._stopped = asyncio.Event()

    async def start(self) -> None:
        certificates = None
        if self.trusted:
            certificates = CertificateUserManager()
            for path in self.trusted:
                await certificates.add_user(Path(path), name=Path(path).stem)
        server = Server(user_manager=CellUsers(self.users, certificates, self.loopback))
        await server.init()
        if self.application_uri:   # a client checks it against the certificate's
            await server.set_application_uri(self.application_uri)
        host = f"[{self.host}]" if ":" in self.host else self.host
        server.set_endpoint(f"opc.tcp://{host}:{self.port}")
        server.set_server_name(f"LandScape cell {self.cell}")
        tokens = ([ua.AnonymousIdentityToken] if self.loopback else [])
        if self.users:
            tokens.append(ua.UserNameIdentityToken)
        if self.trusted:
            tokens.append(ua.X509IdentityToken)
        server.set_identity_tokens(tokens)
        if self.certificate and self.key:
            await server.load_certificate(self.certificate)
            await server.load_private_key(self.key)
            policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
            server.set_security_policy(policies if not self.loopback
                                       else [ua.SecurityPolicyType.NoSecurity, *policies])
        else:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        model = RoboticsModel(server, self.cell)
        await model.build()
        await server.start()
        self.server = server
        self.port = server.bserver.port
        arms = {name: ArmFeed(model, name) for name in self.devices}
        self.feeds = [DeviceFeed(name, target, arms[name].callbacks(), rate_hz=self.rate_hz,
                                 tls=self.tls, token=self.token, client="opcua-bridge")
                      for name, target in self.devices.items()]

    async def run(self) -> None:
        if self.server is None:
            await self.start()
        tasks = [asyncio.create_task(feed.run()) for feed in self.feeds]
        await self._stopped.wait()
        for feed in self.feeds:
            feed.close()
        await asyncio.gather(*tasks, return_exceptions=True)
        await self.server.stop()

    def close(self) -> None:
        self._stopped.set()


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="landscape-opcua", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", action="append", default=[], metavar="NAME=HOST:PORT",
                        help="a device server to expose (repeat for each arm)")
    parser.add_argument("--cell", default="cell", help="the motion device system's name")
    parser.add_argument("--host", default="127.0.0.1",
                        help="where the OPC UA server listens (default %(default)s)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help="its port, 0 for any free one (default %(default)s)")
    parser.add_argument("--users", help="file of `<name> <SHA-256 of the password>` lines")
    parser.add_argument("--trusted-cert", action="append", default=[],
                        help="a client certificate (PEM or DER) allowed in; repeat")
    parser.add_argument("--certificate", help="this server's certificate (PEM or DER)")
    parser.add_argument("--key", help="the private key of --certificate (PEM)")
    credentials.add_arguments(parser)
    args = parser.parse_args(argv)
    devices = device_targets(parser, args.device)
    return args, devices


def main(argv=None) -> None:
    args, devices = parse_args(argv)
    logging.basicConfig(level=logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    logging.getLogger("asyncua").setLevel(logging.WARNING)
    try:
        users = load_users(args.users) if args.users else {}
    except (OSError, UsersError) as error:
        raise SystemExit(f"landscape-opcua: {error}") from None
    tls, token = credentials.from_arguments(args)
    try:
        bridge = OpcUaBridge(devices, args.host, args.port, args.cell, users=users,
                             trusted=tuple(args.trusted_cert), certificate=args.certificate,
                             key=args.key, tls=tls, token=token)
    except ValueError as error:
        raise SystemExit(f"landscape-opcua: {error}") from None
    asyncio.run(_serve(bridge))


async def _serve(bridge: OpcUaBridge) -> None:
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, bridge.close)
    await bridge.start()
    host = f"[{bridge.host}]" if ":" in bridge.host else bridge.host
    print(f"OPC UA server on opc.tcp://{host}:{bridge.port} "
          f"({', '.join(bridge.devices)})", flush=True)
    await bridge.run()
