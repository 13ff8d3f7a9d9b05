"""Fixtures of the server tests."""
from __future__ import annotations

import pytest

from support import Arm, memory_cap


@pytest.fixture
def arm(tmp_path):
    """An active arm on the lock-step clock (support.Arm), closed after the test."""
    a = Arm(tmp_path)
    yield a
    a.close()


@pytest.fixture
def memory_capped():
    """The test runs under support.memory_cap: a runaway allocation fails it, not the machine."""
    with memory_cap():
        yield
