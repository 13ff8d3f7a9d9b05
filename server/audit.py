"""The audit log: every mutating call (who, what, when, result), refused ones included.

One JSON object a line, so it can be read by people and by tools:

    {"time": "2025-01-31T10:02:03.123Z", "who": "alice", "role": "operator",
     "peer": "ipv4:10.0.0.7:51234", "rpc": "DeviceService/MoveAbsolute",
     "request": "point_name: \\"p1\\" values: 0.5 ...", "result": "OK", "ms": 12.5}

`result` is "OK", or the status code's name and the server's explanation; a stream is
written when it opens ("OPEN") and again when it ends. Secrets in requests (a session's
secret, a token) are blanked before anything is written. The file is rotated by size
(logging.handlers.RotatingFileHandler: `audit.log`, `audit.log.1`, ... up to `backups`). A
queue and one writer thread take the disk writes off the server's event loop, so a slow disk
never holds up a command, least of all a stop.
"""
from __future__ import annotations

import json
import logging
import logging.handlers
import queue
import time
from datetime import datetime, timezone
from pathlib import Path

from google.protobuf import text_format

REQUEST_TEXT_LIMIT = 400      # characters of a request kept in a record
_SECRET_WORDS = ("secret", "token", "password")


class AuditLog:
    def __init__(self, path: str | Path, max_bytes: int = 10 * 1024 * 1024, backups: int = 5):
        """Opens (creating its folder) `path`; OSError if it cannot be written."""
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handler = logging.handlers.RotatingFileHandler(self.path, maxBytes=max_bytes,
                                                       backupCount=backups, encoding="utf-8")
        handler.setFormatter(logging.Formatter("%(message)s"))
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._listener = logging.handlers.QueueListener(self._queue, handler)
        self._handler = handler
        # A logger of our own, not in logging's tree: nothing else writes here, and nothing
        # written here ends up on the console.
        self._log = logging.Logger(f"audit:{self.path}", logging.INFO)
        self._log.addHandler(logging.handlers.QueueHandler(self._queue))
        self._listener.start()

    def record(self, *, who: str, role: str, peer: str, rpc: str, request: str, result: str,
               started: float, wall: float) -> None:
        """One line; `started` is time.monotonic() at the call's start, `wall` time.time()."""
        entry = {"time": _utc(wall), "who": who, "role": role, "peer": peer, "rpc": rpc,
                 "request": request, "result": result,
                 "ms": round((time.monotonic() - started) * 1000.0, 1)}
        self._log.info(json.dumps(entry, ensure_ascii=False))

    def close(self) -> None:
        """Writes what is queued and closes the file."""
        self._listener.stop()
        self._handler.close()


def describe(request) -> str:
    """A request as one line of protobuf text, secrets blanked, at most REQUEST_TEXT_LIMIT
    characters; a stream of requests is "(stream)"."""
    if not hasattr(request, "ListFields"):
        return "(stream)"
    if any(any(word in field.name for word in _SECRET_WORDS) for field, _ in request.ListFields()):
        request = _without_secrets(request)
    text = text_format.MessageToString(request, as_one_line=True)
    return text if len(text) <= REQUEST_TEXT_LIMIT else text[:REQUEST_TEXT_LIMIT - 1] + "…"


def _without_secrets(request):
    copy = type(request)()
    copy.CopyFrom(request)
    for field, _ in copy.ListFields():
        if any(word in field.name for word in _SECRET_WORDS):
            copy.ClearField(field.name)
    return copy


def _utc(wall: float) -> str:
    moment = datetime.fromtimestamp(wall, timezone.utc)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 1000:03d}Z"
