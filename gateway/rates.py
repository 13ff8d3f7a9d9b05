"""CRCL speeds and accelerations as the device's motion settings.

The device (seed 3.2.1) holds the tool tip to the arm's Cartesian maximum times one percent
(speed, and acceleration), each also capped by an absolute setting that the percent does not
scale; the joints get the same percent of their maxima. So:
- TransSpeed v and TransAccel a are percents, 100 v / v_max and 100 a / a_max, with the linear
  caps at the maxima: straight moves get v and a exactly, joint moves the same share of the
  joints' maxima (a path's points may carry percents of their own);
- RotSpeed w and RotAccel alpha are the angular caps. The percent still scales the angular
  maximum, so rotation may come out slower than asked, never faster (spec V allows less).

A motion carries its rates in its own request (move_rates: the session's, with the command's
own from a PoseAndSetType or a waypoint): no setting of the device changes, and a MoveTo is one
call. The device's guarded move (MoveReact) and its tool changes (GetTool, PutTool) take the
device's settings: RatesFor sets the session's there just before (only those that changed
since last sent), and the session's end puts the device's own back (device.py). A Set*Speed /
Set*Accel is no device round trip.
"""
from __future__ import annotations

import asyncio

from landscape.gateway import model as m
from landscape.gateway.settings import SiRate, rate_si
from landscape.v1 import motion_pb2, types_pb2

MIN_PERCENT = 0.1            # the device needs a percent above 0
PERCENT_SPEED = ("SetSpeed", types_pb2.SPEED_TYPE_PERCENT_SPEED)
LINEAR_SPEED = ("SetSpeed", types_pb2.SPEED_TYPE_LINEAR_SPEED)
ANGULAR_SPEED = ("SetSpeed", types_pb2.SPEED_TYPE_ANGULAR_SPEED)
PERCENT_ACCEL = ("SetAcceleration", types_pb2.ACCEL_TYPE_PERCENT_ACCEL)
LINEAR_ACCEL = ("SetAcceleration", types_pb2.ACCEL_TYPE_LINEAR_ACCEL)
ANGULAR_ACCEL = ("SetAcceleration", types_pb2.ACCEL_TYPE_ANGULAR_ACCEL)


def percent(value: float, maximum: float) -> float:
    return min(100.0, max(MIN_PERCENT, 100.0 * value / maximum))


def speed_percent(session, rate: SiRate | None = None) -> float:
    v_max = session.control.limits.linear_speed
    return percent((rate or session.settings.trans_speed).value(v_max), v_max)


def accel_percent(session, rate: SiRate | None = None) -> float:
    a_max = session.control.limits.linear_accel
    return percent((rate or session.settings.trans_accel).value(a_max), a_max)


def rot_speed(session, rate: SiRate | None = None) -> float:
    return (rate or session.settings.rot_speed).value(session.control.limits.angular_speed)


def rot_accel(session, rate: SiRate | None = None) -> float:
    return (rate or session.settings.rot_accel).value(session.control.limits.angular_accel)


def session_rates(session) -> dict[tuple[str, int], float]:
    """The device settings that carry the session's rates (SI, or percent)."""
    limits = session.control.limits
    return {PERCENT_SPEED: speed_percent(session),
            LINEAR_SPEED: limits.linear_speed,
            ANGULAR_SPEED: rot_speed(session),
            PERCENT_ACCEL: accel_percent(session),
            LINEAR_ACCEL: limits.linear_accel,
            ANGULAR_ACCEL: rot_accel(session)}


async def push(session, wanted: dict[tuple[str, int], float]) -> None:
    """These device settings, each sent only if it differs from what was sent last (the
    session's Control puts them back as they were when the session ends)."""
    for rate, value in wanted.items():
        await session.control.set_rate(rate, value)


async def push_rates(session) -> None:
    """The session's speeds and accelerations, on the device."""
    await push(session, session_rates(session))


class RatesFor:
    """The device's settings for one command's motion: the session's rates with the
    command's own, set before it starts; the session's own put back once it has started."""

    def __init__(self, session, overrides: dict[tuple[str, int], float]):
        self.session, self.overrides = session, overrides

    async def __aenter__(self):
        await push(self.session, {**session_rates(self.session), **self.overrides})

    async def __aexit__(self, *exc):
        if self.overrides:
            await asyncio.shield(push_rates(self.session))


def move_rates(session, overrides: dict[tuple[str, int], float] | None = None
               ) -> motion_pb2.MoveRates:
    """A motion's own MoveRates: the session's rates with `overrides` (motion_rates'), in the
    device's units. The speed percent goes in the request's speed (or a path point's)."""
    wanted = {**session_rates(session), **(overrides or {})}
    units = session.control.units
    return motion_pb2.MoveRates(
        accel_percent=wanted[PERCENT_ACCEL], linear_speed=units.length(wanted[LINEAR_SPEED]),
        angular_speed=units.angle(wanted[ANGULAR_SPEED]),
        linear_accel=units.length(wanted[LINEAR_ACCEL]),
        angular_accel=units.angle(wanted[ANGULAR_ACCEL]))


def pose_rates(session, pose: m.Pose) -> tuple[SiRate | None, ...]:
    """(TransSpeed, RotSpeed, TransAccel, RotAccel) a PoseAndSetType asks for, in SI, each None
    where it asks for none."""
    settings, units = pose.settings, session.settings.units
    if settings is None:
        return None, None, None, None
    length, angle = units.length_si(1.0), units.angle_si(1.0)
    return tuple(None if rate is None else rate_si(rate, scale) for rate, scale in (
        (settings.trans_speed, length), (settings.rot_speed, angle),
        (settings.trans_accel, length), (settings.rot_accel, angle)))


def motion_rates(session, poses: list[m.Pose]) -> tuple[list[tuple[float | None, float | None]],
                                                       dict[tuple[str, int], float]]:
    """For a motion through `poses`: each pose's (speed percent, accel percent) or None each,
    and the device settings that differ from the session's for the whole motion: the angular
    caps are the lowest any pose asks for (the session's where it asks none), so no segment
    turns faster than its pose allows."""
    percents, w, alpha = [], [rot_speed(session)], [rot_accel(session)]
    for pose in poses:
        trans_speed, rot_s, trans_accel, rot_a = pose_rates(session, pose)
        percents.append((None if trans_speed is None else speed_percent(session, trans_speed),
                         None if trans_accel is None else accel_percent(session, trans_accel)))
        if rot_s is not None:
            w.append(rot_speed(session, rot_s))
        if rot_a is not None:
            alpha.append(rot_accel(session, rot_a))
    overrides = {}
    if min(w) != rot_speed(session):
        overrides[ANGULAR_SPEED] = min(w)
    if min(alpha) != rot_accel(session):
        overrides[ANGULAR_ACCEL] = min(alpha)
    return percents, overrides
