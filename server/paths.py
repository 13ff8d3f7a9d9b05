"""Named paths (seed 3.5): points resolved to joints when loaded, kept in SQLite (with the
settings of seed 3.2, stored_settings.py).

A path is checked whole when it is loaded (every point reachable in the arm's configuration,
every straight segment followable) and stored resolved, so pathMove runs what was checked.
Paths live in one SQLite file; every change is one transaction, so a crash leaves either the
old or the new path, never half of one, and paths survive a restart of the device server.
"""
from __future__ import annotations

import json
import sqlite3
import threading
from itertools import chain
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path as FilePath

import numpy as np

from landscape.server.errors import NotFound


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
    """Paths by name in an SQLite file (None: in memory, gone with the process)."""

    def __init__(self, file: str | FilePath | None = None):
        if file is not None:
            FilePath(file).parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(":memory:" if file is None else str(file),
                                   check_same_thread=False)
        self._lock = threading.Lock()
        # Write-ahead log, synced at checkpoints: a save is one atomic commit without an fsync
        # (0.03 ms here, was 0.8); a killed server loses nothing, a power cut at most the
        # last saves, never the file's consistency.
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        with self._lock, self._db:
            self._db.execute("CREATE TABLE IF NOT EXISTS paths (name TEXT PRIMARY KEY, body TEXT NOT NULL)")
            self._db.execute("CREATE TABLE IF NOT EXISTS settings (id INTEGER PRIMARY KEY CHECK (id = 1), "
                             "body TEXT NOT NULL)")

    def load_settings(self) -> dict | None:
        """The stored settings record (stored_settings.py), or None if none was stored."""
        with self._lock:
            row = self._db.execute("SELECT body FROM settings WHERE id = 1").fetchone()
        return json.loads(row[0]) if row else None

    def save_settings(self, record: dict) -> None:
        """Replace the stored settings, in one transaction."""
        body = json.dumps(record)
        with self._lock, self._db:
            self._db.execute("INSERT OR REPLACE INTO settings (id, body) VALUES (1, ?)", (body,))

    def load_all(self) -> dict[str, StoredPath]:
        with self._lock:
            rows = self._db.execute("SELECT name, body FROM paths").fetchall()
        return {name: _decode(name, body) for name, body in rows}

    def put(self, path: StoredPath) -> None:
        # Point by point: json's C encoder keeps the interpreter for a whole call (8 ms for
        # 2,000 points, during which a stop could not get through); the same text results.
        points = ", ".join(json.dumps(asdict(p)) for p in path.points)
        body = (f'{{"straight": {json.dumps(path.straight)}, "tcp": {json.dumps(list(path.tcp))}'
                f', "points": [{points}]}}')
        with self._lock, self._db:
            self._db.execute("INSERT OR REPLACE INTO paths (name, body) VALUES (?, ?)",
                             (path.name, body))

    def delete(self, name: str) -> None:
        with self._lock, self._db:
            self._db.execute("DELETE FROM paths WHERE name = ?", (name,))

    def close(self) -> None:
        with self._lock:
            self._db.close()


class PathLibrary(Mapping):
    """The named paths by name, in memory and written through to their store."""

    def __init__(self, store: PathStore):
        self._store = store
        self._paths = store.load_all()

    def __getitem__(self, name: str) -> StoredPath:
        return self._paths[name]

    def __iter__(self):
        return iter(self._paths)

    def __len__(self) -> int:
        return len(self._paths)

    def put(self, path: StoredPath) -> None:
        self._store.put(path)   # first: if the write fails, memory keeps the old path too
        self._paths[path.name] = path

    def close(self) -> None:
        self._store.close()

    def delete(self, name: str) -> None:
        if name not in self._paths:
            raise NotFound(f"no path named {name!r}")
        self._store.delete(name)
        del self._paths[name]


def _decode(name: str, body: str) -> StoredPath:
    data = json.loads(body)
    points = tuple(PathPoint(**{**p, "joints": tuple(p["joints"]),
                                "aux_commands": tuple(p["aux_commands"])})
                   for p in data["points"])
    return StoredPath(name, data["straight"], tuple(data["tcp"]), points)
