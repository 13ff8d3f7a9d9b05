"""The arrays of a run: back-to-back trajectory segments, as the server packs them and the
cycle reads them (through SharedArrays: shared memory for a cycle process)."""
from __future__ import annotations

import numpy as np

from landscape.server.cycle.joined_rows import JoinedRows


def pack_run(trajectories, dt: float) -> dict[str, np.ndarray]:
    """The arrays of a run of back-to-back trajectories, for `Segments` (the cycle)."""
    rows = [0]
    marks, segments = [], []
    for t in trajectories:
        m0 = len(marks)
        marks.extend(t.marks)
        segments.append((rows[-1], rows[-1] + len(t), m0, len(marks)))
        rows.append(rows[-1] + len(t))
    positions = np.concatenate([t.positions for t in trajectories])
    velocities = np.concatenate([t.velocities for t in trajectories])
    accelerations = np.concatenate([
        np.diff(t.velocities, axis=0, append=t.velocities[-1:]) / dt for t in trajectories])
    return {"positions": positions, "velocities": velocities, "accelerations": accelerations,
            "marks": np.array(marks, dtype=np.int64).reshape(-1, 2),
            "segments": np.array(segments, dtype=np.int64).reshape(-1, 4)}


class Segments:
    """The segments of a run, read from its shared arrays when played (not all at once: a run
    may have many): "positions", "velocities", "accelerations" (N, 6), "marks" (M, 2) as
    (sample in its segment, label), and "segments" (S, 4): row start, row end, first mark,
    end of marks."""

    def __init__(self, arrays: dict):
        self._a = arrays

    def __len__(self) -> int:
        return len(self._a["segments"])

    def __getitem__(self, index: int) -> dict:
        start, end, m0, m1 = (int(v) for v in self._a["segments"][index])
        return {"positions": self._a["positions"][start:end],
                "velocities": self._a["velocities"][start:end],
                "accelerations": self._a["accelerations"][start:end],
                "marks": self._a["marks"][m0:m1]}


class GrowingSegments:
    """The segments of a run timed as it plays (issue 31 item 4): blocks of Segments appended
    as they come, a block's first segment joined to the one before if it continues it (its
    rows follow on, the arm moving: one segment to play). A joined segment is read across its
    parts (JoinedRows), never copied whole, and the one read grows in place as parts come:
    an append costs the cycle the same however long the segment is."""

    ROWS = ("positions", "velocities", "accelerations")

    def __init__(self, first):
        self._parts: list[list[tuple]] = [[(first, i)] for i in range(len(first))]
        self._joined: dict[int, dict] = {}   # segment index -> it read across its parts

    def __len__(self) -> int:
        return len(self._parts)

    def append(self, block, continues: bool) -> None:
        """The block's segments after those so far, its first joined to the last if it
        `continues` it."""
        for i in range(len(block)):
            if i == 0 and continues:
                self._parts[-1].append((block, i))
                joined = self._joined.get(len(self._parts) - 1)
                if joined is not None:
                    self._join(joined, block[i])
            else:
                self._parts.append([(block, i)])

    def __getitem__(self, index: int) -> dict:
        parts = self._parts[index]
        if len(parts) == 1:
            block, i = parts[0]
            return block[i]
        index %= len(self._parts)
        joined = self._joined.get(index)
        if joined is None:
            joined = {name: JoinedRows() for name in self.ROWS}
            joined["marks"] = []   # (sample in the joined segment, label)
            for block, i in parts:
                self._join(joined, block[i])
            self._joined[index] = joined
        return joined

    def _join(self, joined: dict, segment: dict) -> None:
        offset = len(joined["positions"])
        for name in self.ROWS:
            joined[name].extend(segment[name])
        joined["marks"].extend((int(at) + offset, int(label)) for at, label in segment["marks"])
