"""Child processes that end with their parent, whatever kills it (issue 25.7).

A child sets the kernel's parent-death signal (Linux prctl PR_SET_PDEATHSIG) first thing: when
its parent dies, even by SIGKILL, the kernel sends it `signum` at once. A child busy for
seconds (planning a long path) would otherwise only notice at its next read of the pipe.

The kernel counts as the parent the *thread* that started the child, and signals when that
thread ends. So children are started (`start`) from one thread kept for that, which lives as
long as the process: a child started from a worker thread that later ends lives on.

A child still importing when its parent dies has not set the signal yet: `bind_to_parent`
checks that the parent it was given is still its parent, and signals itself if not.
"""
from __future__ import annotations

import ctypes
import os
import threading
from concurrent.futures import ThreadPoolExecutor

PR_SET_PDEATHSIG = 1       # linux/prctl.h

_spawner: ThreadPoolExecutor | None = None
_spawner_lock = threading.Lock()


def start(process) -> None:
    """`process.start()` (a multiprocessing Process) on the thread kept for starting children;
    returns once it has started, raising what start() raised."""
    global _spawner
    with _spawner_lock:
        if _spawner is None:
            _spawner = ThreadPoolExecutor(1, thread_name_prefix="child-spawner")
    _spawner.submit(process.start).result()


def bind_to_parent(parent_pid: int, signum: int) -> bool:
    """In a child: receive `signum` when the parent (pid `parent_pid`) dies; if it has died
    already, now. False where the kernel has no parent-death signal (not Linux): the child
    must then watch its pipe to the parent."""
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return False
    if prctl(PR_SET_PDEATHSIG, signum, 0, 0, 0) != 0:
        return False
    if os.getppid() != parent_pid:     # died before the line above: nobody will signal
        os.kill(os.getpid(), signum)
    return True
