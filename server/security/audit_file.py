"""The audit log's file: whole lines appended, rotated by size, a failure said, never half a
line left behind.

`append(data)` writes whole lines with one or more os.write calls on an O_APPEND descriptor;
if the disk fills (or anything else fails) part way, the file is cut back to where it was, so
a reader never meets a record cut in half, and OSError says why. Rotation follows
logging.handlers.RotatingFileHandler's names (`audit.log`, `audit.log.1`, ... up to `backups`),
done before a write that would take the file past `max_bytes`. Used by one thread at a time
(the audit's writer). Not RotatingFileHandler itself: it writes through a buffered stream that
keeps a half-written line to write again later, and tells of a failure only on stderr.

A line is in the file once `append` returns: in the operating system's hands, not yet synced
to the disk (a power cut may lose the last ones; a full disk, a file that cannot be written,
never goes unnoticed: ext4, XFS and tmpfs report ENOSPC at the write).
"""
from __future__ import annotations

import os
from pathlib import Path


class AuditFile:
    def __init__(self, path: str | Path, max_bytes: int, backups: int):
        """Opens (creating its folder) `path`; OSError if it cannot be."""
        self.path = Path(path)
        self.max_bytes, self.backups = max_bytes, backups
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = -1
        self._size = 0
        self._open()

    def _open(self) -> None:
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC,
                           0o640)
        self._size = os.fstat(self._fd).st_size

    def append(self, data: bytes) -> None:
        """Write `data` (whole lines) at the end; all of it, or none and OSError."""
        if self._fd < 0:
            self._open()   # a rotation that failed half way left it closed
        if self._size and self._size + len(data) > self.max_bytes:
            self._rotate()
        start, view = self._size, memoryview(data)
        try:
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
        except OSError:
            if len(view) != len(data):   # part of it went in: take it out again
                try:
                    os.ftruncate(self._fd, start)
                except OSError:
                    self._size = os.fstat(self._fd).st_size
                    raise
            raise
        self._size = start + len(data)

    def _rotate(self) -> None:
        os.close(self._fd)
        self._fd = -1
        if self.backups > 0:
            for n in range(self.backups - 1, 0, -1):
                older = self.path.with_name(f"{self.path.name}.{n}")
                if older.exists():
                    older.replace(self.path.with_name(f"{self.path.name}.{n + 1}"))
            self.path.replace(self.path.with_name(f"{self.path.name}.1"))
        else:
            self.path.unlink(missing_ok=True)
        self._open()

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
