"""An SQLite file that cannot stop the server (issue 25.6): opened and checked whole, moved
aside when its content cannot be read, its write failures told apart.

A file is unreadable when SQLite says it is not a database or is corrupt (a truncated file, a
garbage header, a damaged page, an older backup restored under a newer write-ahead log), when
its structure fails `PRAGMA quick_check`, or when a table has other columns than ours. Such a
file is renamed, with its write-ahead log and shared-memory index, to
`<name>.unreadable-<UTC time>` (SQLite's own names follow: `-wal`, `-shm`), so nothing is
lost and `sqlite3 <kept> .recover` can save what is readable. Anything else that fails at
opening (a folder that cannot be written, a full disk, a file locked by another process) says
nothing about the content: the file is left alone.
"""
from __future__ import annotations

import sqlite3
import time
from pathlib import Path

from landscape.server.errors import CommandError, StorageFailed, StorageFull

_UNREADABLE_CODES = {sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_NOTADB}
_SIBLINGS = ("-wal", "-shm", "-journal")


class Unreadable(sqlite3.DatabaseError):
    """The file opened, but what is in it is not what we store."""


def connect(file: str | Path, tables: dict[str, str]) -> sqlite3.Connection:
    """`file` (or ":memory:") checked, opened with a write-ahead log, and `tables` (name:
    column definitions) created where missing; sqlite3.Error (Unreadable among them) if it
    cannot be used. Usable from any thread (the caller serialises access)."""
    if str(file) != ":memory:" and Path(file).exists():
        check(file, tables)
    db = sqlite3.connect(str(file), check_same_thread=False)
    try:
        # Write-ahead log, synced at checkpoints: a save is one atomic commit without an fsync
        # (0.03 ms here, was 0.8); a killed server loses nothing, a power cut at most the last
        # saves, never the file's consistency.
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=NORMAL")
        with db:
            for name, columns in tables.items():
                db.execute(f"CREATE TABLE IF NOT EXISTS {name} ({columns})")
    except BaseException:
        db.close()
        raise
    return db


def check(file: str | Path, tables: dict[str, str]) -> None:
    """Unreadable (or another sqlite3.Error) unless `file` is a sound database whose `tables`,
    those it has, have our columns. Read-only: a write-ahead log is read, never checkpointed
    into the file (a connection that can write does so when it closes, which would make a
    stale log's damage permanent and throw the log away)."""
    db = sqlite3.connect(f"{Path(file).absolute().as_uri()}?mode=ro", uri=True)
    try:
        present = {row[0] for row in db.execute("SELECT name FROM sqlite_master")}
        for name, columns in tables.items():
            if name in present:
                _check_columns(db, name, columns)
        problems = [row[0] for row in db.execute("PRAGMA quick_check(3)")]
        if problems != ["ok"]:
            raise Unreadable("; ".join(problems))
    finally:
        db.close()


def _check_columns(db: sqlite3.Connection, table: str, columns: str) -> None:
    want = [definition.split()[:2] for definition in columns.split(",")
            if not definition.strip().upper().startswith(("PRIMARY", "CHECK", "UNIQUE"))]
    have = [[name, kind] for _, name, kind, *_ in db.execute(f"PRAGMA table_info({table})")]
    if have != want:
        raise Unreadable(f"table {table} has columns {have}, not {want}")


def unreadable(error: sqlite3.Error) -> bool:
    """Whether `error` (from connect) says the content cannot be read, not its surroundings."""
    code = getattr(error, "sqlite_errorcode", None)
    return isinstance(error, Unreadable) or (code is not None and code & 0xFF in _UNREADABLE_CODES)


def move_aside(file: str | Path) -> Path:
    """Rename `file` and its SQLite companions to `<file>.unreadable-<UTC time>`; the new
    name of `file`. OSError if it cannot be renamed."""
    file = Path(file)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    kept, n = file.with_name(f"{file.name}.unreadable-{stamp}"), 1
    while kept.exists():
        n += 1
        kept = file.with_name(f"{file.name}.unreadable-{stamp}-{n}")
    file.rename(kept)
    for suffix in _SIBLINGS:
        sibling = file.with_name(file.name + suffix)
        if not sibling.exists():
            continue
        if sibling.stat().st_size == 0:   # made by the check itself: nothing in it to keep
            sibling.unlink()
        else:
            sibling.rename(kept.with_name(kept.name + suffix))
    return kept


def write_failure(error: sqlite3.Error, file: str | Path, what: str) -> CommandError:
    """The refusal for a write to `file` that failed with `error`: StorageFull
    (RESOURCE_EXHAUSTED) for a full disk, else StorageFailed (UNAVAILABLE). `what` names what
    was not stored."""
    code = getattr(error, "sqlite_errorcode", 0) & 0xFF
    if code == sqlite3.SQLITE_FULL:
        return StorageFull(f"the disk holding {file} is full: {what} was not stored and nothing "
                           f"changed; free some space and send it again")
    return StorageFailed(f"{file} cannot be written ({error}): {what} was not stored and "
                         f"nothing changed")
