"""Rows of several arrays read as one array without joining them: a run timed as it plays
(run_arrays.GrowingSegments) grows its playing segment by parts, and the play steps across them
instead of copying the whole segment on the cycle at every part (quadratic in a long path)."""
from __future__ import annotations

from bisect import bisect_right

import numpy as np


class JoinedRows:
    """Arrays (N_k, M) one after the other, read as one (sum of N_k, M) array for what the play
    and its ramps ask of a segment's rows (playback.py, ramps.py): `len`, a row, a slice of rows
    (a view inside one part; across parts, a copy of those rows alone), rows by an index array
    or list, each optionally with a column index; all rows of some columns come as a
    JoinedRows of views. `extend` appends a part."""

    def __init__(self, parts=()):
        self._parts: list[np.ndarray] = []
        self._starts: list[int] = []   # each part's first row
        self._rows = 0
        for part in parts:
            self.extend(part)

    def extend(self, part: np.ndarray) -> None:
        self._starts.append(self._rows)
        self._parts.append(part)
        self._rows += len(part)

    def __len__(self) -> int:
        return self._rows

    def _part(self, row: int) -> int:
        return bisect_right(self._starts, row) - 1

    def __getitem__(self, key):
        rows, columns = key if isinstance(key, tuple) else (key, None)
        if isinstance(rows, (int, np.integer)):
            row = int(rows) + (self._rows if rows < 0 else 0)
            if not 0 <= row < self._rows:
                raise IndexError(f"row {rows} of {self._rows}")
            k = self._part(row)
            found = self._parts[k][row - self._starts[k]]
        elif isinstance(rows, slice) and rows.step in (None, 1):
            if rows == slice(None) and columns is not None:
                return JoinedRows(part[:, columns] for part in self._parts)
            found = self._slice(*rows.indices(self._rows)[:2])
        else:
            found = self._taken(np.arange(self._rows)[rows] if isinstance(rows, slice)
                                else np.asarray(rows))
        return found if columns is None else found[..., columns]

    def _slice(self, start: int, stop: int) -> np.ndarray:
        if stop <= start:
            return self._parts[0][:0]
        first, last = self._part(start), self._part(stop - 1)
        pieces = [self._parts[k][max(start - self._starts[k], 0):stop - self._starts[k]]
                  for k in range(first, last + 1)]
        return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)

    def _taken(self, index: np.ndarray) -> np.ndarray:
        index = np.where(index < 0, index + self._rows, index)
        if index.size and (index.min() < 0 or index.max() >= self._rows):
            raise IndexError(f"rows {index.min()}..{index.max()} of {self._rows}")
        which = np.searchsorted(self._starts, index, side="right") - 1
        out = np.empty(index.shape + self._parts[0].shape[1:], dtype=self._parts[0].dtype)
        for k in np.unique(which):
            here = which == k
            out[here] = self._parts[k][index[here] - self._starts[k]]
        return out
