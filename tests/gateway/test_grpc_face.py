"""CrclService: CRCL over gRPC against the real gateway and device server."""
from __future__ import annotations

import grpc
import pytest

from landscape.gateway.grpc_face import serve_grpc
from landscape.v1 import crcl_service_pb2 as pb
from landscape.v1 import crcl_service_pb2_grpc

from crcl_support import EXAMPLES, check_status, command, reachable_program, needs_examples
from test_hostile import web  # noqa: F401 - the fixture


@pytest.fixture
def crcl(gateway):
    server, port = gateway.run(serve_grpc(gateway.link, gateway.options, "127.0.0.1", 0))
    with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
        yield crcl_service_pb2_grpc.CrclServiceStub(channel)
    gateway.run(server.stop(None))


def execute(stub, *documents: bytes) -> list[pb.ExecuteResponse]:
    replies = list(stub.Execute((pb.ExecuteRequest(xml=d.decode()) for d in documents), timeout=120))
    for reply in replies:
        check_status(reply.status_xml.encode())
    return replies


def test_a_program_streams_a_status_per_command_and_ends_done(crcl):
    replies = execute(crcl, reachable_program())
    assert replies[-1].command_state == "CRCL_Done"
    assert "program done: 13 commands" in replies[-1].state_description
    working = {r.command_id for r in replies if r.command_state == "CRCL_Working"}
    assert working == set(range(1, 14))
    assert "<ProgramIndex>12</ProgramIndex>" in replies[-2].status_xml


def test_commands_one_at_a_time_and_get_status(crcl):
    replies = execute(crcl, command("InitCanon", 1), command("GetStatus", 2),
                      command("Dwell", 3, "<DwellTime>0.01</DwellTime>"), command("EndCanon", 4))
    finished = [(r.command_id, r.command_state) for r in replies if r.command_state != "CRCL_Working"]
    assert (1, "CRCL_Done") in finished and (4, "CRCL_Done") == finished[-1]


@needs_examples
def test_a_failing_program_ends_with_the_error_naming_the_command(crcl):
    replies = execute(crcl, (EXAMPLES / "programAll.xml").read_bytes())
    assert replies[-1].command_state == "CRCL_Error"
    assert "program stopped at command 1 (ActuateJoints, CommandID 2)" in replies[-1].state_description


def test_an_invalid_document_is_an_error_status(crcl):
    replies = execute(crcl, b"<CRCLCommandInstance>", command("GetStatus", 5))
    assert replies[0].command_state == "CRCL_Error"
    assert "document refused" in replies[0].state_description


def _refused_then_served(stub, document: bytes) -> str:
    """Send a hostile document then a GetStatus on one stream: the first reply is an error,
    and the stream goes on; returns the error's description."""
    replies = execute(stub, document, command("GetStatus", 2))
    assert replies[0].command_state == "CRCL_Error", replies[0]
    assert replies[1].status_xml.count("<StatusID>") == 1
    return replies[0].state_description


def test_hostile_xml_over_grpc_is_refused_and_the_service_goes_on(crcl, web, tmp_path):
    port, hits = web
    secret = tmp_path / "secret"
    secret.write_text("do not read")
    for target in (f"http://127.0.0.1:{port}/e", secret.as_uri()):
        external = (f'<?xml version="1.0"?><!DOCTYPE CRCLCommandInstance [<!ENTITY x SYSTEM '
                    f'"{target}">]>').encode() + command("Message", 1, "<Message>&x;</Message>")
        assert "DTDs and entities are not accepted" in _refused_then_served(crcl, external)
    laughs = b'<!DOCTYPE r [<!ENTITY a "lol">' + b"".join(
        f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">'.encode()
        for i in range(9)) + b"]><r>&j;</r>"
    assert "DTDs and entities" in _refused_then_served(crcl, laughs)
    schema_hint = command("GetStatus", 3).replace(
        b"<CRCLCommandInstance ", f'<CRCLCommandInstance xsi:noNamespaceSchemaLocation='
                                  f'"http://127.0.0.1:{port}/s.xsd" '.encode())
    assert execute(crcl, schema_hint)[0].status_xml
    assert hits == []
    a = command("Dwell", 4, "<DwellTime>0</DwellTime>")
    assert "not well-formed" in _refused_then_served(crcl, a[:len(a) // 2])
    assert "not well-formed" in _refused_then_served(crcl, a[:60] + a)       # two roots in one
    big = a.replace(b"<DwellTime>", b"<!--" + b"x" * (2 << 20) + b"--><DwellTime>")
    assert "longer than" in _refused_then_served(crcl, big)


def test_a_message_past_grpc_limit_fails_that_call_only(crcl):
    huge = command("Message", 1, "<Message>" + "A" * (8 << 20) + "</Message>")   # > 4 MB
    with pytest.raises(grpc.RpcError) as failure:
        execute(crcl, huge)
    assert failure.value.code() is grpc.StatusCode.RESOURCE_EXHAUSTED
    assert execute(crcl, command("GetStatus", 2))[-1].status_xml
