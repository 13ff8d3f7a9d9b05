"""Named paths (seed 3.5): points resolved to joints when loaded, kept in SQLite (with the
settings of seed 3.2, stored_settings.py).

A path is checked whole when it is loaded (every point reachable in the arm's configuration,
every straight segment followable) and stored resolved, so pathMove runs what was checked.
Paths live in one SQLite file; every change is one transaction, so a crash leaves either the
old or the new path, never half of one, and paths survive a restart of the device server.

Stored data never stops the server (issue 25.6), and each fault is reported (an alarm, through
`report`): a file whose content cannot be read is moved aside and a fresh one started
(sqlite_file.py); a file that cannot be opened at all leaves the paths and settings in memory
until a restart; a path or the settings that cannot be read are skipped (an unreadable path
can still be cleared, or loaded again); a write that fails (a full disk: StorageFull,
RESOURCE_EXHAUSTED; anything else: StorageFailed, UNAVAILABLE) changes nothing, is reported
once, and its recovery too.
"""
from __future__ import annotations

import contextlib
import json
import logging
import sqlite3
import threading
from itertools import chain
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path as FilePath
from typing import Callable

import numpy as np

from landscape.server.planning import sqlite_file
from landscape.server.errors import NotFound
from landscape.server.events.records import Severity

log = logging.getLogger(__name__)
TABLES = {"paths": "name TEXT PRIMARY KEY, body TEXT NOT NULL",
          "settings": "id INTEGER PRIMARY KEY CHECK (id = 1), body TEXT NOT NULL"}
_LOG_LEVELS = {Severity.INFO: logging.INFO, Severity.WARNING: logging.WARNING,
               Severity.ERROR: logging.ERROR, Severity.CRITICAL: logging.CRITICAL}


@dataclass(frozen=True)
class PathPoint:
    """One point: joint target (rad, (6,)) and the tag_struct's other fields (seed 3.5.1)."""

    joints: tuple[float, ...]
    tag_name: str = ""
    tag_index: int = 0
    time_delay: float = 0.0          # s of dwell at the point
    transition_speed: float = 0.0    # percent; > 0: pass through without stopping
    speed: float = 0.0               # percent towards the point; 0: the set speed
    accel: float = 0.0               # percent; 0: the set acceleration
    aux_commands: tuple[str, ...] = ()

    @property
    def stops(self) -> bool:
        return self.transition_speed <= 0.0 or self.time_delay > 0.0


@dataclass(frozen=True)
class StoredPath:
    name: str
    straight: bool                   # STRAIGHT_MOTION between points (else JOINT_MOTION)
    tcp: tuple[float, ...]           # tool offset (4x4, row-major) the points were resolved with
    points: tuple[PathPoint, ...] = field(default=())

    @property
    def tcp_matrix(self) -> np.ndarray:
        return np.array(self.tcp).reshape(4, 4)

    def appended(self, points) -> "StoredPath":
        return StoredPath(self.name, self.straight, self.tcp, self.points + tuple(points))

    def __reduce__(self):
        # To and from the planning process, the points go as columns (arrays for the numbers,
        # filled from generators) and are rebuilt in Python: pickling or unpickling 2,000
        # PathPoints is one C call that held the server's interpreter for 2.3 to 2.6 ms, and a
        # stop arriving meanwhile missed its cycle. These steps let other threads in.
        points, n = self.points, len(self.points)
        return (_stored_path, (
            self.name, self.straight, self.tcp,
            np.fromiter(chain.from_iterable(p.joints for p in points), float, 6 * n),
            np.fromiter(chain.from_iterable((p.time_delay, p.transition_speed, p.speed, p.accel)
                                            for p in points), float, 4 * n),
            np.fromiter((p.tag_index for p in points), np.int64, n),
            [p.tag_name for p in points], [p.aux_commands for p in points]))


def _stored_path(name, straight, tcp, joints, numbers, tag_indices, tag_names, aux):
    return StoredPath(name, straight, tcp, tuple(
        PathPoint(tuple(q), tag_name, tag_index, *rest, aux_commands)
        for q, rest, tag_index, tag_name, aux_commands
        in zip(joints.reshape(-1, 6).tolist(), numbers.reshape(-1, 4).tolist(),
               tag_indices.tolist(), tag_names, aux)))


class PathStore:
    """Paths by name in an SQLite file (None: in memory, gone with the process). `report`
    (severity, message) is told of every fault and recovery; each is logged as well."""

    def __init__(self, file: str | FilePath | None = None,
                 report: Callable[[Severity, str], None] = lambda severity, message: None):
        self._file = file
        self._report_to = report
        self._lock = threading.Lock()
        self._failing = False        # the last write failed: said once, until one works
        self._db = self._open(file)

    @property
    def failing(self) -> bool:
        """The last write failed (a full disk, say): none has worked since."""
        return self._failing

    def _report(self, severity: Severity, message: str) -> None:
        log.log(_LOG_LEVELS[severity], "%s", message)
        self._report_to(severity, message)

    def _open(self, file) -> sqlite3.Connection:
        if file is None:
            return sqlite_file.connect(":memory:", TABLES)
        try:
            FilePath(file).parent.mkdir(parents=True, exist_ok=True)
            return sqlite_file.connect(file, TABLES)
        except (OSError, sqlite3.Error) as error:
            if not (isinstance(error, sqlite3.Error) and sqlite_file.unreadable(error)):
                return self._in_memory(f"{file} cannot be opened ({error})")
            problem = error
        try:
            kept = sqlite_file.move_aside(file)
        except OSError as error:
            return self._in_memory(f"{file} cannot be read ({problem}) nor moved aside "
                                   f"({error})")
        self._report(Severity.ERROR, f"{file} cannot be read ({problem}): it is kept as {kept} "
                                     f"(sqlite3's .recover may save what is readable); "
                                     f"starting anew: no stored paths, the default settings")
        try:
            return sqlite_file.connect(file, TABLES)
        except (OSError, sqlite3.Error) as error:
            return self._in_memory(f"a new {file} cannot be started ({error})")

    def _in_memory(self, why: str) -> sqlite3.Connection:
        self._report(Severity.ERROR, f"{why}: paths and settings are kept in memory only, "
                                     f"until the server restarts")
        return sqlite_file.connect(":memory:", TABLES)

    @contextlib.contextmanager
    def _writing(self, what: str):
        """One transaction; a failure changes nothing and becomes StorageFull/StorageFailed."""
        try:
            with self._lock, self._db:
                yield self._db
        except sqlite3.Error as error:
            refusal = sqlite_file.write_failure(error, self._file or "memory", what)
            if not self._failing:
                self._failing = True
                self._report(Severity.ERROR, refusal.message)
            raise refusal from None
        if self._failing:
            self._failing = False
            self._report(Severity.INFO, f"{self._file} is written again")

    def load_settings(self) -> dict | None:
        """The stored settings record (stored_settings.py), or None if none was stored or it
        cannot be read (said)."""
        with self._lock:
            row = self._db.execute("SELECT body FROM settings WHERE id = 1").fetchone()
        if row is None:
            return None
        try:
            record = json.loads(row[0])
            if not isinstance(record, dict):
                raise ValueError(f"a {type(record).__name__}, not a record")
        except ValueError as error:
            self._report(Severity.WARNING, f"the stored settings cannot be read ({error}): "
                                           f"the defaults are in force")
            return None
        return record

    def save_settings(self, record: dict) -> None:
        """Replace the stored settings, in one transaction."""
        body = json.dumps(record)
        with self._writing("the settings") as db:
            db.execute("INSERT OR REPLACE INTO settings (id, body) VALUES (1, ?)", (body,))

    def load_all(self) -> tuple[dict[str, "StoredPath"], set[str]]:
        """Every stored path by name, and the names of those that cannot be read (said)."""
        with self._lock:
            try:
                rows = self._db.execute("SELECT name, body FROM paths").fetchall()
            except sqlite3.Error as error:
                rows = []
                self._report(Severity.ERROR, f"the stored paths in {self._file} cannot be "
                                             f"read ({error}): serving without them")
        paths, unreadable = {}, set()
        for name, body in rows:
            try:
                paths[name] = _decode(name, body)
            except (ValueError, TypeError, KeyError, AttributeError) as error:
                unreadable.add(name)
                self._report(Severity.WARNING, f"stored path {name!r} cannot be read "
                                               f"({type(error).__name__}: {error}): skipped; "
                                               f"load it again, or clear it")
        return paths, unreadable

    def put(self, path: StoredPath) -> None:
        # Point by point: json's C encoder keeps the interpreter for a whole call (8 ms for
        # 2,000 points, during which a stop could not get through); the same text results.
        points = ", ".join(json.dumps(asdict(p)) for p in path.points)
        body = (f'{{"straight": {json.dumps(path.straight)}, "tcp": {json.dumps(list(path.tcp))}'
                f', "points": [{points}]}}')
        with self._writing(f"path {path.name!r}") as db:
            db.execute("INSERT OR REPLACE INTO paths (name, body) VALUES (?, ?)",
                       (path.name, body))

    def delete(self, name: str) -> None:
        with self._writing(f"the clearing of path {name!r}") as db:
            db.execute("DELETE FROM paths WHERE name = ?", (name,))

    def close(self) -> None:
        with self._lock:
            self._db.close()


class PathLibrary(Mapping):
    """The named paths by name, in memory and written through to their store."""

    def __init__(self, store: PathStore):
        self._store = store
        self._paths, self._unreadable = store.load_all()   # the latter: only to clear them

    def __getitem__(self, name: str) -> StoredPath:
        return self._paths[name]

    def __iter__(self):
        return iter(self._paths)

    def __len__(self) -> int:
        return len(self._paths)

    def snapshot(self) -> tuple[dict[str, StoredPath], list[str]]:
        """The paths by name and the names of the unreadable ones, as they are now (safe
        beside a PathLoad on another thread: each copy is one step)."""
        return dict(self._paths), sorted(set(self._unreadable))

    def put(self, path: StoredPath) -> None:
        self._store.put(path)   # first: if the write fails, memory keeps the old path too
        self._paths[path.name] = path
        self._unreadable.discard(path.name)

    def close(self) -> None:
        self._store.close()

    def delete(self, name: str) -> None:
        if name not in self._paths and name not in self._unreadable:
            raise NotFound(f"no path named {name!r}")
        self._store.delete(name)
        self._paths.pop(name, None)
        self._unreadable.discard(name)


def _decode(name: str, body: str) -> StoredPath:
    data = json.loads(body)
    points = tuple(PathPoint(**{**p, "joints": tuple(p["joints"]),
                                "aux_commands": tuple(p["aux_commands"])})
                   for p in data["points"])
    return StoredPath(name, data["straight"], tuple(data["tcp"]), points)
