"""Issue 29 item 2: every device server serves /metrics; a scrape, parsed with
prometheus-client's own parser, has the cell's figures, and they move with the cell."""
from __future__ import annotations

import math
import urllib.request

import grpc
import pytest
from prometheus_client.parser import text_string_to_metric_families

from landscape.server.app import StartupError, serve
from landscape.server.config import SecurityConfig, ServerConfig
from landscape.v1 import control_pb2, motion_pb2, types_pb2

from support import activate, locked_session, stubs, wait_until


def scrape(url: str) -> dict[tuple[str, tuple], float]:
    """Every sample of a scrape: (name, sorted labels) -> value."""
    text = urllib.request.urlopen(url, timeout=10).read().decode()
    return {(sample.name, tuple(sorted(sample.labels.items()))): sample.value
            for family in text_string_to_metric_families(text) for sample in family.samples}


def value(samples: dict, name: str, **labels) -> float:
    return samples.get((name, tuple(sorted(labels.items()))), math.nan)


def total(samples: dict, name: str, **labels) -> float:
    """The sum of `name` over the samples carrying `labels` (and any others)."""
    return sum(v for (n, ls), v in samples.items()
               if n == name and set(labels.items()) <= set(ls))


@pytest.fixture(scope="module")
def server():
    """A device server as the cell runs it: the real-time cycle process, /metrics on."""
    running = serve(ServerConfig(port=0, clock="realtime", metrics_port=0))
    yield running
    running.stop(grace=None)


@pytest.mark.slow   # the real-time cycle process
def test_a_scrape_has_the_cell_s_figures_and_they_move_with_it(server):
    before = scrape(server.metrics.url)
    assert value(before, "landscape_device_state", state="unlocked") == 1.0
    assert value(before, "landscape_sessions") == 0.0
    assert value(before, "process_resident_memory_bytes") > 0
    assert value(before, "landscape_cycle_process_resident_memory_bytes") > 0

    session = locked_session(server, "metrics-test")
    try:
        activate(session)
        device, _, _ = stubs(session.channel)
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=[1.5, 0, 1.5708, 0, 1.5708, 0]),
            timeout=30)
        assert reply.ret_val.command_id
        with pytest.raises(grpc.RpcError):     # refused: a move while moving
            device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=[0, 0, 1.5708, 0, 1.5708, 0]),
                timeout=30)
        during = scrape(server.metrics.url)
        assert value(during, "landscape_sessions") == 1.0
        assert value(during, "landscape_lock_handovers_total", direction="taken") >= 1
        assert total(during, "landscape_planning_seconds_count", kind="move") >= 1
        device.OperatePanel(control_pb2.OperatePanelRequest(
            action=control_pb2.PANEL_ACTION_PRESS_ESTOP), timeout=10)
        wait_until(lambda: value(scrape(server.metrics.url), "landscape_estop") == 1.0, 10)
        after = scrape(server.metrics.url)
    finally:
        session.close()

    assert value(after, "landscape_device_state", state="error") == 1.0
    assert total(after, "landscape_alarms_total") > total(before, "landscape_alarms_total")
    # the cycle's histograms count every cycle run, and grow with them
    cycles = value(after, "landscape_cycles_total")
    assert cycles > value(before, "landscape_cycles_total") > 0
    assert value(after, "landscape_cycle_period_seconds_bucket", le="+Inf") >= cycles - 2
    assert value(after, "landscape_cycle_late_seconds_count") >= cycles - 1
    assert value(after, "landscape_cycle_overruns_total") >= 0
    # RPC latency by method and status code
    assert total(after, "landscape_rpc_duration_seconds_count", method="MoveAbsolute",
                 code="OK") == 1
    assert total(after, "landscape_rpc_duration_seconds_count", method="MoveAbsolute",
                 code="FAILED_PRECONDITION") == 1
    assert total(after, "landscape_rpc_duration_seconds_count", method="Lock", code="OK") == 1
    assert value(after, "landscape_queue_depth", queue="commands") >= 0
    assert value(after, "landscape_streams", kind="session") >= 0


def test_metrics_stay_off_unless_asked_and_off_loopback_need_tls(tmp_path):
    with pytest.raises(StartupError, match="metrics.*plaintext"):
        serve(ServerConfig(port=0, clock="lockstep", metrics_port=0, metrics_address="0.0.0.0"))
    server = serve(ServerConfig(port=0, clock="lockstep", security=SecurityConfig()))
    try:
        assert server.metrics is None and server.security.idle
    finally:
        server.stop(grace=None)


def test_on_the_lock_step_clock_a_scrape_has_no_cycle_timing_but_the_rest(tmp_path):
    server = serve(ServerConfig(port=0, clock="lockstep", metrics_port=0))
    try:
        samples = scrape(server.metrics.url)
        assert value(samples, "landscape_device_state", state="unlocked") == 1.0
        assert not any(name.startswith("landscape_cycle_") and "process" not in name
                       for name, _ in samples)
    finally:
        server.stop(grace=None)


@pytest.mark.slow   # the real-time cycle process
def test_every_metric_the_dashboard_and_the_alerts_use_is_served(server):
    """docs/grafana: each landscape_* name its queries use is in a device server's scrape
    (the gateway's landscape_crcl_* is checked by tests/cell/test_bridges_launch.py)."""
    import re
    from pathlib import Path
    docs = Path(__file__).resolve().parents[2] / "docs" / "grafana"
    used = set()
    for path in (docs / "landscape-cell.json", docs / "alerts.yml"):
        used |= set(re.findall(r"\b(landscape_[a-z_]+|process_[a-z_]+)", path.read_text()))
    served = {re.sub(r"_(bucket|count|sum|total|created)$", "", name)
              for name, _ in scrape(server.metrics.url)}
    missing = {name for name in used if not name.startswith("landscape_crcl_")
               and re.sub(r"_(bucket|count|sum|total)$", "", name) not in served}
    assert not missing, missing
