"""Validation against the official CRCL schemas, read from a directory at run time.

The schema files are NIST's (../shared/crcl/xsd); they are never copied into the repository.
The gateway works without them (its typed parser checks every command), and is strictly
conformant with them when they are configured. Each instance is validated against the schema of
its root element; `xsi:noNamespaceSchemaLocation` hints in documents are ignored (never
fetched).
"""
from __future__ import annotations

import os
from pathlib import Path

from lxml import etree

# Where the project keeps NIST's schemas beside the repository (see ../shared/crcl/README.md).
SHARED_SCHEMAS = Path(__file__).resolve().parents[2] / "shared" / "crcl" / "xsd"
SCHEMAS_ENV = "LANDSCAPE_CRCL_SCHEMAS"

ROOT_SCHEMAS = {"CRCLCommandInstance": "CRCLCommandInstance.xsd",
                "CRCLProgram": "CRCLProgramInstance.xsd",
                "CRCLStatus": "CRCLStatus.xsd"}


class SchemaInvalid(Exception):
    """The document breaks the schema; the message names the line and element."""


def default_directory() -> Path | None:
    """$LANDSCAPE_CRCL_SCHEMAS, else ../shared/crcl/xsd beside the checkout, if present."""
    configured = os.environ.get(SCHEMAS_ENV)
    if configured:
        return Path(configured)
    return SHARED_SCHEMAS if (SHARED_SCHEMAS / "CRCLCommands.xsd").is_file() else None


class SchemaSet:
    """The three instance schemas of a directory, compiled once."""

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
