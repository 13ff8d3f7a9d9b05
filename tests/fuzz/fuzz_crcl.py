"""A coverage-guided fuzz target (atheris, libFuzzer) for the gateway's reading of CRCL: the wire
splitter, the hardened XML parse, the schemas (when configured) and the typed parser, as a
connection's bytes go through them. Whatever the bytes, the outcome is documents and refusals
(WireError, XmlRefused, SchemaInvalid, CrclParseError), never another exception.

    python tests/fuzz/fuzz_crcl.py NEW_INPUTS_DIR tests/fuzz/corpus/crcl -max_total_time=60

(libFuzzer writes what it finds into the first folder: keep the repository's corpus second.)
"""
from __future__ import annotations

import sys

import atheris

with atheris.instrument_imports():
    from landscape.gateway import parse, wire, xmlsafe
    from landscape.gateway.schemas import SchemaInvalid, SchemaSet, default_directory

MAX_DOCUMENT = 1 << 16          # bytes: small, so that the size bound is reached too
_directory = default_directory()
SCHEMAS = SchemaSet(_directory) if _directory else None


def test_one_input(data: bytes) -> None:
    splitter = wire.DocumentSplitter(MAX_DOCUMENT)
    try:
        # as TCP may cut it: two reads, split where the first byte says
        cut = data[0] % (len(data) + 1) if data else 0
        items = splitter.feed(data[:cut]) + splitter.feed(data[cut:])
    except wire.WireError:
        return
    for item in items:
        if not isinstance(item, wire.Document):
            continue
        try:
            tree = xmlsafe.parse(item.data, MAX_DOCUMENT)
        except xmlsafe.XmlRefused:
            continue
        if SCHEMAS is not None:
            try:
                SCHEMAS.validate(tree)
            except SchemaInvalid:
                pass
        try:                    # the typed parser stands alone too (no schemas configured)
            parse.document(tree)
        except parse.CrclParseError:
            pass


if __name__ == "__main__":
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()
