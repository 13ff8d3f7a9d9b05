"""NIST's schemas are the project's own dependency: `make install` unpacks them from
crcl4java-base 1.8 (Maven Central) into .tools/crcl-schemas, the gateway's default; the gateway
says at start what it validates against, and never reads ../shared/crcl/xsd by itself."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from landscape.gateway import schemas

from crcl_support import XSD, XSD_2021, RawClient, command, field, needs_xsd, pose

GATEWAY = [sys.executable, "-m", "landscape.gateway", "--device", "127.0.0.1:1", "--port", "0"]
GUARDED_MOVE = ("<Guard><SensorID>force_sensor</SensorID><SubField>Fz</SubField><LimitType>"
                "INCREASE_OVER_LIMIT</LimitType><LimitValue>20</LimitValue></Guard>"
                "<MoveStraight>true</MoveStraight>" + pose(0.5, 0, 0.5))


def test_the_default_is_the_environment_then_the_installed_schemas_never_the_shared_folder(
        monkeypatch, tmp_path):
    monkeypatch.setenv(schemas.SCHEMAS_ENV, str(tmp_path))
    assert schemas.default_directory() == tmp_path
    monkeypatch.delenv(schemas.SCHEMAS_ENV)
    monkeypatch.setattr(schemas, "INSTALLED", tmp_path / "not-installed")
    assert schemas.default_directory() is None          # whatever ../shared holds


def _first_log_line(*flags: str, env: dict | None = None) -> str:
    """The gateway's line about its schemas (it starts without a device to talk to)."""
    gateway = subprocess.Popen([*GATEWAY, *flags], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})})
    try:
        for line in gateway.stderr:
            if "validating CRCL documents against" in line:
                return line
        raise AssertionError("the gateway said nothing of its schemas")
    finally:
        gateway.terminate()
        gateway.wait(timeout=20)


@needs_xsd
def test_the_gateway_says_at_start_which_schemas_it_validates_against():
    line = _first_log_line(env={schemas.SCHEMAS_ENV: ""})
    assert f"NIST's CRCL schemas in {XSD} (2018 revision, as crcl4java 1.8" in line
    assert "INFO" in line


def test_without_schemas_the_gateway_says_so_loudly():
    line = _first_log_line("--schemas", "none")
    assert "WARNING" in line and "NO SCHEMAS" in line and "make tools" in line


@pytest.mark.skipif(XSD_2021 is None, reason="NIST's 2021 schemas (../shared/crcl/xsd) are absent")
def test_another_folder_is_named_by_the_environment():
    line = _first_log_line(env={schemas.SCHEMAS_ENV: str(XSD_2021)})
    assert f"NIST's CRCL schemas in {XSD_2021} (2021 revision)" in line


@needs_xsd
def test_the_installed_schemas_refuse_a_2021_document_naming_the_element(gateway):
    """crcl4java-base 1.8's schemas know no Guard: the document is refused with the schema's
    reason, and the session goes on."""
    client = RawClient(gateway.port)
    try:
        client.run("InitCanon", 1)
        client.send(command("MoveTo", 2, GUARDED_MOVE))
        refused = client.status()
        assert field(refused, "CommandState") == "CRCL_Error"
        assert "document refused: line 2: Element 'Guard': This element is not expected" in \
            field(refused, "StateDescription")
        assert field(client.run("Dwell", 3, "<DwellTime>0</DwellTime>"),
                     "CommandState") == "CRCL_Done"
    finally:
        client.close()
