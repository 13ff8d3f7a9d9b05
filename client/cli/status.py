"""`landscape status` and `landscape watch`: read-only, any client, any state."""
from __future__ import annotations

import json
import queue
import threading
import time

import click

from landscape.client.cli.context import CliState, pass_state
from landscape.client.cli.output import (event_line, sample_line, state_name, to_dict,
                                         units_names)
from landscape.client.errors import LandscapeError, NotImplementedByServer
from landscape.client.values import Pose


@click.command()
@pass_state
def status(state: CliState) -> None:
    """The device: state, lock holder, motion, joints, tool tip, units, end effector."""
    with state.reader() as robot:
        device = robot.get_device_state()
        position = robot.get_robot_position()
        motion = robot.get_motion_control_state()
        try:
            effector = robot.get_end_effector_state()
            tool = {"current_ee": effector.current_ee, "ee_state": effector.ee_state}
        except NotImplementedByServer:
            tool = None
    units = units_names(position.units)
    data = {
        "target": state.target, "state": state_name(device.state), "locked": device.locked,
        "lock_holder": device.lock_holder, "estop": device.estop, "error": device.error,
        "command_id": device.command_id, "manual_control": device.manual_control,
        "motion_control_state": motion.motion_control_state, "control_mode": motion.control_mode,
        "joints": list(position.joint_position),
        "tool_pose": vars(Pose.from_pb(position.world_position)), "units": units,
        "end_effector": tool,
    }
    pose = data["tool_pose"]
    holder = f" (locked by {device.lock_holder})" if device.locked else ""
    lines = [
        f"device      {state.target}",
        f"state       {data['state']}{holder}" + ("  E-STOP" if device.estop else ""),
        *([f"error       {device.error}"] if device.error else []),
        f"motion      {motion.motion_control_state}, {motion.control_mode}"
        + (f", command {device.command_id}" if device.command_id else ""),
        f"joints      {' '.join(f'{q:.4f}' for q in position.joint_position)}  {units['angular']}",
        f"tool tip    x {pose['x']:.4f}  y {pose['y']:.4f}  z {pose['z']:.4f}  "
        f"roll {pose['roll']:.4f}  pitch {pose['pitch']:.4f}  yaw {pose['yaw']:.4f}  "
        f"(world frame; {units['linear']}, {units['angular']})",
        "tool        " + (f"{tool['current_ee'] or 'none'} {tool['ee_state']}".strip()
                           if tool else "(not reported by this server)"),
    ]
    state.out.result(data, "\n".join(lines))


@click.command()
@click.option("--events/--no-events", default=True, show_default=True,
              help="Show events and alarms.")
@click.option("--state/--no-state", "live", default=True, show_default=True,
              help="Show live state samples.")
@click.option("--rate", type=float, default=2.0, show_default=True,
              help="State samples per second.")
@click.option("--after", type=int, default=None,
              help="Replay the kept events after this sequence number first.")
@click.option("--count", type=int, default=None, help="Stop after this many lines.")
@click.option("--duration", type=float, default=None, help="Stop after this many seconds.")
@pass_state
def watch(state: CliState, events: bool, live: bool, rate: float, after: int | None,
          count: int | None, duration: float | None) -> None:
    """Follow the device's events and live state until Ctrl-C (or --count / --duration).

    With --json, one JSON document per line: {"event": ...} or {"state": ...}.
    """
    lines: queue.Queue = queue.Queue()
    with state.reader() as robot:
        streams = []
        if events:
            streams.append(("event", robot.events(after_sequence=after), event_line))
        if live:
            streams.append(("state", robot.live_state(rate_hz=rate), sample_line))
        for kind, stream, fmt in streams:
            threading.Thread(target=_pump, args=(kind, stream, fmt, lines), daemon=True).start()
        try:
            _print_lines(state, lines, len(streams), count, duration)
        finally:
            for _, stream, _ in streams:
                stream.close()


def _pump(kind, stream, fmt, lines: queue.Queue) -> None:
    try:
        for item in stream:
            lines.put((kind, item, fmt))
    except LandscapeError as error:
        lines.put((kind, error, None))
    lines.put((kind, None, None))


def _print_lines(state: CliState, lines: queue.Queue, open_streams: int, count, duration) -> None:
    deadline = None if duration is None else time.monotonic() + duration
    printed = 0
    while open_streams and (count is None or printed < count):
        timeout = None if deadline is None else deadline - time.monotonic()
        if timeout is not None and timeout <= 0:
            return
        try:
            kind, item, fmt = lines.get(timeout=timeout)
        except queue.Empty:
            return
        if item is None:
            open_streams -= 1
        elif isinstance(item, LandscapeError):
            click.echo(f"{kind} stream: {item}", err=True)   # e.g. state not built yet
        else:
            click.echo(json.dumps({kind: to_dict(item)}) if state.as_json else
                       (fmt(item) if kind == "event" else f"state {fmt(item)}"))
            printed += 1
