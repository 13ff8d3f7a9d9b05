"""The CRCL wire: a TCP byte stream in, complete XML documents out.

NIST's reference implementation sends UTF-8 XML documents back to back with no length prefix
and no delimiter (../shared/crcl/README.md): a reader finds a document's end where its root
element closes. TCP may split a document across reads or bring several in one; an XML
declaration, comments, processing instructions and whitespace may come between documents.

`DocumentSplitter` scans markup incrementally (tags, comments, processing instructions, CDATA,
quoted attribute values that may hold '>') and counts element depth; it never parses content,
so it costs one `bytes.find` per markup token. Three things end the stream (WireError), since
after them nothing the peer sends can be trusted to be CRCL:
- bytes outside any document, before the first '<' of one: an HTTP request line and headers
  (a browser's form or fetch POST, whose body would otherwise run as commands), or any other
  protocol (OutsideDocument);
- a DOCTYPE or other declaration: no DTD, hence no entity declaration, ever reaches the parser
  (DeclarationRefused);
- a single markup token, or a document being skipped, past the size bounds.
A document that grows past the bound is skipped to its end while its bytes are dropped, so the
connection stays usable. An XML declaration, or the start of a CRCL root element
(`<CRCLCommandInstance`, `<CRCLProgram`: CRCL's roots never nest), inside a document means it
was truncated: it is refused, and the next document starts there. A document whose bytes stop
coming is the server's to drop (DOCUMENT_IDLE).
"""
from __future__ import annotations

from dataclasses import dataclass

DEFAULT_MAX_DOCUMENT = 1 << 20     # bytes; a CRCL command is a few hundred, a program a few 10k
DOCUMENT_IDLE = 10.0               # s a started document may wait for its next bytes: a client
                                   # writes a document at once, so a stall means it is gone
SKIP_BUDGET = 256                  # an oversized document is skipped for this many times the
                                   # bound at most; past that the connection closes

_WHITESPACE = b" \t\r\n"
# Root elements of CRCL documents (CRCLStatus too, for readers of status streams).
ROOTS = (b"CRCLCommandInstance", b"CRCLProgram", b"CRCLStatus")


@dataclass(frozen=True)
class Document:
    """One complete document: its bytes (prolog included) and where it started in the stream."""

    data: bytes
    offset: int


@dataclass(frozen=True)
class Refused:
    """A document the splitter dropped: why, and where it started in the stream (byte offset)."""

    reason: str
    offset: int


class WireError(Exception):
    """The stream cannot be resynchronised; the connection must close."""


class OutsideDocument(WireError):
    """Bytes that are no part of a CRCL document (an HTTP request, another protocol)."""


class DeclarationRefused(WireError):
    """A DOCTYPE or another declaration: DTDs and entities are not accepted."""


class DocumentSplitter:
    """Feed bytes as they arrive; get back complete documents and refusals, in stream order."""

    def __init__(self, max_document: int = DEFAULT_MAX_DOCUMENT):
        self.max_document = max_document
        self._buf = bytearray()
        self._base = 0          # stream offset of _buf[0]
        self._pos = 0           # scan position in _buf
        self._doc_start = 0     # index in _buf where the current document (prolog) began
        self._depth = 0         # open elements of the current document
        self._in_root = False   # the root element has started
        self._skipping: str | None = None   # why the current document is being dropped
        self._skip_offset = 0
        self._skipped = 0       # bytes of the current document dropped so far

    @property
    def pending(self) -> int:
        """Bytes held for a document not complete yet."""
        return len(self._buf) - self._doc_start

    def feed(self, data: bytes) -> list[Document | Refused]:
        self._buf += data
        out: list[Document | Refused] = []
        while self._step(out):
            pass
        self._compact()
        return out

    # ---- scanning ------------------------------------------------------------------------

    def _step(self, out: list) -> bool:
        """Consume one token if it is complete; False when more bytes are needed."""
        buf = self._buf
        if not self._in_root:
            if not self._skip_between_documents():
                return False
            lt = self._pos
        else:
            lt = buf.find(b"<", self._pos)
            if lt < 0:                                   # character data: wait for markup
                self._pos = len(buf)
                self._check_size()
                return False
            self._pos = lt
        return self._token(out, lt)

    def _skip_between_documents(self) -> bool:
        """Before a root element: whitespace, then '<'. Anything else ends the stream."""
        buf, pos = self._buf, self._pos
        while pos < len(buf) and buf[pos] in _WHITESPACE:
            pos += 1
        if not buf[self._doc_start:pos].strip():         # nothing but blanks so far
            self._doc_start = pos                        # the XML declaration must come first
        self._pos = pos
        if pos >= len(buf):
            return False
        if buf[pos] == 0x3C:                             # '<'
            return True
        raise OutsideDocument(f"bytes outside any CRCL document at byte {self._base + pos}: "
                              f"{bytes(buf[pos:pos + 40])!r}")

    def _token(self, out: list, lt: int) -> bool:
        buf = self._buf
        if len(buf) - lt < 2:
            return False
        second = buf[lt + 1]
        if second == 0x3F:                               # <? ... ?>
            if self._in_root and _is_declaration(buf, lt):
                self._truncated(out, lt)                 # a new document began: resync here
            end = self._find_end(b"?>", lt + 2)
        elif buf.startswith(b"<!--", lt):
            end = self._find_end(b"-->", lt + 4)
        elif buf.startswith(b"<![CDATA[", lt):
            end = self._find_end(b"]]>", lt + 9)
        elif second == 0x21:                             # <!DOCTYPE, <!ENTITY, ...
            if b"<![CDATA[".startswith(bytes(buf[lt:lt + 9])) or \
                    b"<!--".startswith(bytes(buf[lt:lt + 4])):
                return False                             # may still become CDATA or a comment
            raise DeclarationRefused("a DOCTYPE or other declaration: DTDs and entities are "
                                     "not accepted")
        else:
            end = self._tag_end(lt)
            if end <= -2:                                # a '<' inside a tag: it was cut short
                self._truncated(out, -end - 2)
                self._pos = -end - 2
                return True
        if end < 0:
            self._check_token(lt)
            return False
        self._pos = end
        if second == 0x2F:                               # </name>
            self._depth -= 1
            if self._depth <= 0:
                self._finish(out, end)
        elif second not in (0x3F, 0x21):                 # <name ...> or <name .../>
            if self._in_root and _is_root(buf, lt):
                self._truncated(out, lt)                 # a new document began: resync here
                self._pos = lt
                return True
            self._in_root = True
            if buf[end - 2] != 0x2F:
                self._depth += 1
            elif self._depth == 0:                       # a self-closing root: <A/>
                self._finish(out, end)
        self._check_size()
        return True

    def _find_end(self, marker: bytes, start: int) -> int:
        i = self._buf.find(marker, start)
        return -1 if i < 0 else i + len(marker)

    def _tag_end(self, lt: int) -> int:
        """Index just past the '>' closing the tag at lt, skipping quoted attribute values;
        -1 if it has not arrived yet; -2 - k if a '<' at k comes first (the tag was cut)."""
        buf, i = self._buf, lt + 1
        while True:
            gt = buf.find(b">", i)
            stray = buf.find(b"<", i, len(buf) if gt < 0 else gt)
            quote = _first_quote(buf, i, len(buf) if gt < 0 else gt)
            if stray >= 0 and (quote < 0 or stray < quote):
                return -2 - stray
            if gt < 0:
                return -1
            if quote < 0:
                return gt + 1
            close = buf.find(buf[quote:quote + 1], quote + 1)
            if close < 0:
                return -1
            i = close + 1

    # ---- documents and bounds --------------------------------------------------------------

    def _finish(self, out: list, end: int) -> None:
        if self._skipping:
            out.append(Refused(self._skipping, self._skip_offset))
        else:
            out.append(Document(bytes(self._buf[self._doc_start:end]),
                                self._base + self._doc_start))
        self._doc_start = end
        self._in_root = False
        self._depth = 0
        self._skipping = None
        self._skipped = 0

    def _truncated(self, out: list, lt: int) -> None:
        """An XML declaration or a CRCL root inside a document: the document was cut short
        (a declaration may only open one; roots never nest). Refuse it and start the next
        document there."""
        offset = self._skip_offset if self._skipping else self._base + self._doc_start
        out.append(Refused("truncated document: another began before its end", offset))
        self._doc_start, self._depth, self._in_root, self._skipping = lt, 0, False, None
        self._skipped = 0

    def _check_size(self) -> None:
        """Past the bound, drop the document's bytes as they are scanned, up to its end."""
        if not self._skipping and len(self._buf) - self._doc_start > self.max_document:
            self._skipping = (f"document longer than {self.max_document} bytes (the gateway's "
                              f"maximum document size): dropped")
            self._skip_offset = self._base + self._doc_start
        if self._skipping and self._pos > self._doc_start:
            self._skipped += self._pos
            if self._skipped > SKIP_BUDGET * self.max_document:
                raise WireError(f"a document without end: more than {self._skipped} bytes "
                                f"dropped")
            del self._buf[:self._pos]
            self._base += self._pos
            self._pos = self._doc_start = 0

    def _check_token(self, lt: int) -> None:
        if len(self._buf) - lt > self.max_document:
            raise WireError(f"one markup token longer than {self.max_document} bytes")
        self._check_size()

    def _compact(self) -> None:
        if self._doc_start > 0:
            del self._buf[:self._doc_start]
            self._base += self._doc_start
            self._pos -= self._doc_start
            self._doc_start = 0


def _is_declaration(buf: bytearray, lt: int) -> bool:
    return buf.startswith(b"<?xml", lt) and len(buf) > lt + 5 and buf[lt + 5] in b" \t\r\n?"


def _is_root(buf: bytearray, lt: int) -> bool:
    """Whether the (complete) start tag at lt opens a CRCL root element."""
    for name in ROOTS:
        end = lt + 1 + len(name)
        if buf.startswith(name, lt + 1) and buf[end] in b" \t\r\n/>":
            return True
    return False


def _first_quote(buf: bytearray, start: int, stop: int) -> int:
    """Index of the first ' or " in buf[start:stop], or -1."""
    dq, sq = buf.find(b'"', start, stop), buf.find(b"'", start, stop)
    if dq < 0:
        return sq
    if sq < 0:
        return dq
    return min(dq, sq)
