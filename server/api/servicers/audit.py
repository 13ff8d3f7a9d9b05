"""AuditService: the device's audit log (security/audit.py) read back, for administrators.

The files are opened when the call begins (rotated ones and the newest), so a rotation while
the records stream leaves this transfer whole; each is read up to the size it had then. Reads
run on the guard's read pool a chunk at a time: the event loop never waits on the disk.
"""
from __future__ import annotations

import os
import re
from datetime import timezone
from pathlib import Path
from typing import BinaryIO, Iterator

from landscape.server.api import convert, services
from landscape.server.api.guard import guarded
from landscape.server.errors import NotOffered
from landscape.v1 import audit_service_pb2 as pb

CHUNK = 64 * 1024
_TIME = re.compile(rb'"time": "([^"]*)"')   # audit.Record.line writes it first


@guarded(services.AUDIT)
class AuditServicer(services.AUDIT.servicer_base):
    def __init__(self, device, log: str | None, backups: int, dispatch, limits):
        """log: the audit log's file (None: the server keeps none); backups: the rotated
        files kept beside it (audit.log.1 ...)."""
        self.device, self.dispatch, self.limits = device, dispatch, limits
        self.log, self.backups = (Path(log) if log else None), backups

    async def ReadAuditLog(self, request, context):
        if self.log is None:
            raise NotOffered("this device server keeps no audit log (--audit-log)")
        since = _text(request.since) if request.HasField("since") else None
        until = _text(request.until) if request.HasField("until") else None
        reads = self.dispatch.reads
        files = await self.dispatch.run(reads, open_files, self.log, self.backups)
        try:
            chunks = records(files, since, until)
            while (chunk := await self.dispatch.run(reads, next, chunks, None)) is not None:
                yield pb.ReadAuditLogResponse(ret_val=convert.ok(), file=chunk[0],
                                              records=chunk[1])
        finally:
            for _, stream, _ in files:
                stream.close()


def open_files(log: Path, backups: int) -> list[tuple[str, BinaryIO, int]]:
    """(name, open file, size now) of each file of the log, oldest first. Opened newest first,
    each file once (by inode): a rotation meanwhile cannot make a file come twice."""
    files, seen = [], set()
    for name in [log] + [log.with_name(f"{log.name}.{n}") for n in range(1, backups + 1)]:
        try:
            stream = name.open("rb")
        except FileNotFoundError:
            continue
        status = os.fstat(stream.fileno())
        if (status.st_dev, status.st_ino) in seen:
            stream.close()
            continue
        seen.add((status.st_dev, status.st_ino))
        files.append((name.name, stream, status.st_size))
    return files[::-1]


def records(files, since: str | None, until: str | None) -> Iterator[tuple[str, bytes]]:
    """(file name, whole lines) chunks of `files`, keeping the records in [since, until)."""
    for name, stream, size in files:
        left, rest = size, b""
        while left > 0:
            data = stream.read(min(CHUNK, left))
            if not data:
                break
            left -= len(data)
            data = rest + data
            cut = data.rfind(b"\n") + 1 if left > 0 else len(data)
            lines, rest = data[:cut], data[cut:]
            if since is not None or until is not None:
                lines = b"".join(line for line in lines.splitlines(keepends=True)
                                 if _within(line, since, until))
            if lines:
                yield name, lines


def _within(line: bytes, since: str | None, until: str | None) -> bool:
    found = _TIME.search(line)
    if found is None:
        return False
    moment = found.group(1).decode(errors="replace")   # ISO 8601 UTC: ordered as text
    return (since is None or moment >= since) and (until is None or moment < until)


def _text(stamp) -> str:
    """A Timestamp as the audit writes times (audit._utc), to the millisecond."""
    moment = stamp.ToDatetime(tzinfo=timezone.utc)
    return moment.strftime("%Y-%m-%dT%H:%M:%S.") + f"{moment.microsecond // 1000:03d}Z"
