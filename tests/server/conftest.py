"""Fixtures of the server tests."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from support import Arm, memory_cap

BACKENDS = ("pybullet", "kinematic")


@pytest.fixture(params=BACKENDS)
def backend(request) -> str:
    """The device's contract holds on every controller backend: each test of a server or an
    arm runs on both, except those marked `physics` (pybullet only; tests/conftest.py)."""
    return request.param


@pytest.fixture
def arm(tmp_path, backend):
    """An active arm on the lock-step clock (support.Arm), closed after the test."""
    a = Arm(tmp_path, backend=backend)
    yield a
    a.close()


@pytest.fixture
def memory_capped():
    """The test runs under support.memory_cap: a runaway allocation fails it, not the machine."""
    with memory_cap():
        yield


class SmallDisk:
    """A filesystem of a few hundred KiB at `path`; `fill()` takes its every free byte,
    `free()` gives them back."""

    def __init__(self, path: Path):
        self.path = path
        self._filler = path / "filler"

    def fill(self) -> None:
        with open(self._filler, "ab", buffering=0) as out:
            try:
                while True:
                    out.write(b"\0" * 4096)
            except OSError:     # ENOSPC: full
                pass
            try:                # the last few bytes too
                while True:
                    out.write(b"\0")
            except OSError:
                pass

    def free(self) -> None:
        self._filler.unlink(missing_ok=True)


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs mounted for the test (root: CI runs as root), unmounted after it;
    skipped where it cannot be mounted."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small filesystem needs root")
    path = tmp_path / "disk"
    path.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(path)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.strip()}")
    try:
        yield SmallDisk(path)
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)
