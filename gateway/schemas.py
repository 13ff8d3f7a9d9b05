"""Validation against NIST's CRCL schemas, read from a folder at run time.

`make tools` installs them: Maven fetches NIST's crcl4java-base 1.8 from Maven Central and the
Makefile unpacks its five XSDs into .tools/crcl-schemas (never committed). That is the default
folder; `--schemas DIR` or $LANDSCAPE_CRCL_SCHEMAS names another (NIST's 2021 revision from
usnistgov/crcl, say). The gateway works without them (its typed parser checks every command)
and is strictly conformant with them when they are there; it says at start which it uses.

Two revisions are in use: crcl4java-base 1.8 carries the 2018 one, which NIST's Java client
speaks; the 2021 one adds guards, sensors, grippers' and parameters' reporting, loop blocks
and joint tolerances, and renames SettingsStatus's PoseTolerance to EndPoseTolerance. A
SchemaSet knows which it holds, so statuses are written in that revision (status.py). Each
instance is validated against the schema of its root element; `xsi:noNamespaceSchemaLocation`
hints in documents are ignored (never fetched).
"""
from __future__ import annotations

import os
from pathlib import Path

from lxml import etree

SCHEMAS_ENV = "LANDSCAPE_CRCL_SCHEMAS"
# Where `make tools` puts them, in the checkout this package runs from (an editable install).
INSTALLED = Path(__file__).resolve().parents[1] / ".tools" / "crcl-schemas"
INSTALL_HINT = "`make tools` installs NIST's (crcl4java-base 1.8 from Maven Central)"
NEWEST = 2021

ROOT_SCHEMAS = {"CRCLCommandInstance": "CRCLCommandInstance.xsd",
                "CRCLProgram": "CRCLProgramInstance.xsd",
                "CRCLStatus": "CRCLStatus.xsd"}
_XS = "{http://www.w3.org/2001/XMLSchema}"


class SchemaInvalid(Exception):
    """The document breaks the schema; the message names the line and element."""


def default_directory() -> Path | None:
    """$LANDSCAPE_CRCL_SCHEMAS, else the schemas `make tools` installed, if they are there."""
    configured = os.environ.get(SCHEMAS_ENV)
    if configured:
        return Path(configured)
    return INSTALLED if (INSTALLED / "CRCLCommands.xsd").is_file() else None


class SchemaSet:
    """The three instance schemas of a folder, compiled once, and their revision."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)
        # The schema files are trusted local files: xs:include may read its siblings, but
        # nothing is fetched from the network.
        parser = etree.XMLParser(no_network=True, resolve_entities=False)
        self._schemas = {}
        for root, filename in ROOT_SCHEMAS.items():
            path = self.directory / filename
            if not path.is_file():
                raise FileNotFoundError(f"CRCL schema {path} not found")
            self._schemas[root] = etree.XMLSchema(etree.parse(str(path), parser))
        primitives = etree.parse(str(self.directory / "DataPrimitives.xsd"), parser)
        self.revision = 2021 if primitives.find(
            f"{_XS}complexType[@name='GuardType']") is not None else 2018

    def describe(self) -> str:
        """For the start-up line: where they are, and what their revision accepts."""
        if self.revision >= NEWEST:
            return f"NIST's CRCL schemas in {self.directory} (2021 revision)"
        return (f"NIST's CRCL schemas in {self.directory} (2018 revision, as crcl4java 1.8: "
                f"documents with the 2021 revision's guards, sensors, gripper and parameter "
                f"reports, loop blocks or joint tolerances are refused)")

    def validate(self, tree: etree._ElementTree) -> None:
        """Raises SchemaInvalid with the first error (line and element) if the tree breaks
        the schema of its root element."""
        root = tree.getroot()
        schema = self._schemas.get(root.tag)
        if schema is None:
            raise SchemaInvalid(f"line {root.sourceline}: root element <{root.tag}> is none of "
                                f"{', '.join(ROOT_SCHEMAS)}")
        if not schema.validate(tree):
            error = schema.error_log[0]
            raise SchemaInvalid(f"line {error.line}: {error.message} "
                                f"(against {ROOT_SCHEMAS[root.tag]})")


def describe(schemas: SchemaSet | None) -> str:
    """What the gateway validates against, for its start-up line."""
    if schemas is None:
        return ("NO SCHEMAS: documents are checked by the gateway's own parser only, not "
                f"against NIST's CRCL schemas ({INSTALL_HINT}, or give --schemas DIR)")
    return schemas.describe()
