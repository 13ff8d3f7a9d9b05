"""Shared fixtures: a real device server on a free loopback port, channels to it, and one
with TLS and role tokens."""
from __future__ import annotations

import os

import grpc
import pytest

from support import make_keys, start_secured_server, start_server


@pytest.fixture(scope="session", autouse=True)
def own_working_folder(tmp_path_factory):
    """Each pytest process (each xdist worker) works in a folder of its own: what a server
    writes to its default relative paths (var/paths.sqlite3, var/audit.log, var/records/)
    lands there, never in the checkout that the workers share."""
    before = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("cwd"))
    yield
    os.chdir(before)


@pytest.fixture
def backend() -> str:
    """The controller backend the device servers of a test run on (tests/server runs its tests
    on each, where physics does not matter: tests/server/conftest.py)."""
    return "pybullet"


@pytest.fixture
def server(backend):
    running = start_server(backend=backend)
    yield running
    running.stop(grace=None)


@pytest.fixture
def channel(server):
    with grpc.insecure_channel(server.target) as ch:
        grpc.channel_ready_future(ch).result(timeout=5)
        yield ch


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    """A development CA, a server certificate and one token file per role."""
    return make_keys(tmp_path_factory.mktemp("keys"))


@pytest.fixture
def secured(keys, backend):
    """A device server with TLS and the keys' role tokens."""
    running = start_secured_server(keys, backend=backend)
    yield running
    running.stop(grace=None)


# ---- the fast lane: `make test-fast` runs every test not marked slow -------------------------
# Slow, by module: browsers; other languages and the tools `make tools` / `make clients` build;
# cells of processes (device servers, gateways, clients of their own); the real-time cycle
# process; physics-heavy runs (force loops, pick and place, jogs paced at real time, long
# trajectories); fuzzing.
# The device's contract runs on both controller backends (tests/server/conftest.py): the fast
# lane runs it on the kinematic one (no physics: the arm follows its setpoints exactly), the
# full one on both. A test whose assertions need physics (a weight, a contact, a settling arm)
# is marked `physics` and runs on pybullet only, in both lanes.
SLOW_MODULES = {
    "tests/supervisor/test_page.py", "tests/supervisor/test_page_panels.py",          # browser
    "tests/clients/test_other_languages.py", "tests/server/test_grpcurl.py",         # languages
    "tests/gateway/test_nist_client.py", "tests/test_readme.py",
    "tests/cell/test_launcher.py", "tests/cell/test_compose.py",                     # processes
    "tests/cell/test_multi_host.py", "tests/reliability/test_load.py",
    "tests/reliability/test_lock_holder_faults.py", "tests/reliability/test_stops.py",
    "tests/reliability/test_server_restart.py", "tests/server/test_signals.py",
    "tests/server/test_logging.py", "tests/server/test_fast_clock.py",
    "tests/server/test_planning_process.py", "tests/examples/test_examples.py",
    "tests/server/test_controller_loss.py", "tests/server/test_realtime.py",          # real time
    "tests/server/test_sensors.py", "tests/server/test_tools.py",                    # physics
    "tests/server/test_model_torques.py", "tests/server/test_jog.py",
    "tests/server/test_handover.py",
    "tests/fuzz/test_fuzz.py", "tests/server/test_fuzz_rpcs.py",                    # fuzzing
}
SLOW_TESTS = {   # physics-heavy, real time, device servers as processes
    "tests/server/test_safety.py::test_stop_motion_does_not_wait_for_long_planning",
    "tests/sim/test_clock.py::test_lock_step_motion_is_deterministic",
    "tests/supervisor/test_backend.py::test_the_world_follows_tool_changes_and_parts_taken_and_put",
    "tests/sim/test_clock.py::test_real_time_clock_drives_the_arm",
    "tests/sim/test_clock.py::test_an_urgent_call_is_answered_while_a_slow_call_runs",
    "tests/server/test_first_hour.py::test_an_ipv6_address_works_with_or_without_brackets",
}
SLOW_FIXTURES = {"realtime"}    # a real-time cycle process of the test's own


def pytest_collection_modifyitems(config, items):
    kept, physics_only = [], []
    for item in items:
        module, _, name = item.nodeid.partition("::")
        backend = getattr(item, "callspec", None) and item.callspec.params.get("backend")
        physics = item.get_closest_marker("physics") is not None
        if backend == "kinematic" and physics:
            physics_only.append(item)
            continue
        kept.append(item)
        if (module in SLOW_MODULES or f"{module}::{name.split('[')[0]}" in SLOW_TESTS
                or SLOW_FIXTURES & set(item.fixturenames)
                or (backend == "pybullet" and not physics)):
            item.add_marker(pytest.mark.slow)
    if physics_only:
        config.hook.pytest_deselected(items=physics_only)
        items[:] = kept
    # The slow modules first (each in its own order): the workers (pytest-xdist, a module to a
    # worker) take them on while the many short ones fill in, instead of ending on them.
    items.sort(key=lambda item: item.nodeid.partition("::")[0] not in SLOW_MODULES)
