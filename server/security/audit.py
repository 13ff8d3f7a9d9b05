"""The audit log: every call that acts on the device (who, through which front end, for whom,
what, when, with what result), refused ones included.

One JSON object a line, so it can be read by people and by tools:

    {"time": "2025-01-31T10:02:03.123Z", "who": "alice", "role": "operator",
     "via": "supervisor", "for": "alice", "peer": "ipv4:10.0.0.7:51234",
     "rpc": "DeviceService/MoveAbsolute", "request": "point_name: \\"p1\\" values: 0.5 ...",
     "result": "OK", "ms": 12.5}

`who` and `role` are the caller's token (with tokens off: its address, or its certificate's
name under mutual TLS, with every right); `via` and `for` what its identity headers say
(`landscape-client`, `landscape-on-behalf-of`): recorded, never trusted. Every text is written
printable (log_text.py). `result` is "OK", or the status code's name and the server's
explanation. A call that changes something is written when it is admitted ("ADMITTED"; a
stream: "OPEN") and again when it ends. Secrets in requests are blanked.

Fails closed (issue 25.5). A call that would start or change motion or settings waits (on the
event loop, without blocking it) for its admission record to be in the file: `write_ahead`;
if the record cannot be written, the call is refused (AuditUnavailable, UNAVAILABLE) and
nothing ran unrecorded. Every other record (results, refusals, and the calls that make the arm
safe, which are never refused for the audit) is queued: `record`. One writer thread does the
writing, so a slow disk never holds up the event loop, nor a stop. Records that cannot be
written yet are kept (up to BACKLOG) and written, in order, once the file takes them again.
`report` (severity, message) is told when the file stops taking records and when it takes
them again (app.py: alarm 111).
"""
from __future__ import annotations

import asyncio
import json
import logging
import queue
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from google.protobuf import text_format

from landscape.server.security.audit_file import AuditFile
from landscape.server.errors import Unavailable
from landscape.server.events.records import Severity
from landscape.server.log_text import printable

log = logging.getLogger(__name__)

REQUEST_TEXT_LIMIT = 400      # characters of a request kept in a record
BACKLOG = 10_000              # records kept while the file cannot take them
_SECRET_WORDS = ("secret", "token", "password")


class AuditUnavailable(Unavailable):
    """The call's record cannot be written, so the call does not run."""

    reason = "AUDIT_UNAVAILABLE"


@dataclass
class Record:
    """One call as the audit writes it; `line(result)` for each time it is written. `request`:
    its message (described only when written), a request stream, or None. `started` is
    time.monotonic() at the call's start, `wall` time.time()."""

    who: str
    role: str
    via: str
    on_behalf_of: str
    peer: str
    rpc: str
    request: object
    started: float = field(default_factory=time.monotonic)
    wall: float = field(default_factory=time.time)

    def line(self, result: str) -> bytes:
        if not isinstance(self.request, str):     # described once, when first written
            self.request = "" if self.request is None else describe(self.request)
        entry = {"time": _utc(self.wall), "who": self.who, "role": self.role, "via": self.via,
                 "for": self.on_behalf_of, "peer": self.peer, "rpc": self.rpc,
                 "request": self.request, "result": result,
                 "ms": round((time.monotonic() - self.started) * 1000.0, 1)}
        text = {key: printable(value) if isinstance(value, str) else value
                for key, value in entry.items()}
        return (json.dumps(text, ensure_ascii=False) + "\n").encode()


class AuditLog:
    def __init__(self, path: str | Path, max_bytes: int = 10 * 1024 * 1024, backups: int = 5,
                 report: Callable[[Severity, str], None] = lambda severity, message: None):
        """Opens (creating its folder) `path`; OSError if it cannot be written."""
        self.path = Path(path)
        self._file = AuditFile(self.path, max_bytes, backups)
        self.report = report
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._backlog: deque[bytes] = deque()
        self._lost = 0                # records dropped from a full backlog
        self._problem: str | None = None   # why the file does not take records, while it does not
        self._writer = threading.Thread(target=self._run, name="audit-writer", daemon=True)
        self._writer.start()

    @property
    def healthy(self) -> bool:
        return self._problem is None

    @property
    def backlog(self) -> int:
        """Records waiting for the writer (a queue depth of /metrics)."""
        return self._queue.qsize()

    async def write_ahead(self, record: Record, result: str) -> None:
        """Write `record` and return once it is in the file; AuditUnavailable if it cannot be
        (nothing was written). The event loop goes on meanwhile."""
        loop = asyncio.get_running_loop()
        written = loop.create_future()
        self._queue.put((record.line(result), (loop, written)))
        await written

    def record(self, record: Record, result: str) -> None:
        """Queue `record`: written as soon as the file takes it, in order."""
        self._queue.put((record.line(result), None))

    def close(self, timeout: float = 5.0) -> None:
        """Write what is queued (what cannot be written is said in the log) and close."""
        self._queue.put(None)
        self._writer.join(timeout)
        self._file.close()

    # ---- the writer thread -------------------------------------------------------------------

    def _run(self) -> None:
        while True:
            batch = [self._queue.get()]
            while True:
                try:
                    batch.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            closing = None in batch
            self._write([item for item in batch if item is not None])
            if closing:
                if self._backlog or self._lost:
                    log.error("%d audit records could not be written to %s (%s)",
                              len(self._backlog) + self._lost, self.path, self._problem)
                return

    def _write(self, items: list) -> None:
        try:
            self._file.append(b"".join(self._backlog) + b"".join(line for line, _ in items))
        except OSError as error:
            self._failed(error)
            for line, waiter in items:
                if waiter is None:
                    self._keep(line)
                else:
                    _settle(waiter, AuditUnavailable(
                        f"the audit log cannot be written ({self._problem}): nothing that moves "
                        f"the arm or changes a setting runs unrecorded (stops still do)"))
            return
        kept, lost = len(self._backlog), self._lost
        self._backlog.clear()
        self._lost = 0
        for _, waiter in items:
            if waiter is not None:
                _settle(waiter, None)
        if self._problem is not None:
            self._problem = None
            self._tell(Severity.INFO, f"the audit log {self.path} is written again ({kept} "
                                      f"records kept meanwhile written"
                                      + (f", {lost} lost)" if lost else ")"))

    def _failed(self, error: OSError) -> None:
        if self._problem is None:
            self._problem = error.strerror or str(error)
            self._tell(Severity.ERROR,
                       f"the audit log {self.path} cannot be written ({self._problem}): calls "
                       f"that would move the arm or change a setting are refused until it can; "
                       f"stops are not, and are written once it can")

    def _keep(self, line: bytes) -> None:
        if len(self._backlog) >= BACKLOG:
            self._backlog.popleft()
            self._lost += 1
        self._backlog.append(line)

    def _tell(self, severity: Severity, message: str) -> None:
        log.log(logging.INFO if severity is Severity.INFO else logging.ERROR, "%s", message)
        try:
            self.report(severity, message)
        except Exception:   # the writer must go on whatever the alarm does
            log.exception("reporting the audit log's state failed")


def _settle(waiter: tuple, error: Exception | None) -> None:
    """Resolve an awaited write from the writer thread (on its loop, if it still runs)."""
    loop, future = waiter

    def settle():
        if not future.done():
            if error is None:
                future.set_result(None)
            else:
                future.set_exception(error)
    try:
        loop.call_soon_threadsafe(settle)
    except RuntimeError:   # the loop has closed: nobody waits any more
        pass


def describe(request) -> str:
    """A request as one line of protobuf text, secrets blanked, at most REQUEST_TEXT_LIMIT
    characters; a stream of requests is "(stream)"."""
    if not hasattr(request, "ListFields"):
        return "(stream)"
    if any(any(word in f.name for word in _SECRET_WORDS) for f, _ in request.ListFields()):
        request = _without_secrets(request)
    text = text_format.MessageToString(request, as_one_line=True)
    return text if len(text) <= REQUEST_TEXT_LIMIT else text[:REQUEST_TEXT_LIMIT - 1] + "…"


def _without_secrets(request):
    copy = type(request)()
    copy.CopyFrom(request)
    for f, _ in copy.ListFields():
        if any(word in f.name for word in _SECRET_WORDS):
            copy.ClearField(f.name)
    return copy


def _utc(wall: float) -> str:
    moment = datetime.fromtimestamp(wall, timezone.utc)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 1000:03d}Z"
