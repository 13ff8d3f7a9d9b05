"""How the gateway judges a motion: on the device's present state (never an old sample), against
an end tolerance that always exists, with each command's own rates; against the real device
server (through a forwarding proxy where the state stream must stall)."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from landscape.gateway.errors import CrclError
from landscape.gateway.motions import check_pose
from landscape.gateway.settings import CrclSettings, ToleranceSi
from landscape.gateway.units import CrclUnits

from crcl_support import ToolWatch, field, pose
from test_gateway import MOVE, point

GOAL = np.array([0.5, 0.1, 0.6, math.pi, 0.0, 0.0])


def test_an_end_pose_off_by_more_than_the_default_tolerance_is_no_success():
    """Without SetEndPoseTolerance, 1 mm and 1 mrad hold (settings.DEFAULT_END_TOLERANCE)."""
    units, default = CrclUnits(), CrclSettings().end_tolerance
    assert "reached" in check_pose(units, GOAL, default, GOAL + [0.0005, 0, 0, 0, 0, 0])
    with pytest.raises(CrclError, match="off in X"):
        check_pose(units, GOAL, default, GOAL + [0.002, 0, 0, 0, 0, 0])
    with pytest.raises(CrclError, match="XAxis|ZAxis"):
        check_pose(units, GOAL, default, GOAL + [0, 0, 0, 0, 0.01, 0])
    # an element a SetEndPoseTolerance leaves out keeps the default
    only_x = ToleranceSi(x=0.01).over(default)
    with pytest.raises(CrclError, match="off in Y"):
        check_pose(units, GOAL, only_x, GOAL + [0.005, 0.002, 0, 0, 0, 0])


def test_status_says_how_old_a_stalled_state_is(proxied):
    proxy, _, client = proxied
    assert field(client.status(), "StateDescription") is None or \
        "old" not in field(client.status(), "StateDescription")
    proxy.hold("StreamState")
    time.sleep(1.5)
    description = field(client.status(), "StateDescription")
    assert description and "the device's state is" in description and "s old" in description
    proxy.release("StreamState")
    deadline = time.monotonic() + 10
    while "old" in (field(client.status(), "StateDescription") or ""):
        assert time.monotonic() < deadline
        time.sleep(0.05)


def test_a_motion_is_not_judged_on_a_sample_from_before_its_end(proxied):
    proxy, gateway, client = proxied
    proxy.hold("StreamState")
    stalled = client.run("MoveTo", 2, MOVE.format("true") + pose(0.5, 0.1, 0.6))
    assert field(stalled, "CommandState") == "CRCL_Error", stalled
    assert "the end pose is unchecked" in field(stalled, "StateDescription")
    # a path starts from the arm's present joints, which a stalled stream cannot give
    through = client.run("MoveThroughTo", 3, MOVE.format("false") + pose(
        0.5, 0.0, 0.6, tag="Waypoint") + pose(0.5, -0.1, 0.6, tag="Waypoint") +
        "<NumPositions>2</NumPositions>")
    assert field(through, "CommandState") == "CRCL_Error", through
    assert "no present state from the device" in field(through, "StateDescription")
    proxy.release("StreamState")
    deadline = time.monotonic() + 20                # the proxy's backlog drains
    while time.time() - gateway.link.feed.latest.time > 0.2:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    done = client.run("MoveTo", 4, MOVE.format("true") + pose(0.5, -0.1, 0.6))
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx((0.5, -0.1, 0.6), abs=1e-4)


# ---- per-command rates and tolerances ------------------------------------------------------------

def _turned(yaw_degrees: float, settings: str = "", tag: str = "EndPosition") -> str:
    """The pose (0.5, 0, 0.6) pointing down, turned about the vertical; PoseAndSetType when
    `settings` are given."""
    a = math.radians(yaw_degrees)
    body = pose(0.5, 0.0, 0.6, xaxis=(math.cos(a), -math.sin(a), 0), tag=tag)
    if not settings:
        return body
    return body.replace(f"<{tag}>", f'<{tag} xsi:type="PoseAndSetType">', 1).replace(
        f"</{tag}>", f"<Coordinated>false</Coordinated>{settings}</{tag}>")


def test_a_pose_own_rot_speed_holds_for_its_move_only(server, client):
    client.run("MoveTo", 2, MOVE.format("true") + _turned(0))
    watch = ToolWatch(server.target)
    slow = client.run("MoveTo", 3, MOVE.format("true") + _turned(
        60, '<RotSpeed xsi:type="RotSpeedAbsoluteType"><Setting>0.2</Setting></RotSpeed>'))
    assert field(slow, "CommandState") == "CRCL_Done", slow
    slow_rate = watch.peak_turn_rate()
    watch = ToolWatch(server.target)
    fast = client.run("MoveTo", 4, MOVE.format("true") + _turned(0))
    assert field(fast, "CommandState") == "CRCL_Done", fast
    fast_rate = watch.peak_turn_rate()
    assert 0.1 < slow_rate <= 0.2 * 1.02, slow_rate
    assert fast_rate > 2 * 0.2, fast_rate          # the session's RotSpeed is back


def test_a_pose_own_rot_speed_on_a_joint_motion_is_refused_not_ignored(client):
    refused = client.run("MoveTo", 2, MOVE.format("false") + _turned(
        30, '<RotSpeed xsi:type="RotSpeedAbsoluteType"><Setting>0.2</Setting></RotSpeed>'))
    assert field(refused, "CommandState") == "CRCL_Error", refused
    assert "straight motions only" in field(refused, "StateDescription")


def test_move_screw_ends_within_the_tolerance_its_start_position_gives(client):
    """The start's tolerance, not SetEndPoseTolerance's, judges the screw's end (spec VII)."""
    client.run("SetEndPoseTolerance", 2, "<Tolerance><XPointTolerance>1e-12</XPointTolerance>"
                                         "<YPointTolerance>1e-12</YPointTolerance></Tolerance>")
    start = _turned(0, "<Tolerance><XPointTolerance>0.001</XPointTolerance><YPointTolerance>0.001"
                       "</YPointTolerance></Tolerance>", tag="StartPosition")
    screw = client.run("MoveScrew", 3, start + "<AxialDistanceScrew>-0.01</AxialDistanceScrew>"
                                              "<Turn>0.3</Turn>")
    assert field(screw, "CommandState") == "CRCL_Done", screw
    assert point(screw) == pytest.approx((0.5, 0.0, 0.61), abs=1e-4)
    plain = client.run("MoveTo", 4, MOVE.format("true") + pose(0.5, 0.05, 0.6))
    assert "beyond the tolerance 1e-12" in field(plain, "StateDescription")


def _calls_of(proxy, action) -> dict:
    before = dict(proxy.calls)
    action()
    return {k: v - before.get(k, 0) for k, v in proxy.calls.items() if v != before.get(k, 0)}


OWN_RATES = ("<Coordinated>true</Coordinated>"
             '<TransSpeed xsi:type="TransSpeedAbsoluteType"><Setting>0.3</Setting></TransSpeed>'
             '<RotSpeed xsi:type="RotSpeedAbsoluteType"><Setting>0.4</Setting></RotSpeed>'
             '<TransAccel xsi:type="TransAccelRelativeType"><Fraction>0.3</Fraction></TransAccel>'
             '<RotAccel xsi:type="RotAccelAbsoluteType"><Setting>2</Setting></RotAccel>')


def test_a_move_to_is_one_device_call_with_its_own_rates_or_the_sessions(proxied):
    """Issue 27 item 6: no settings round trips (nor stored settings) around a motion."""
    proxy, _, client = proxied
    done = lambda status: field(status, "CommandState") == "CRCL_Done"  # noqa: E731
    assert _calls_of(proxy, lambda: done(client.run(
        "MoveTo", 2, MOVE.format("true") + pose(0.5, 0.1, 0.6)))) == {"MoveAbsolute": 1}
    own = pose(0.5, -0.1, 0.6).replace("</ZAxis></EndPosition>", f"</ZAxis>{OWN_RATES}"
                                       "</EndPosition>").replace("<EndPosition>",
                                                                 '<EndPosition xsi:type='
                                                                 '"PoseAndSetType">')
    status = []
    assert _calls_of(proxy, lambda: status.append(client.run(
        "MoveTo", 3, MOVE.format("true") + own))) == {"MoveAbsolute": 1}
    assert done(status[0]), status[0]
    assert _calls_of(proxy, lambda: client.run(
        "MoveTo", 4, MOVE.format("false") + pose(0.5, 0.1, 0.6))) == {"MoveAbsolute": 1}
