"""Development certificates: a cell's own CA, a server certificate for every device server,
and client certificates for mutual TLS (`landscape-cell certs`).

For a cell on a lab network, not for the Internet: the CA's key sits beside the
certificates (mode 0600), so keep the folder to the cell's administrators. Running it again
keeps the CA (clients that trust it go on trusting) and issues fresh certificates, so adding
a host name is one more run with one more --host.

Keys are ECDSA P-256; certificates last `days` (default 825, the longest that browsers and
Apple's TLS accept), the CA ten years. The OPC UA bridge's pair (opcua-server, and
opcua-client for a SCADA client to be trusted) has RSA 2048 keys instead, as its security
policy Basic256Sha256 requires (OPC UA Part 7), and names its application by a URI, as OPC
UA Part 6 (6.2.2) asks of an application instance certificate.
"""
from __future__ import annotations

import datetime
import ipaddress
import os
import socket
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec, rsa
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

# Names every development server certificate holds: loopback, and the service names of
# docker-compose.yml, so the same certificates serve `make run`, the compose cell and tests.
DEFAULT_HOSTS = ("localhost", "127.0.0.1", "::1", "arm1", "arm2", "gateway", "supervisor")
CA_DAYS = 3650
OPCUA_SERVER_URI = "urn:landscape-grpc:opcua-server"
OPCUA_CLIENT_URI = "urn:landscape-grpc:opcua-client"


@dataclass(frozen=True)
class CertFiles:
    """Where `make_certificates` wrote (PEM): the CA, the server pair, a client pair per
    client name (`clients[name] = (cert, key)`), and the OPC UA bridge's pairs."""

    ca: Path
    server_cert: Path
    server_key: Path
    clients: dict[str, tuple[Path, Path]]
    opcua_server: tuple[Path, Path] | None = None
    opcua_client: tuple[Path, Path] | None = None


def make_certificates(folder: str | Path, hosts=(), clients=("client",), days: int = 825,
                      new_ca: bool = False, opcua: bool = False) -> CertFiles:
    """CA (kept if present, unless new_ca), a server certificate for DEFAULT_HOSTS, this
    machine's name and `hosts` (names or IP addresses), a client certificate per name, and
    with `opcua` the OPC UA pairs (RSA keys take a second or two to make)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ca_cert_path, ca_key_path = folder / "ca.pem", folder / "ca-key.pem"
    if new_ca or not (ca_cert_path.exists() and ca_key_path.exists()):
        ca_key = ec.generate_private_key(ec.SECP256R1())
        ca_cert = _ca_certificate(ca_key)
        _write_key(ca_key_path, ca_key)
        ca_cert_path.write_bytes(ca_cert.public_bytes(serialization.Encoding.PEM))
    else:
        ca_key = serialization.load_pem_private_key(ca_key_path.read_bytes(), None)
        ca_cert = x509.load_pem_x509_certificate(ca_cert_path.read_bytes())
    names = list(dict.fromkeys((*DEFAULT_HOSTS, socket.gethostname(), *hosts)))
    server = _issue(folder / "server", "landscape device server", ca_cert, ca_key, days,
                    [ExtendedKeyUsageOID.SERVER_AUTH], _san(names))
    issued = {name: _issue(folder / name, name, ca_cert, ca_key, days,
                           [ExtendedKeyUsageOID.CLIENT_AUTH]) for name in clients}
    if not opcua:
        return CertFiles(ca_cert_path, *server, issued)
    both = [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
    pairs = [_issue(folder / stem, f"landscape {stem}", ca_cert, ca_key, days, both,
                    _san(hosts_named, uri), _rsa_key(), _OPCUA_USAGE)
             for stem, uri, hosts_named in (("opcua-server", OPCUA_SERVER_URI, names),
                                            ("opcua-client", OPCUA_CLIENT_URI, ()))]
    return CertFiles(ca_cert_path, *server, issued, *pairs)


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "LandScape cell"),
                      x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _now() -> datetime.datetime:
    return datetime.datetime.now(datetime.timezone.utc)


def _ca_certificate(key) -> x509.Certificate:
    name = _name("LandScape development CA")
    return (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(_now() - datetime.timedelta(minutes=5))
            .not_valid_after(_now() + datetime.timedelta(days=CA_DAYS))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True,
                                         crl_sign=True, content_commitment=False,
                                         key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False,
                                         decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                           critical=False)
            .sign(key, hashes.SHA256()))


# What OPC UA asks of an application instance certificate's key (Part 6, 6.2.2).
_OPCUA_USAGE = x509.KeyUsage(digital_signature=True, content_commitment=True,
                             key_encipherment=True, data_encipherment=True, key_agreement=False,
                             key_cert_sign=False, crl_sign=False, encipher_only=False,
                             decipher_only=False)


def _rsa_key():
    return rsa.generate_private_key(public_exponent=65537, key_size=2048)


def _san(names, uri: str | None = None) -> x509.SubjectAlternativeName:
    entries = [x509.UniformResourceIdentifier(uri)] if uri else []
    for name in names:
        try:
            entries.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            entries.append(x509.DNSName(name))
    return x509.SubjectAlternativeName(entries)


def _issue(stem: Path, common_name: str, ca_cert, ca_key, days: int, usages,
           san: x509.SubjectAlternativeName | None = None, key=None,
           key_usage: x509.KeyUsage | None = None) -> tuple[Path, Path]:
    """A certificate signed by the CA (an ECDSA key unless `key` is given); its files."""
    key = key or ec.generate_private_key(ec.SECP256R1())
    builder = (x509.CertificateBuilder().subject_name(_name(common_name))
               .issuer_name(ca_cert.subject).public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .not_valid_before(_now() - datetime.timedelta(minutes=5))
               .not_valid_after(_now() + datetime.timedelta(days=days))
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                   ca_key.public_key()), critical=False))
    if san is not None:
        builder = builder.add_extension(san, critical=False)
    if key_usage is not None:
        builder = builder.add_extension(key_usage, critical=True)
    cert = builder.sign(ca_key, hashes.SHA256())
    cert_path, key_path = stem.with_suffix(".pem"), Path(f"{stem}-key.pem")
    _write_key(key_path, key)
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return cert_path, key_path


def _write_key(path: Path, key) -> None:
    data = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(data)
    os.chmod(path, 0o600)
