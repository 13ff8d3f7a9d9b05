"""Hostile XML against the real gateway: a CRCL_Error or a closed connection, never a crash or
a file or network access, and the gateway keeps serving its other clients. (Browsers' HTTP
requests: test_crcl_port.py.)"""
from __future__ import annotations

import http.server
import threading

import pytest

from crcl_support import RawClient, command, field


@pytest.fixture
def bystander(gateway):
    """Another client with a session, which must keep being served."""
    client = RawClient(gateway.port)
    assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
    yield client
    assert field(client.run("Dwell", 99, "<DwellTime>0</DwellTime>"), "CommandState") == "CRCL_Done"
    client.close()


@pytest.fixture
def web():
    """A local HTTP server that counts requests: no document may make the gateway fetch."""
    hits = []

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            hits.append(self.path)
            self.send_response(200)
            self.end_headers()
            self.wfile.write(b"<x>pwned</x>")

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server.server_address[1], hits
    server.shutdown()


def closed(client: RawClient) -> bool:
    try:
        client.status()
    except (ConnectionError, OSError):
        return True
    return False


def refused_then_closed(client: RawClient) -> bool:
    """A declaration is answered with a CRCL_Error status saying so, then the close."""
    status = client.read_status()
    return (field(status, "CommandState") == "CRCL_Error"
            and "DOCTYPE" in field(status, "StateDescription") and closed(client))


def test_external_entities_close_the_connection_without_any_fetch(gateway, bystander, web, tmp_path):
    port, hits = web
    secret = tmp_path / "secret"
    secret.write_text("do not read")
    for target in (f"http://127.0.0.1:{port}/e", secret.as_uri()):
        attacker = RawClient(gateway.port)
        attacker.send(f'<?xml version="1.0"?><!DOCTYPE CRCLCommandInstance [<!ENTITY x SYSTEM '
                      f'"{target}">]>'.encode() + command("Message", 1, "<Message>&x;</Message>"))
        assert refused_then_closed(attacker)
        attacker.close()
    schema_hint = command("GetStatus", 2).replace(
        b"<CRCLCommandInstance ", f'<CRCLCommandInstance xsi:noNamespaceSchemaLocation='
                                  f'"http://127.0.0.1:{port}/s.xsd" '.encode())
    client = RawClient(gateway.port)
    client.send(schema_hint)
    assert field(client.read_status(), "StatusID")
    client.close()
    assert hits == []


def test_entity_expansion_closes_the_connection(gateway, bystander):
    laughs = b'<!DOCTYPE r [<!ENTITY a "lol">' + b"".join(
        f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">'.encode() for i in range(9)) + b"]>"
    attacker = RawClient(gateway.port)
    attacker.send(b'<?xml version="1.0"?>' + laughs + b"<r>&j;</r>")
    assert refused_then_closed(attacker)
    attacker.close()


def test_a_100_mb_document_is_refused_and_the_connection_goes_on(gateway, bystander):
    attacker = RawClient(gateway.port, timeout=120)
    head = command("Message", 7, "<Message>").split(b"<Message>")[0] + b"<Message>"
    attacker.send(head)
    block = b"A" * (1 << 20)
    for _ in range(100):
        attacker.send(block)
    attacker.send(b"</Message></CRCLCommand></CRCLCommandInstance>")
    status = attacker.status()
    assert field(status, "CommandState") == "CRCL_Error"
    assert "longer than" in field(status, "StateDescription")
    assert field(attacker.run("InitCanon", 8), "CommandState") in ("CRCL_Done", "CRCL_Error")
    attacker.close()


def test_truncated_and_interleaved_documents_are_errors(gateway, bystander):
    client = RawClient(gateway.port)
    a = command("Dwell", 11, "<DwellTime>0</DwellTime>")
    b = command("GetStatus", 12)
    client.send(a[:len(a) // 2] + b)                       # a cut short, then b
    status = client.read_status()
    assert field(status, "CommandState") == "CRCL_Error"
    assert "truncated" in field(status, "StateDescription")
    client.send(b"</CRCLCommandInstance>" * 3 + command("GetStatus", 13))
    assert field(client.read_status(), "CommandState") == "CRCL_Error"
    client.send(b"junk" + command("GetStatus", 14))       # text outside a document: the end
    assert closed(client)
    client.close()
    interleaved = RawClient(gateway.port)                  # the halves leave text outside
    interleaved.send(a[:40] + b[:60] + a[40:] + b[60:])
    interleaved.send(command("GetStatus", 15))
    assert closed(interleaved)
    interleaved.close()


def test_a_document_cut_at_a_tag_boundary_then_undeclared_documents_are_answered(gateway, bystander):
    """The next root element, with no XML declaration before it, resynchronises the wire."""
    client = RawClient(gateway.port, timeout=10)
    a = command("Dwell", 15, "<DwellTime>0</DwellTime>")
    bare = [command("GetStatus", i).split(b"?>", 1)[1].strip() for i in (16, 17)]
    client.send(a[:a.index(b"</CRCLCommand>")] + bare[0] + bare[1])
    first, second = client.read_status(), client.read_status()
    assert field(first, "CommandState") == "CRCL_Error"
    assert "truncated" in field(first, "StateDescription")
    assert int(field(second, "StatusID")) == int(field(first, "StatusID")) + 1
    client.close()


def test_nonsense_values_are_errors_not_crashes(gateway, bystander):
    client = RawClient(gateway.port)
    for body in ("<DwellTime>1e999999</DwellTime>", "<DwellTime>nan</DwellTime>",
                 "<DwellTime>" + "9" * 5000 + "</DwellTime>"):
        client.send(command("Dwell", 21, body))
        assert field(client.status(), "CommandState") == "CRCL_Error"
    client.send(b"<\x00C\x00" + b"\x00" * 10 + command("GetStatus", 22))
    client.send(command("GetStatus", 23))
    assert field(client.read_status(), "StatusID")
    client.close()
    utf16 = RawClient(gateway.port)                       # a BOM is no '<': the end
    utf16.send(b"\xff\xfe<\x00C\x00" + command("GetStatus", 24))
    assert closed(utf16)
    utf16.close()
