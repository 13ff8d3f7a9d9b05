"""Issue 10, seed 4: the DigitalIO service on the real server, the simulated cell's I/O on the
lock-step clock: the map, set and get by unit and bit field, outputs acting on the world,
and signalDigitalIO watches (event, alarm, RSVP, timeout) seen in the cycle."""
from __future__ import annotations

import re

import grpc
import numpy as np
import pytest

from landscape.client import Session
from landscape.server.events import alarms
from landscape.server.device.states import State
from landscape.v1 import digital_io_service_pb2 as pb
from landscape.v1 import end_effector_pb2 as ee

from support import Arm, activate, error_info, stubs, wait_until

INPUTS, OUTPUTS = 1, 2                                  # cell_inputs, cell_outputs
GRIPPER_CLOSED, PART_AT_PLACE = 1 << 0, 1 << 4          # unit 1
CHANGER_LOCK, GRIPPER_CLOSE, LAMP_GREEN, LAMP_RED = 1, 1 << 1, 1 << 3, 1 << 4   # unit 2


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    a.io = stubs(a.session.channel)[1]
    yield a
    a.close()


def _get(arm, unit: int, type: str) -> int:
    return arm.io.GetDigitalIO(pb.GetDigitalIORequest(type=type, unit_id=unit)).bits_on


def _refused(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


def test_the_io_map_names_every_unit_and_bit(arm):
    units = {u.unit_id: u for u in arm.io.ListDigitalIO(pb.ListDigitalIORequest()).units}
    assert {i: (u.name, u.type) for i, u in units.items()} == {
        0: ("safety", "input"), 1: ("cell_inputs", "input"), 2: ("cell_outputs", "output")}
    assert {b.name: b.bit for b in units[2].bits} == {
        "toolchanger_lock": 0, "gripper_close": 1, "vacuum_on": 2, "lamp_green": 3, "lamp_red": 4}
    assert {b.name for b in units[1].bits} >= {"gripper_closed", "part_at_pick", "tool_id_0"}


def test_outputs_are_set_and_cleared_by_bit_field(arm):
    arm.io.SetDigitalIO(pb.SetDigitalIORequest(type="output", unit_id=OUTPUTS,
                                               bits_on=LAMP_GREEN | LAMP_RED,
                                               description="stack light on"))
    assert _get(arm, OUTPUTS, "output") == LAMP_GREEN | LAMP_RED
    arm.io.SetDigitalIO(pb.SetDigitalIORequest(type="output", unit_id=OUTPUTS,
                                               bits_on=0, bits_off=LAMP_RED))
    assert _get(arm, OUTPUTS, "output") == LAMP_GREEN
    assert _get(arm, 0, "input") == 1 << 1          # safety: door closed, e-stop released


@pytest.mark.parametrize("fields, code", [
    ({"type": "input", "unit_id": INPUTS, "bits_on": 1}, grpc.StatusCode.INVALID_ARGUMENT),
    ({"type": "output", "unit_id": 9, "bits_on": 1}, grpc.StatusCode.INVALID_ARGUMENT),
    ({"type": "output", "unit_id": OUTPUTS, "bits_on": 1 << 9}, grpc.StatusCode.OUT_OF_RANGE),
    ({"type": "output", "unit_id": OUTPUTS, "bits_on": LAMP_RED, "bits_off": LAMP_RED},
     grpc.StatusCode.INVALID_ARGUMENT),
    ({"type": "wobble", "unit_id": OUTPUTS, "bits_on": LAMP_RED},
     grpc.StatusCode.INVALID_ARGUMENT),
])
def test_bad_writes_are_refused_and_change_nothing(arm, fields, code):
    error = _refused(lambda: arm.io.SetDigitalIO(pb.SetDigitalIORequest(**fields)))
    assert error.code() is code, error.details()
    assert _get(arm, OUTPUTS, "output") == 0


def test_only_the_lock_holder_sets_and_anyone_reads(arm):
    other = grpc.insecure_channel(arm.server.target)
    _, io, _ = stubs(other)
    error = _refused(lambda: io.SetDigitalIO(pb.SetDigitalIORequest(
        type="output", unit_id=OUTPUTS, bits_on=LAMP_RED)))
    assert error.code() is grpc.StatusCode.PERMISSION_DENIED
    assert io.GetDigitalIO(pb.GetDigitalIORequest(type="output", unit_id=OUTPUTS)).bits_on == 0
    error = _refused(lambda: io.GetDigitalIO(pb.GetDigitalIORequest(type="input",
                                                                    unit_id=OUTPUTS)))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    other.close()


@pytest.mark.physics   # the world: tools, parts, wired inputs, sensor readings
def test_a_wired_output_acts_on_the_world_and_its_input_follows(arm):
    arm.get_tool("gripper")
    assert _get(arm, INPUTS, "input") & GRIPPER_CLOSED == 0
    arm.io.SetDigitalIO(pb.SetDigitalIORequest(type="output", unit_id=OUTPUTS,
                                               bits_on=GRIPPER_CLOSE))
    wait_until(lambda: _get(arm, INPUTS, "input") & GRIPPER_CLOSED, timeout=10)
    reply = arm.device.GetEndEffectorState(ee.GetEndEffectorStateRequest())
    assert (reply.current_ee, reply.ee_state) == ("gripper", "closed")


@pytest.mark.physics   # the world: tools, parts, wired inputs, sensor readings
def test_the_changer_closes_on_nothing_and_opens_only_with_its_tool_in_the_rack(arm):
    arm.io.SetDigitalIO(pb.SetDigitalIORequest(type="output", unit_id=OUTPUTS,
                                               bits_on=CHANGER_LOCK))
    assert _get(arm, OUTPUTS, "output") & CHANGER_LOCK        # locked on air: no tool
    reply = arm.device.GetEndEffectorState(ee.GetEndEffectorStateRequest())
    assert reply.current_ee == "" and np.allclose(arm.server.device.settings.tool_offset,
                                                  np.eye(4))
    arm.io.SetDigitalIO(pb.SetDigitalIORequest(type="output", unit_id=OUTPUTS,
                                               bits_off=CHANGER_LOCK))
    arm.get_tool("vacuum")
    error = _refused(lambda: arm.io.SetDigitalIO(pb.SetDigitalIORequest(
        type="output", unit_id=OUTPUTS, bits_off=CHANGER_LOCK)))
    assert error.code() is grpc.StatusCode.FAILED_PRECONDITION and "rack" in error.details()
    assert _get(arm, OUTPUTS, "output") & CHANGER_LOCK        # still locked, the tool still on
    reply = arm.device.GetEndEffectorState(ee.GetEndEffectorStateRequest())
    assert reply.current_ee == "vacuum"


# ---- signalDigitalIO ------------------------------------------------------------------------

def _watch(arm, **fields) -> str:
    request = dict(type="input", unit_id=INPUTS, bit_string=PART_AT_PLACE,
                   callback_type=pb.CALLBACK_TYPE_CLIENT_EVENT)
    request.update(fields)
    reply = arm.io.SignalDigitalIO(pb.SignalDigitalIORequest(**request))
    return reply.ret_val.command_id


def _events(arm, command_id: str, until=("command_done", "command_failed")) -> list:
    seen = []
    while True:
        event = arm.next_event()
        names_it = (event.HasField("command") and event.command.command_id == command_id
                    or event.HasField("digital_io") and event.digital_io.command_id == command_id
                    or event.HasField("alarm") and event.alarm.command_id == command_id
                    or command_id in event.data)
        if names_it:
            seen.append(event)
            if event.event_id in until:
                return seen


def _place_part_in_the_zone(arm) -> int:
    """Put a block in the place zone between two cycles; the sequence of the next cycle."""
    def place(controller):
        controller.panel.place_part("block_1", (0.73, -0.15, 0.22))
        return controller.cyclic.sequence
    return arm.link.between_cycles(place)


def _cycle_of(event) -> int:
    return int(re.search(r"cycle (\d+)", event.command.message).group(1))


def _watch_from_the_next_cycle(arm, **fields) -> tuple[str, int]:
    """A watch handed over while the clock stands still: (its id, the cycle it starts in)."""
    clock = arm.link.clock
    clock.hold()
    try:
        return _watch(arm, **fields), arm.server.link.feedback.head + 1
    finally:
        clock.release()


@pytest.mark.physics   # the world: tools, parts, wired inputs, sensor readings
def test_a_watch_delivers_its_event_within_two_cycles_of_its_bits_being_set(arm):
    """Seen in the cycle after the bits were set, and delivered to the client with the
    controller at most two cycles further: the clock stands still after those cycles (the
    test steps them itself, between cycles), and the event must reach the client then."""
    command_id = _watch(arm)
    assert _events(arm, command_id, until=("command_started",))
    clock = arm.link.clock
    clock.hold()
    try:
        def place_and_step(controller) -> int:
            controller.panel.place_part("block_1", (0.73, -0.15, 0.22))
            set_in = controller.cyclic.sequence
            for _ in range(3):          # cycles set_in, set_in + 1, set_in + 2
                controller.step()
            return set_in
        set_in = arm.link.between_cycles(place_and_step)
        signal = _events(arm, command_id, until=("digital_io",))[-1]
        head = arm.server.link.feedback.head      # the controller when the client has it
    finally:
        clock.release()
    assert signal.digital_io.bits_on & PART_AT_PLACE
    assert signal.digital_io.bit_string == PART_AT_PLACE
    done = _events(arm, command_id)[-1]
    assert done.event_id == "command_done"
    seen_in = _cycle_of(done)
    print(f"\nbits set before cycle {set_in}, seen in cycle {seen_in}, the event at the client "
          f"with the controller at cycle {head}")
    assert 0 <= seen_in - set_in <= 1
    assert head - set_in <= 2


def test_bits_set_already_fire_at_the_first_poll_and_outputs_can_be_watched(arm):
    arm.io.SetDigitalIO(pb.SetDigitalIORequest(type="output", unit_id=OUTPUTS,
                                               bits_on=LAMP_GREEN))
    command_id, first = _watch_from_the_next_cycle(
        arm, type="output", unit_id=OUTPUTS, bit_string=LAMP_GREEN, polling_cycle_time=40)
    events = _events(arm, command_id)
    assert events[-1].event_id == "command_done"
    assert _cycle_of(events[-1]) == first


def test_a_watch_not_satisfied_in_time_fails_with_a_timeout(arm):
    command_id, first = _watch_from_the_next_cycle(arm, polling_timeout=100,
                                                   polling_cycle_time=8)
    events = _events(arm, command_id)
    assert [e.event_id for e in events] == ["command_started", "command_failed"]
    assert events[-1].command.message.startswith("timeout")
    assert _cycle_of(events[-1]) - first == 25 - 1   # 100 ms of 4 ms cycles, the first counts


@pytest.mark.physics   # the world: tools, parts, wired inputs, sensor readings
def test_the_alarm_callback_raises_an_alarm(arm):
    command_id = _watch(arm, callback_type=pb.CALLBACK_TYPE_CLIENT_ALARM)
    _place_part_in_the_zone(arm)
    events = _events(arm, command_id)
    assert [e.event_id for e in events] == ["command_started", "alarm", "command_done"]
    assert events[1].alarm.code == alarms.DIGITAL_IO


@pytest.mark.parametrize("callback, alarm", [(pb.CALLBACK_TYPE_CLIENT_EVENT_RSVP, False),
                                             (pb.CALLBACK_TYPE_CLIENT_ALARM_RSVP, True)])
def test_the_rsvp_callback_asks_the_lock_holder_and_gets_its_answer(tmp_path, callback, alarm):
    arm = Arm(tmp_path)
    asked = []

    def answer(request):
        asked.append(request)
        return "acknowledge", list(request.data)

    holder = Session(grpc.insecure_channel(arm.server.target), "operator",
                     on_rsvp=answer).open()
    try:
        arm.session.close()                        # the lock passes to the operator
        wait_until(lambda: arm.server.device.state is State.UNLOCKED, timeout=10)
        holder.lock()
        activate(holder)
        io = stubs(holder.channel)[1]
        command_id = io.SignalDigitalIO(pb.SignalDigitalIORequest(
            type="input", unit_id=INPUTS, bit_string=PART_AT_PLACE,
            callback_type=callback)).ret_val.command_id
        _place_part_in_the_zone(arm)
        events = _events(arm, command_id)
        kinds = [e.event_id for e in events]
        assert kinds == ["command_started", "rsvp_request", "rsvp_answer", "command_done"], kinds
        assert asked and asked[0].event_id == "digital_io"
        assert asked[0].alarm is alarm and events[1].rsvp_request.alarm is alarm
        assert list(asked[0].choices) == ["acknowledge"]
        answer_event = events[2].rsvp_answer
        assert (answer_event.choice, answer_event.timed_out) == ("acknowledge", False)
        assert events[-1].command.message.endswith("answered acknowledge")
    finally:
        holder.close()
        arm.close()


@pytest.mark.parametrize("fields, code", [
    ({"bit_string": 0}, grpc.StatusCode.INVALID_ARGUMENT),
    ({"bit_string": 1 << 20}, grpc.StatusCode.OUT_OF_RANGE),
    ({"polling_timeout": -1}, grpc.StatusCode.OUT_OF_RANGE),
    ({"type": "output"}, grpc.StatusCode.INVALID_ARGUMENT),        # unit 1 holds inputs
    ({"callback_type": pb.CALLBACK_TYPE_UNSPECIFIED}, grpc.StatusCode.INVALID_ARGUMENT),
])
def test_bad_watches_are_refused(arm, fields, code):
    error = _refused(lambda: _watch(arm, **fields))
    assert error.code() is code
    assert error_info(error).metadata["ret_code"] in ("-2", "-3")
