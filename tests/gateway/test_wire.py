"""The wire splitter: documents found in a byte stream however TCP cuts it."""
from __future__ import annotations

import pytest

from landscape.gateway.wire import (DeclarationRefused, Document, DocumentSplitter,
                                    OutsideDocument, Refused, WireError)

from crcl_support import EXAMPLES, command, pose

# NIST's example commands when they are beside the checkout; our own otherwise.
COMMANDS = [p.read_bytes().strip() for p in sorted(EXAMPLES.glob("command*.xml"))] or [
    command("InitCanon", 1), command("SetLengthUnits", 2, "<UnitName>meter</UnitName>"),
    command("MoveTo", 3, "<MoveStraight>true</MoveStraight>" + pose(0.5, 0.1, 0.6)),
    command("Dwell", 4, "<DwellTime>0.5</DwellTime>"), command("GetStatus", 5),
    command("EndCanon", 6)]


def documents(items):
    return [i.data for i in items if isinstance(i, Document)]


def test_documents_split_byte_by_byte_come_out_whole():
    stream = b"\n \t".join(COMMANDS)
    splitter, out = DocumentSplitter(), []
    for i in range(len(stream)):
        out += splitter.feed(stream[i:i + 1])
    assert [d.strip() for d in documents(out)] == [c.strip() for c in COMMANDS]
    assert splitter.pending == 0


def test_coalesced_documents_and_odd_markup():
    tricky = (b'<?xml version="1.0"?><!-- </A> --><A x="a>b" y=\'</A>\'><B/><![CDATA[</A>]]>'
              b'<C>t</C></A>')
    out = DocumentSplitter().feed(tricky + b"  " + tricky + COMMANDS[0])
    assert documents(out) == [tricky, tricky, COMMANDS[0]]


def test_a_declaration_starts_the_document_after_whitespace():
    out = DocumentSplitter().feed(b"\r\n  " + COMMANDS[0])
    assert documents(out)[0].startswith(b"<?xml")


def test_an_oversized_document_is_dropped_and_the_next_one_is_read():
    splitter = DocumentSplitter(max_document=2000)
    big = b"<A>" + b"<B>" + b"x" * 10_000 + b"</B>" * 1 + b"</A>"
    out = []
    for i in range(0, len(big), 333):
        out += splitter.feed(big[i:i + 333])
        assert splitter.pending <= 2000 + 333
    out += splitter.feed(COMMANDS[1])
    assert isinstance(out[0], Refused) and "longer than 2000 bytes" in out[0].reason
    assert documents(out) == [COMMANDS[1]]


@pytest.mark.parametrize("before", [b"garbage", b"POST / HTTP/1.1\r\nHost: x\r\n\r\n",
                                    b"\xef\xbb\xbf", COMMANDS[0] + b" x"])
def test_bytes_outside_a_document_end_the_stream(before):
    splitter = DocumentSplitter()
    with pytest.raises(OutsideDocument, match="outside any CRCL document"):
        splitter.feed(before + COMMANDS[1])


def test_declarations_comments_and_instructions_may_come_between_documents():
    between = b'\n<!-- next --> <?crcl hint?>\r\n'
    out = DocumentSplitter().feed(COMMANDS[0] + between + COMMANDS[1])
    assert [d.strip() for d in documents(out)] == [COMMANDS[0], (between + COMMANDS[1]).strip()]


@pytest.mark.parametrize("declaration", [b"<!DOCTYPE A [<!ENTITY e 'x'>]>", b"<!ENTITY e 'x'>"])
def test_a_dtd_ends_the_stream(declaration):
    with pytest.raises(DeclarationRefused, match="DTD"):
        DocumentSplitter().feed(b'<?xml version="1.0"?>' + declaration + b"<A>&e;</A>")


def test_a_single_endless_token_ends_the_stream():
    splitter = DocumentSplitter(max_document=1000)
    with pytest.raises(WireError, match="token"):
        splitter.feed(b'<A x="' + b"y" * 5000)


def test_a_truncated_document_is_refused_where_the_next_declaration_starts():
    cut = COMMANDS[0][:COMMANDS[0].index(b"<CommandID>") + 5]   # inside the body
    out = DocumentSplitter().feed(cut + b"\n" + COMMANDS[1])
    assert isinstance(out[0], Refused) and "truncated" in out[0].reason
    assert documents(out) == [COMMANDS[1]]


def test_a_document_without_end_closes_the_stream_after_its_budget():
    splitter = DocumentSplitter(max_document=100)
    splitter.feed(b"<A>")
    with pytest.raises(WireError, match="without end"):
        for _ in range(1000):
            splitter.feed(b"x" * 100)


@pytest.mark.parametrize("root", [b"CRCLCommandInstance", b"CRCLProgram"])
def test_a_document_cut_at_a_tag_boundary_is_refused_where_the_next_root_starts(root):
    """CRCL root elements never nest: a root start inside a document means it was cut, even
    when the documents after it come without an XML declaration."""
    cut = COMMANDS[0][:COMMANDS[0].rindex(b"</")]            # cut just before a closing tag
    following = [c.split(b"?>", 1)[1].strip() if c.startswith(b"<?xml") else c
                 for c in COMMANDS[1:3]]
    if root == b"CRCLProgram":
        following[0] = (b'<CRCLProgram><InitCanon><CommandID>1</CommandID></InitCanon>'
                        b'<EndCanon><CommandID>2</CommandID></EndCanon></CRCLProgram>')
    out = DocumentSplitter().feed(cut + b"".join(following))
    assert isinstance(out[0], Refused) and "truncated" in out[0].reason
    assert documents(out) == following


def test_a_root_name_inside_a_longer_tag_name_is_no_new_document():
    doc = b"<CRCLCommandInstance><CRCLCommandInstanceX/><CRCLProgramme>a</CRCLProgramme></CRCLCommandInstance>"
    assert documents(DocumentSplitter().feed(doc)) == [doc]
