"""Text from callers made safe for a log line (issue 25.5): a client's name, a header, a peer
may hold newlines or terminal escapes that would forge lines or rewrite the screen of whoever
reads the log. `printable` spells every such character out (`\\n`, `\\x1b`, `\\u2028`);
`EscapingFilter`, on a logging handler, does it to every argument of every record, so the
format strings stay ours and the data in them can never break a line.
"""
from __future__ import annotations

import logging


def printable(text: str, limit: int | None = None) -> str:
    """`text` with every character that is not printable (control characters, line and
    paragraph separators, other invisible formatting) written as its escape, cut to `limit`
    characters (then ending in "…")."""
    if not text.isprintable():
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    if limit is not None and len(text) > limit:
        text = text[:limit - 1] + "…"
    return text


class EscapingFilter(logging.Filter):
    """Escapes the string arguments of each record (and the text of an exception given as an
    argument, if it needs it) before a handler formats it. The message itself is the
    program's own format string: it may hold newlines on purpose."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.args and not getattr(record, "escaped", False):
            args = record.args
            if isinstance(args, dict):
                record.args = {key: _escaped(value) for key, value in args.items()}
            else:
                record.args = tuple(_escaped(value) for value in args)
            record.escaped = True
        return True


def _escaped(value):
    if isinstance(value, str):
        return printable(value)
    if isinstance(value, BaseException) and not str(value).isprintable():
        return printable(str(value))
    return value


def escape_handlers(logger: logging.Logger = logging.getLogger()) -> None:
    """Put an EscapingFilter on every handler of `logger` (the root: all of them)."""
    for handler in logger.handlers:
        if not any(isinstance(f, EscapingFilter) for f in handler.filters):
            handler.addFilter(EscapingFilter())
