"""Named numpy arrays handed to the cycle without copying them through the pipe.

A trajectory of ten minutes is about ten megabytes; unpickling it on the cycle thread would
make that cycle late by tens of milliseconds. Across processes the arrays go into one block of
POSIX shared memory and the message carries only its name and layout, so taking them costs
the cycle one mmap whatever their size. On the lock-step thread (same process) the arrays are
passed as they are, and so are a short run's (under INLINE_BYTES) across processes: making a
block costs the sender more (shm_open, ftruncate, mmap and two messages to the resource
tracker: about 0.5 ms, before the motion's first cycle) than unpickling them costs the cycle
(under 0.1 ms).

The receiving side calls `open()` once (it unlinks the block's name: the mapping stays valid
until `close()`); the sending side calls `discard()` when the run is over, which unlinks the
name if the receiver never did (it died first).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from multiprocessing import resource_tracker, shared_memory

import _posixshmem

import numpy as np

_ALIGN = 64
INLINE_BYTES = 64 * 1024   # about 450 rows of a run (1.8 s at 4 ms): pickled with the message


@dataclass
class SharedArrays:
    layout: tuple            # ((name, dtype str, shape, byte offset), ...)
    block: str | None = None                 # shared memory name; None: `local` holds them
    local: dict | None = None
    _shm: shared_memory.SharedMemory | None = field(default=None, repr=False)

    @classmethod
    def create(cls, arrays: dict[str, np.ndarray], shared: bool) -> "SharedArrays":
        arrays = {name: np.ascontiguousarray(a) for name, a in arrays.items()}
        if not shared or sum(a.nbytes for a in arrays.values()) <= INLINE_BYTES:
            return cls(tuple((n, a.dtype.str, a.shape, 0) for n, a in arrays.items()),
                       local=arrays)
        layout, offset = [], 0
        for name, a in arrays.items():
            layout.append((name, a.dtype.str, a.shape, offset))
            offset += -(-a.nbytes // _ALIGN) * _ALIGN
        shm = shared_memory.SharedMemory(create=True, size=max(offset, 1))
        _untrack(shm)   # we unlink it ourselves (discard), not the resource tracker at exit
        for (name, dtype, shape, start), a in zip(layout, arrays.values()):
            np.ndarray(shape, dtype, shm.buf, start)[...] = a
        return cls(tuple(layout), block=shm.name, _shm=shm)

    def __getstate__(self):
        return {"layout": self.layout, "block": self.block, "local": self.local, "_shm": None}

    def open(self) -> dict[str, np.ndarray]:
        """The arrays (read-only views of the block when shared)."""
        if self.block is None:
            return dict(self.local)
        shm = shared_memory.SharedMemory(name=self.block)
        _untrack(shm)
        _unlink(self.block)   # nobody else needs the name: the mapping lives on until close()
        self._shm = shm
        views = {}
        for name, dtype, shape, start in self.layout:
            view = np.ndarray(shape, dtype, shm.buf, start)
            view.flags.writeable = False
            views[name] = view
        return views

    def close(self) -> None:
        """The receiver is done with the views (they must not be used after this)."""
        if self._shm is not None:
            try:
                self._shm.close()
            except BufferError:
                pass   # a view is still referenced; the mapping goes with the process
            self._shm = None

    def discard(self) -> None:
        """The sender is done: free the block (unlinks its name if the receiver did not)."""
        if self.block is not None and self._shm is not None:
            _unlink(self.block)
        self.close()


def _unlink(name: str) -> None:
    # Not SharedMemory.unlink(): it would also unregister a name we never left registered.
    try:
        _posixshmem.shm_unlink(name)
    except FileNotFoundError:
        pass


def _untrack(shm: shared_memory.SharedMemory) -> None:
    try:
        resource_tracker.unregister(shm._name, "shared_memory")  # noqa: SLF001 (Python 3.11)
    except Exception:
        pass
