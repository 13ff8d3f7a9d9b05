"""The typed parser and the schemas on NIST's examples and on bad documents."""
from __future__ import annotations

import pytest

from landscape.gateway import model as m
from landscape.gateway import parse, xmlsafe
from landscape.gateway.handlers import HANDLERS, SESSION_COMMANDS
from landscape.gateway.schemas import SchemaInvalid, SchemaSet

from crcl_support import EXAMPLES, XSD, XSD_2021, command, needs_examples, needs_xsd, pose

# A 2018 document (ConfigureStatusReport without the 2021 revision's sensor and guard flags):
# valid against crcl4java's schemas, not against the 2021 ones; the gateway reads both.
OLD_FORM = "commandConfigureStatusReport.xml"
DOCUMENTS = sorted(p for p in EXAMPLES.glob("*.xml") if not p.name.startswith(("status", "crcl4")))
needs_2021 = pytest.mark.skipif(XSD_2021 is None,
                                reason="NIST's 2021 CRCL schemas (../shared/crcl/xsd) are absent")


@needs_examples
@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: p.name)
def test_every_example_command_and_program_is_parsed(path):
    document = parse.document(xmlsafe.parse(path.read_bytes()))
    commands = document.commands if isinstance(document, m.Program) else [document.command]
    assert commands and all(c.command_id >= 0 for c in commands)


def test_a_2018_status_report_configuration_reports_no_sensors_and_no_guards():
    flags = "".join(f"<{tag}>true</{tag}>" for tag in (
        "ReportJointStatuses", "ReportPoseStatus", "ReportGripperStatus", "ReportSettingsStatus"))
    read = parse.document(xmlsafe.parse(command("ConfigureStatusReport", 3, flags))).command
    assert read.report_settings and not read.report_sensors and not read.report_guards
    with pytest.raises(parse.CrclParseError, match="expected <ReportGuardsStatus>, it ends"):
        parse.document(xmlsafe.parse(command("ConfigureStatusReport", 3, flags +
                                             "<ReportSensorsStatus>true</ReportSensorsStatus>")))


@needs_xsd
@needs_examples
@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.xml")), ids=lambda p: p.name)
def test_every_example_is_valid_against_the_installed_schemas(path):
    schemas = SchemaSet(XSD)
    assert schemas.revision == 2018     # crcl4java-base 1.8's
    schemas.validate(xmlsafe.parse(path.read_bytes()))


@needs_2021
@needs_examples
@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.xml")), ids=lambda p: p.name)
def test_the_2021_schemas_refuse_only_the_2018_status_report_configuration(path):
    schemas = SchemaSet(XSD_2021)
    assert schemas.revision == 2021
    tree = xmlsafe.parse(path.read_bytes())
    if path.name == OLD_FORM:
        with pytest.raises(SchemaInvalid, match="line 5: .*ReportSensorsStatus"):
            schemas.validate(tree)
    else:
        schemas.validate(tree)


@needs_examples
def test_the_example_program_reads_in_order():
    program = parse.document(xmlsafe.parse((EXAMPLES / "programExample.xml").read_bytes()))
    ids = [c.command_id for c in program.commands]
    assert ids == list(range(1, 42))
    move = program.commands[7]
    assert isinstance(move, m.MoveThroughTo) and move.num_positions == 2
    assert move.waypoints[1].point == m.Point(1.5, 1.0, 0.0001)


@needs_examples
def test_pose_and_set_settings_are_read():
    tree = xmlsafe.parse((EXAMPLES / "commandMoveThroughTo.xml").read_bytes())
    waypoint = parse.document(tree).command.waypoints[0]
    assert waypoint.settings.trans_speed == m.Rate(absolute=1.23)
    assert waypoint.settings.tolerance.z_axis == 0.5


def test_every_command_type_has_a_handler():
    assert set(m.COMMAND_TYPES.values()) == set(HANDLERS) | set(SESSION_COMMANDS)


def _command_types(directory) -> set[str]:
    from lxml import etree
    xs = "{http://www.w3.org/2001/XMLSchema}"
    schema = etree.parse(str(directory / "CRCLCommands.xsd"))
    return {t.get("name") for t in schema.iter(f"{xs}complexType")
            if t.get("abstract") != "true" and any(
                e.get("base") in ("MiddleCommandType", "CRCLCommandType")
                for e in t.iter(f"{xs}extension"))}


@needs_2021
def test_the_model_has_every_command_type_of_the_2021_schema():
    assert _command_types(XSD_2021) == set(m.COMMAND_TYPES)


@needs_xsd
def test_the_model_has_every_command_type_of_the_installed_schema():
    assert _command_types(XSD) <= set(m.COMMAND_TYPES)


@pytest.mark.parametrize("body, message", [
    ("<DwellTime>1_0</DwellTime>", "'1_0' is not a number"),
    ("<DwellTime>infinity</DwellTime>", "'infinity' is not a number"),
    ("<DwellTime>INF</DwellTime>", "INF is a double but not a usable value"),
    ("<DwellTime>-1</DwellTime>", "must not be negative"),
    ("", "expected <DwellTime>, it ends"),
    ("<DwellTime>1</DwellTime><Extra/>", "<Extra>: unexpected element"),
])
def test_bad_values_name_line_and_element(body, message):
    tree = xmlsafe.parse(command("Dwell", 5, body))
    with pytest.raises(parse.CrclParseError, match=message):
        parse.document(tree)


def test_pose_axes_must_be_unit_and_orthogonal():
    bad = command("MoveTo", 7, "<MoveStraight>true</MoveStraight>" +
                  pose(0.5, 0, 0.5, xaxis=(1, 0, 0), zaxis=(0.5, 0, -0.866)))
    with pytest.raises(parse.CrclParseError, match="orthogonal"):
        parse.document(xmlsafe.parse(bad))


def test_unknown_command_types_are_refused():
    with pytest.raises(parse.CrclParseError, match="xsi:type 'FlyType' is none of"):
        parse.document(xmlsafe.parse(command("Fly", 3)))


@pytest.mark.parametrize("document", [
    b'<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]><r>&x;</r>',
    b'<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><r>&b;</r>',
])
def test_dtds_and_entities_are_refused_before_parsing(document):
    with pytest.raises(xmlsafe.XmlRefused, match="DTDs and entities are not accepted"):
        xmlsafe.parse(document)


def test_an_undeclared_entity_is_not_well_formed():
    with pytest.raises(xmlsafe.XmlRefused, match="line 1: .*Entity 'x' not defined"):
        xmlsafe.parse(b"<r>&x;</r>")
