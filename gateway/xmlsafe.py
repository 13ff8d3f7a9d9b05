"""Hardened XML parsing of untrusted CRCL documents, with lxml (libxml2).

Why lxml rather than defusedxml: the gateway needs XSD validation against the official schemas
on every document, and lxml's (libxml2's, in C) is the validator; parsing with the same library
hands the validator a tree without a second parse. libxml2's parser is hardened here by its
options, and by refusing what CRCL never needs before the parser sees it:

- no DTD at all: a document with a DOCTYPE is refused (so no entity can be declared, hence no
  entity expansion, internal or external; "billion laughs" cannot start);
- resolve_entities=False, load_dtd=False, no_network=True: no file or network access even if a
  DOCTYPE got through (defence in depth; checked again on the parsed tree);
- huge_tree=False keeps libxml2's own limits on depth and text size; the gateway's size bound
  (wire.py) comes first;
- processing instructions and comments are dropped from the tree.
"""
from __future__ import annotations

from lxml import etree

from landscape.gateway.wire import DEFAULT_MAX_DOCUMENT


class XmlRefused(Exception):
    """A document that is not well-formed XML or uses what the gateway does not accept."""


def _parser() -> etree.XMLParser:
    return etree.XMLParser(resolve_entities=False, load_dtd=False, dtd_validation=False,
                           no_network=True, huge_tree=False, remove_pis=True,
                           remove_comments=True, collect_ids=False)


_PARSER = _parser()


def parse(data: bytes, max_size: int = DEFAULT_MAX_DOCUMENT) -> etree._ElementTree:
    """The document's tree; raises XmlRefused saying what is wrong and where (line)."""
    if len(data) > max_size:
        raise XmlRefused(f"document longer than {max_size} bytes")
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        raise XmlRefused("a DOCTYPE or entity declaration: DTDs and entities are not accepted")
    try:
        root = etree.fromstring(data, _PARSER)
    except etree.XMLSyntaxError as error:
        line = f"line {error.lineno}: " if error.lineno else ""
        raise XmlRefused(f"not well-formed XML: {line}{error.msg}") from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise XmlRefused("a DOCTYPE: DTDs and entities are not accepted")
    return tree
