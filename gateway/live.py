"""The device's live state as CRCL reads it: a sample of the client core's state feed
(landscape.client.state_feed: one StateService.StreamState per gateway, in the robot's base
frame, m and rad) as SI numpy arrays. Base, not the device's world: CRCL's workstation frame is
each session's own (workstation.py), whatever any client set SetWorldCartesianFrame to.

GetStatus is answered from the newest sample, never by a round trip per poll; while the stream
is down, status says why and how old its last sample is, and motions fail rather than judge
their end on it. Each sample is converted once, however many connections poll it.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from landscape.client.state_feed import Sample
from landscape.gateway.device_units import DeviceUnits

@dataclass(frozen=True, eq=False)
class LiveState:
    """One sample of the device, SI: joints rad (6,), rad/s (6,), N*m (6,) or empty; the tool
    tip in the base frame as x, y, z (m), roll, pitch, yaw (rad). Each sample is its own
    (compared and hashed by identity: status.py keeps what it made of the newest ones)."""

    sequence: int
    joint_positions: np.ndarray
    tool_pose: np.ndarray
    device_state: int                     # types_pb2.DeviceState
    joint_velocities: np.ndarray = field(default_factory=lambda: np.zeros(0))
    joint_torques: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command_id: str = ""
    end_effector: str = ""
    end_effector_state: str = ""
    sensors: dict[str, tuple[float, ...]] = field(default_factory=dict)
    received: float = 0.0                 # time.monotonic() when it arrived
    time: float = 0.0                     # unix s of the controller cycle it was taken in


@functools.lru_cache(maxsize=8)
def live_state(arrived: Sample) -> LiveState:
    """The sample in SI (the same object for the same sample: status.py keeps what it made of
    the newest ones)."""
    sample = arrived.message
    units = DeviceUnits.of(sample.units)
    return LiveState(
        sequence=sample.sequence,
        joint_positions=np.asarray(sample.joint_positions, dtype=float) * units.radians,
        tool_pose=np.array(units.pb_pose_si(sample.tool_pose)),
        device_state=sample.device_state,
        joint_velocities=np.asarray(sample.joint_velocities) * units.radians,
        joint_torques=np.asarray(sample.joint_torques),
        command_id=sample.command_id, end_effector=sample.end_effector,
        end_effector_state=sample.end_effector_state,
        sensors={s.name: tuple(s.values) for s in sample.sensors}, received=arrived.received,
        time=arrived.time)
