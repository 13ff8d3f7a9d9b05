"""Silence what native code prints on the process's own stdout and stderr.

pybullet's C++ prints a build banner when imported and "argv[0]=" when a client connects,
straight to file descriptors 1 and 2, past Python's sys.stdout; a server's output must be its
own. Only for short stretches at start-up: other threads' output is lost meanwhile too.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys

_libc = ctypes.CDLL(None)


@contextlib.contextmanager
def silenced():
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        _libc.fflush(None)   # what C buffered goes to /dev/null, not out after we restore
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)
