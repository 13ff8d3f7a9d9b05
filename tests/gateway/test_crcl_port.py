"""The CRCL port is no place for a browser (issue 25 item 2): the bytes Chromium sends for a
form POST or a fetch POST to localhost:64444 end the connection before anything runs, a
DOCTYPE is answered with a CRCL_Error status before the close, a document left unfinished is
dropped after the gateway's idle time, and the errors the gateway raises are logged."""
from __future__ import annotations

import logging
import socket

import numpy as np
import pytest

from landscape.server.device.states import State

from crcl_support import RawClient, RunningGateway, command, field, pose

# The requests as Debian's Chromium sends them (captured from /usr/bin/chromium 156): a page
# on another origin submitting a form with enctype="text/plain" (the body is name=value, so
# the page names its input '<?xml version' and puts the rest of the documents in its value),
# and the same page calling fetch() in no-cors mode, whose string body goes as it is.
USER_AGENT = (b"Mozilla/5.0 (X11; Linux x86_64) AppleWebKit/537.36 (KHTML, like Gecko) "
              b"HeadlessChrome/156.0.0.0 Safari/537.36")
FORM_POST = (b"POST / HTTP/1.1\r\nHost: 127.0.0.1:%(port)d\r\nConnection: keep-alive\r\n"
             b"Content-Length: %(length)d\r\nCache-Control: max-age=0\r\n"
             b'sec-ch-ua: "Not:A-Brand";v="8", "Chromium";v="156"\r\nsec-ch-ua-mobile: ?0\r\n'
             b'sec-ch-ua-platform: "Linux"\r\nUpgrade-Insecure-Requests: 1\r\n'
             b"Content-Type: text/plain\r\nUser-Agent: %(agent)s\r\n"
             b"Origin: http://localhost:42477\r\nAccept: text/html,application/xhtml+xml,"
             b"application/xml;q=0.9,image/jxl,image/avif,image/webp,image/apng,*/*;q=0.8,"
             b"application/signed-exchange;v=b3;q=0.7\r\nSec-Fetch-Site: cross-site\r\n"
             b"Sec-Fetch-Mode: navigate\r\nSec-Fetch-User: ?1\r\nSec-Fetch-Dest: document\r\n"
             b"Referer: http://localhost:42477/\r\nAccept-Encoding: gzip, deflate, br, zstd\r\n"
             b"Accept-Language: en-US,en;q=0.9\r\n\r\n%(body)s")
FETCH_POST = (b"POST / HTTP/1.1\r\nHost: 127.0.0.1:%(port)d\r\nConnection: keep-alive\r\n"
              b'Content-Length: %(length)d\r\nsec-ch-ua-platform: "Linux"\r\n'
              b"User-Agent: %(agent)s\r\n"
              b'sec-ch-ua: "Not:A-Brand";v="8", "Chromium";v="156"\r\n'
              b"Content-Type: application/x-www-form-urlencoded\r\nsec-ch-ua-mobile: ?0\r\n"
              b"Accept: */*\r\nOrigin: http://localhost:42477\r\nSec-Fetch-Site: cross-site\r\n"
              b"Sec-Fetch-Mode: no-cors\r\nSec-Fetch-Dest: empty\r\n"
              b"Referer: http://localhost:42477/\r\nAccept-Encoding: gzip, deflate, br, zstd\r\n"
              b"Accept-Language: en-US,en;q=0.9\r\n\r\n%(body)s")
MOVE = command("MoveTo", 2, "<MoveStraight>false</MoveStraight>" + pose(0.5, 0.3, 0.5))


def form_body(documents: bytes) -> bytes:
    """A text/plain form's body: the input's name, '=', its value, CRLF."""
    name, value = documents.split(b"=", 1)
    return name + b"=" + value + b"\r\n"


def request(template: bytes, port: int, body: bytes) -> bytes:
    return template % {b"port": port, b"length": len(body), b"agent": USER_AGENT, b"body": body}


def closed_without_reply(sock: socket.socket, timeout: float = 10.0) -> bool:
    """The gateway closed the connection and sent nothing back."""
    sock.settimeout(timeout)
    received = b""
    try:
        while chunk := sock.recv(65536):
            received += chunk
    except ConnectionResetError:
        pass
    except TimeoutError:
        return False
    return received == b""


def peer_lines(caplog, sock: socket.socket) -> list[str]:
    host, port = sock.getsockname()
    return [r.getMessage() for r in caplog.records if f"{host}:{port}" in r.getMessage()]


@pytest.mark.parametrize("template, body", [
    (FORM_POST, form_body(command("InitCanon", 1) + MOVE)),
    (FETCH_POST, command("InitCanon", 1) + MOVE),
], ids=["form-post", "fetch-post"])
def test_a_browsers_post_ends_the_connection_and_nothing_runs(server, gateway, caplog,
                                                              template, body):
    caplog.set_level(logging.INFO, logger="landscape.gateway")
    joints = server.device.feedback().position.copy()
    sock = socket.create_connection(("127.0.0.1", gateway.port))
    sock.sendall(request(template, gateway.port, body))
    assert closed_without_reply(sock)
    lines = peer_lines(caplog, sock)
    sock.close()
    assert server.device.state is State.UNLOCKED and not server.device.status().locked
    assert np.abs(server.device.feedback().position - joints).max() < 1e-6   # not 0.53 rad
    assert len(lines) == 1 and "outside any CRCL document" in lines[0], lines


def test_the_gateway_serves_other_clients_after_a_post(server, gateway):
    sock = socket.create_connection(("127.0.0.1", gateway.port))
    sock.sendall(request(FETCH_POST, gateway.port, command("InitCanon", 1) + MOVE))
    assert closed_without_reply(sock)
    sock.close()
    client = RawClient(gateway.port)
    assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
    client.close()


def test_a_doctype_gets_an_error_status_then_the_close(gateway, caplog):
    caplog.set_level(logging.INFO, logger="landscape.gateway")
    client = RawClient(gateway.port, timeout=10)
    client.send(b'<?xml version="1.0"?><!DOCTYPE CRCLCommandInstance [<!ENTITY x "y">]>'
                + command("GetStatus", 5))
    status = client.read_status()            # validated against CRCLStatus.xsd
    assert field(status, "CommandState") == "CRCL_Error"
    assert "DOCTYPE" in field(status, "StateDescription")
    assert closed_without_reply(client.sock)
    assert len(peer_lines(caplog, client.sock)) == 1
    client.close()


def test_a_document_left_unfinished_is_dropped_after_the_idle_time(server):
    running = RunningGateway(server.target, document_idle=0.5)
    try:
        idle = RawClient(running.port)                 # between documents: kept
        cut = RawClient(running.port)
        cut.send(command("GetStatus", 1)[:60])         # half a document, then nothing
        assert closed_without_reply(cut.sock)
        assert field(idle.status(), "CommandState")    # still served
        idle.close()
        cut.close()
    finally:
        running.close()


def test_an_error_the_gateway_raises_is_logged(gateway, caplog):
    caplog.set_level(logging.INFO, logger="landscape.gateway")
    client = RawClient(gateway.port)
    status = client.run("MoveTo", 3, "<MoveStraight>false</MoveStraight>" + pose(0.5, 0, 0.5))
    assert field(status, "CommandState") == "CRCL_Error"
    # The status adds why the device's state is not current, if it is not ("; no state from
    # the device yet" right after the connection): the log says the command's own error.
    description = field(status, "StateDescription")
    logged = [line.split(": command 3: ", 1)[1] for line in peer_lines(caplog, client.sock)
              if ": command 3: " in line]
    assert logged and description.startswith(logged[0]), (description, caplog.text)
    client.close()
