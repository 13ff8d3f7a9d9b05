"""DeviceService: the LandScape server IDL (seed section 3). Thin: convert, call the device, wrap.

Every RPC is guarded by the state table (guard.py), which also decides where a body runs (the
event loop, a command thread); the ones not defined here answer UNIMPLEMENTED after the check.
"""
from __future__ import annotations

import asyncio

import numpy as np

from landscape.server.api import cell_view, convert, services
from landscape.server.device.device import Device
from landscape.server.errors import ControllerFailure, ParamError, Stopped
from landscape.server.planning.process import StreamRef
from landscape.server.api.guard import blocking, guarded, lease_of, on_loop
from landscape.server.api.read_cache import ReplyCache, by_version
from landscape.server.api.servicers.paths import PathReads
from landscape.server.api.servicers.pose_solving import PoseSolving
from landscape.server.planning.targets import Frame
from landscape.robot.units import Units, pose_matrix
from landscape.server.workcell.assembly import Workcell
from landscape.robot.arm import urdf
from landscape.v1 import (control_pb2, end_effector_pb2, motion_pb2, sensing_pb2, settings_pb2,
                          types_pb2)

JOG_END_TIMEOUT = 5.0   # s for a jogging arm to come to rest once its stream ends
# StopMotion's decelerations (issue 30): whether the stop brakes at the set limits.
STOP_DECELERATIONS = {motion_pb2.STOP_DECELERATION_FULL: False,
                      motion_pb2.STOP_DECELERATION_SET: True}

# What the cached reads' replies depend on (read_cache.py).
_SETTINGS = by_version(lambda s: (s.device.settings,))
_CYCLE = by_version(lambda s: (s.hub.cycle,))
_POSITION_AND_SETTINGS = by_version(lambda s: (s.hub.position_since(), s.device.settings))
_SCENE = by_version(lambda s: (s.device.collisions.version,))
_FIXED = by_version(lambda s: ())


@guarded(services.DEVICE)
class DeviceServicer(PathReads, PoseSolving, services.DEVICE.servicer_base):
    def __init__(self, device: Device, workcell: Workcell, hub, dispatch, limits):
        self.device, self.workcell, self.hub = device, workcell, hub
        self.dispatch, self.limits = dispatch, limits
        self.replies = ReplyCache()

    # ---- 3.1 ----
    def Lock(self, request, context):
        lease = self.device.lock(request.session_id, request.session_secret)
        return control_pb2.LockResponse(ret_val=convert.ok("locked"), lease=lease)

    def Release(self, request, context):
        self.device.release()
        return control_pb2.ReleaseResponse(ret_val=convert.ok("released"))

    def Activate(self, request, context):
        self.device.activate()
        return control_pb2.ActivateResponse(ret_val=convert.ok("drives on"))

    def Deactivate(self, request, context):
        self.device.deactivate()
        return control_pb2.DeactivateResponse(ret_val=convert.ok("drives off"))

    # ---- 3.2 ----
    @on_loop
    def SetSpeed(self, request, context):
        kind = convert.enum_value(convert.SPEED_KINDS, request.attribute, "attribute")
        value = convert.rate_to_si(kind, request.speed, self.device.settings.units)
        self.device.update_settings(lambda s: s.with_speed(kind, value))
        return settings_pb2.SetSpeedResponse(ret_val=convert.ok(convert.rate_text(
            "speed", kind, request.speed, self.device.settings.units)))

    @on_loop
    def SetAcceleration(self, request, context):
        kind = convert.enum_value(convert.ACCEL_KINDS, request.attribute, "attribute")
        value = convert.rate_to_si(kind, request.accel, self.device.settings.units)
        self.device.update_settings(lambda s: s.with_accel(kind, value))
        return settings_pb2.SetAccelerationResponse(ret_val=convert.ok(convert.rate_text(
            "acceleration", kind, request.accel, self.device.settings.units)))

    @on_loop
    def SetToolOffset(self, request, context):
        offset = convert.pose_to_matrix(request.offset, self.device.settings.units)
        self.device.update_settings(lambda s: s.with_tool_offset(offset))
        return settings_pb2.SetToolOffsetResponse(ret_val=convert.ok(convert.pose_text(
            "tool offset", request.offset, self.device.settings.units)))

    @on_loop
    def SetWorldCartesianFrame(self, request, context):
        frame = convert.pose_to_matrix(request.frame, self.device.settings.units)
        self.device.update_settings(lambda s: s.with_world_frame(frame))
        return settings_pb2.SetWorldCartesianFrameResponse(ret_val=convert.ok(convert.pose_text(
            "world frame", request.frame, self.device.settings.units)))

    @on_loop
    def SetUnits(self, request, context):
        units = convert.units_from_pb(request.linear_units, request.angular_units)
        self.device.update_settings(lambda s: s.with_units(units))
        return settings_pb2.SetUnitsResponse(ret_val=convert.ok(convert.units_text(units)))

    # ---- 3.3 ----
    @_SETTINGS
    def GetUnits(self, request, context):
        units = self.device.settings.units
        return settings_pb2.GetUnitsResponse(ret_val=convert.ok(),
                                             linear_units=convert.LINEAR_PB[units.linear],
                                             angular_units=convert.ANGULAR_PB[units.angular])

    @_SETTINGS
    def GetVelocities(self, request, context):
        s = self.device.settings
        return settings_pb2.GetVelocitiesResponse(
            ret_val=convert.ok(), percent_velocity=s.speed_percent,
            world_linear_velocity=float(s.units.length_from_si(s.linear_speed)),
            world_angular_velocity=float(s.units.angle_from_si(s.angular_speed)),
            joint_velocities=s.units.angle_from_si(s.joint_velocities).tolist(),
            units=convert.units_to_pb(s.units))

    @_SETTINGS
    def GetAccelerations(self, request, context):
        s = self.device.settings
        return settings_pb2.GetAccelerationsResponse(
            ret_val=convert.ok(), percent_accel=s.accel_percent,
            world_linear_accel=float(s.units.length_from_si(s.linear_accel)),
            world_angular_accel=float(s.units.angle_from_si(s.angular_accel)),
            joint_accels=s.units.angle_from_si(s.joint_accelerations).tolist(),
            units=convert.units_to_pb(s.units))

    @_SETTINGS
    def GetMaxVelocities(self, request, context):
        arm, units = self.device.arm, self.device.settings.units
        return settings_pb2.GetMaxVelocitiesResponse(
            ret_val=convert.ok(),
            max_world_linear_velocity=float(units.length_from_si(arm.max_linear_velocity)),
            max_world_angular_velocity=float(units.angle_from_si(arm.max_angular_velocity)),
            max_joint_velocities=units.angle_from_si(arm.max_velocity).tolist(),
            units=convert.units_to_pb(units))

    @_SETTINGS
    def GetMaxAccelerations(self, request, context):
        arm, units = self.device.arm, self.device.settings.units
        return settings_pb2.GetMaxAccelerationsResponse(
            ret_val=convert.ok(),
            max_world_linear_accel=float(units.length_from_si(arm.max_linear_acceleration)),
            max_world_angular_accel=float(units.angle_from_si(arm.max_angular_acceleration)),
            max_joint_accels=units.angle_from_si(arm.max_acceleration).tolist(),
            units=convert.units_to_pb(units))

    @_SETTINGS
    def GetToolOffsets(self, request, context):
        s = self.device.settings
        return settings_pb2.GetToolOffsetsResponse(
            ret_val=convert.ok(), offset=convert.matrix_to_pose(s.tool_offset, s.units),
            units=convert.units_to_pb(s.units))

    @_SETTINGS
    def GetWorldCartesianFrame(self, request, context):
        s = self.device.settings
        return settings_pb2.GetWorldCartesianFrameResponse(
            ret_val=convert.ok(), frame=convert.matrix_to_pose(s.world_frame, s.units),
            units=convert.units_to_pb(s.units))

    @_POSITION_AND_SETTINGS
    def GetRobotPosition(self, request, context):
        joints, world, units = self._position()
        return settings_pb2.GetRobotPositionResponse(
            ret_val=convert.ok(), joint_position=joints, world_position=world, units=units)

    def _position(self):
        """The arm now: joints, the tool tip in the world frame, their units (as sent)."""
        sample = self.device.feedback()
        units = self.device.settings.units
        world = self.hub.tool_pose(sample.sequence, sample.position, Frame.WORLD)
        return (units.angle_from_si(sample.position).tolist(),
                convert.matrix_to_pose(world, units), convert.units_to_pb(units))

    def GetMotionControlState(self, request, context):
        motion, mode = self.device.motion_control_state()
        return settings_pb2.GetMotionControlStateResponse(
            ret_val=convert.ok(), motion_control_state=motion, control_mode=mode)

    # ---- 3.4 single motions ----
    def MoveAbsolute(self, request, context):
        return motion_pb2.MoveAbsoluteResponse(ret_val=self._move("MoveAbsolute", request, False))

    def MoveRelative(self, request, context):
        return motion_pb2.MoveRelativeResponse(ret_val=self._move("MoveRelative", request, True))

    def _move(self, command: str, request, relative: bool) -> types_pb2.RetVal:
        frame = convert.enum_value(convert.FRAMES, request.frame, "frame")
        values = convert.move_values(frame, request.values, self.device.settings.units)
        command_id = self.device.motions.move(command, request.point_name, frame, values, relative,
                                      convert.motion_type(request), convert.optional_speed(request),
                                      convert.move_settings(self.device.settings, request))
        return convert.started(command_id)

    def MoveArc(self, request, context):
        units = self.device.settings.units
        frame = convert.enum_value(convert.FRAMES, request.frame, "frame")
        command_id = self.device.motions.move_arc(
            request.point_name, frame, convert.move_values(frame, request.arc_value, units),
            convert.move_values(frame, request.goal_value, units),
            convert.enum_value(convert.OFFSETS, request.offset_type, "offset_type"),
            convert.optional_speed(request))
        return motion_pb2.MoveArcResponse(ret_val=convert.started(command_id))

    # ---- 3.5 paths ----
    async def PathLoad(self, request_iterator, context):
        # The points arrive without holding anything: stops and other commands go on while a
        # long path streams in; only storing it takes the command lock. Each message is parsed
        # and kept by the planning (planning_process.py: in a process of its own beside a cycle
        # process), reached from the parsing thread, never from the event loop.
        planning, parse = self.device.path_runs.planning, self.dispatch.parse
        key = await self.dispatch.run(parse, planning.open_stream, self.device.settings.units)
        try:
            async for request in request_iterator:
                await self.dispatch.run(parse, planning.feed_stream, key, request)
            header, frame = await self.dispatch.run(parse, planning.run, "finish_stream", key)
            straight = convert.enum_value(convert.STRAIGHT, header.motion_type,
                                          "motion_type (JOINT or STRAIGHT)")
            relative = convert.enum_value(convert.OFFSETS, header.offset_type, "offset_type")
            lease = lease_of(context)

            def store():
                with self.device.command("PathLoad", lease):
                    return self.device.path_runs.path_load(header.path_name, frame, straight,
                                                           relative, StreamRef(key),
                                                           header.number_of_points or None)
            loaded, length = await self.dispatch.run(self.dispatch.commands, store)
        finally:
            planning.drop_stream(key)
        return motion_pb2.PathLoadResponse(ret_val=convert.ok(), points_loaded=loaded,
                                           path_length=length)

    def PathClearPath(self, request, context):
        self.device.path_runs.path_clear(request.path_name)
        return motion_pb2.PathClearPathResponse(
            ret_val=convert.ok(f"path {request.path_name!r} cleared"))

    def PathMove(self, request, context):
        cycles = request.number_of_cycles if request.HasField("number_of_cycles") else 1
        return motion_pb2.PathMoveResponse(
            ret_val=convert.started(self.device.path_runs.path_move(
                request.path_name, cycles, convert.move_settings(self.device.settings, request))))

    # ---- 3.6 interruptions ----
    # Stops are sent to the cycle from the event loop, at once; only the wait for the arm to
    # come to rest takes a thread (DESIGN.md 5: a stop never waits behind anything).
    async def StopMotion(self, request, context):
        motions = self.device.motions
        gentle = False
        if request.HasField("deceleration"):   # unset: the arm's full deceleration
            if request.deceleration not in STOP_DECELERATIONS:
                raise ParamError("deceleration must be STOP_DECELERATION_FULL or "
                                 f"STOP_DECELERATION_SET, got {request.deceleration}")
            gentle = STOP_DECELERATIONS[request.deceleration]
        motion = motions.request_stop(gentle)
        await self.dispatch.run(self.dispatch.immediate, motions.wait_at_rest, motion)
        return motion_pb2.StopMotionResponse(ret_val=convert.ok())

    def ResumeMotion(self, request, context):
        self.device.motions.resume_motion()
        return motion_pb2.ResumeMotionResponse(ret_val=convert.ok())

    async def AbortMotion(self, request, context):
        motions = self.device.motions
        motion = motions.request_abort()
        await self.dispatch.run(self.dispatch.immediate, motions.wait_ended, motion)
        return motion_pb2.AbortMotionResponse(ret_val=convert.ok())

    def GetTagId(self, request, context):
        path_name, tag = self.device.path_runs.last_tag
        return settings_pb2.GetTagIdResponse(ret_val=convert.ok(), path_name=path_name, tag_id=tag)

    # ---- 3.7 sensors ----
    async def GetSensorReading(self, request, context):
        # A sensor the newest cycle's row carries is read from memory, on the loop, its reply
        # built once per (cycle, settings); any other is asked of the controller on a thread.
        name, sensors = request.sensor_type, self.workcell.sensors
        kind = sensors.info(name).kind
        cycle = sensors.held_cycle(name)
        if cycle is None:
            values = await self.dispatch.run(self.dispatch.reads, sensors.reading, name)
            return self._sensor_reply(kind, values, self.device.settings.units)
        settings = self.device.settings
        return self.replies.reply(f"GetSensorReading {name}", (cycle, settings), lambda: (
            self._sensor_reply(kind, sensors.reading_at(name, cycle), settings.units)))

    @staticmethod
    def _sensor_reply(kind: str, values, units: Units) -> sensing_pb2.GetSensorReadingResponse:
        return sensing_pb2.GetSensorReadingResponse(
            ret_val=convert.ok(), current_data=convert.sensor_to_pb(kind, values, units),
            units=convert.units_to_pb(units))

    def MoveReact(self, request, context):
        units = self.device.settings.units
        kind = self.workcell.sensors.info(request.sensor_type).kind
        command_id = self.workcell.guarded.move_react(
            request.sensor_type, convert.lengths3(request.motion, units),
            convert.lengths3(request.compliance, units), request.speed, request.compliance_speed,
            convert.sensor_to_si(kind, convert.vector3(request.thresholds), units),
            convert.vector3(request.gains),
            convert.sensor_to_si(kind, convert.vector3(request.envelope_max), units))
        return sensing_pb2.MoveReactResponse(ret_val=convert.started(command_id))

    def Comply(self, request, context):
        arrays = convert.comply_arrays(request, self.device.settings.units)
        command_id = self.workcell.guarded.comply(
            request.sensor_type, max_timeout=request.max_timeout,
            panic_code=request.panic_stop_code, speed=request.speed,
            compliance_speed=request.compliance_speed,
            envelope_max=convert.vector3(request.envelope_max), **arrays)
        return sensing_pb2.ComplyResponse(ret_val=convert.started(command_id))

    def ManualControl(self, request, context):
        mode = convert.enum_value(convert.MANUAL_CONTROL, request.type, "type")
        self.workcell.manual.set_mode(mode)
        return sensing_pb2.ManualControlResponse(ret_val=convert.ok(f"manual control {mode}"))

    async def Jog(self, request_iterator, context):
        requests = aiter(request_iterator)
        first = await anext(requests, None)
        if first is None:
            return
        lease = lease_of(context)
        deadman = first.deadman_timeout_ms / 1000.0

        def start():
            with self.device.command("Jog", lease):
                return self.workcell.manual.start(deadman)
        session = await self.dispatch.run(self.dispatch.commands, start)
        request, pending = first, None
        try:
            while request is not None and not session.ended:
                frame = convert.enum_value(convert.FRAMES, request.frame, "frame")
                session.request(frame, request.velocity, request.deadman)
                joints, world, units = self._position()
                yield sensing_pb2.JogResponse(ret_val=convert.ok(session.status),
                                              joint_position=joints,
                                              world_position=world, units=units)
                pending = asyncio.ensure_future(anext(requests, None))
                while not pending.done() and not session.ended:
                    await asyncio.wait({pending}, timeout=0.01)
                request = pending.result() if pending.done() else None
        finally:
            if pending is not None:
                pending.cancel()
            session.end()
        for _ in range(round(JOG_END_TIMEOUT / 0.01)):
            if session.ended:
                break
            await asyncio.sleep(0.01)
        motion = session.motion
        why = motion.report.get("message", "")
        if motion.phase == "failed" or not session.ended:
            raise ControllerFailure(f"jogging failed: {why or 'the arm did not come to rest'}")
        if motion.phase != "done":
            raise Stopped(f"the jog session ended: {why or motion.phase}")

    # ---- 3.8 end effector ----
    @_CYCLE
    def GetEndEffectorState(self, request, context):
        tool, state = self.workcell.tools.state()
        return end_effector_pb2.GetEndEffectorStateResponse(ret_val=convert.ok(), current_ee=tool,
                                                            ee_state=state)

    def GetTool(self, request, context):
        return end_effector_pb2.GetToolResponse(
            ret_val=convert.ok(self.workcell.tools.get_tool(request.tool_id)))

    def PutTool(self, request, context):
        return end_effector_pb2.PutToolResponse(
            ret_val=convert.ok(self.workcell.tools.put_tool(request.tool_id)))

    def ActivateTool(self, request, context):
        return end_effector_pb2.ActivateToolResponse(
            ret_val=convert.ok(self.workcell.tools.activate(request.tool_id, request.bit_field)))

    def DeactivateTool(self, request, context):
        return end_effector_pb2.DeactivateToolResponse(ret_val=convert.ok(
            self.workcell.tools.deactivate(request.tool_id, request.bit_field)))

    @blocking
    def SendCommand(self, request, context):
        result = self.workcell.vendor.run(request.input, lease_of(context))
        return end_effector_pb2.SendCommandResponse(ret_val=convert.ok(), result=result)

    # ---- extensions ----
    def Reset(self, request, context):
        state = self.device.reset()
        return control_pb2.ResetResponse(ret_val=convert.ok(), state=convert.DEVICE_STATE_PB[state])

    def GetDeviceState(self, request, context):
        # The reply kept while the status is the same: the version is the status read once,
        # and the reply is built from that very status, never from a later one.
        s = self.device.status()
        version = (s.state, s.locked, s.lock_holder, s.error, s.estop, s.manual_control,
                   s.command_id)
        return self.replies.reply("GetDeviceState", version, lambda: (
            control_pb2.GetDeviceStateResponse(
                ret_val=convert.ok(), state=convert.DEVICE_STATE_PB[s.state], locked=s.locked,
                lock_holder=s.lock_holder, error=s.error, estop=s.estop,
                manual_control=s.manual_control, command_id=s.command_id)))

    @blocking(lane="panel")
    def OperatePanel(self, request, context):
        action = convert.enum_value(convert.PANEL_ACTIONS, request.action, "action")
        estop, door_open = self.device.operate_panel(action)
        return control_pb2.OperatePanelResponse(ret_val=convert.ok(action), estop_pressed=estop,
                                                door_open=door_open)

    @_SCENE
    def GetCellDescription(self, request, context):
        scene = self.device.collisions
        cell = scene.cell
        base = pose_matrix(cell.base.xyz, cell.base.rpy)
        placement = cell.placement
        world_in_cell = None if placement is None else convert.matrix_to_pose(
            pose_matrix(placement.xyz, placement.rpy) @ np.linalg.inv(base), Units())
        return control_pb2.GetCellDescriptionResponse(
            ret_val=convert.ok(), cell_name=cell.name, base=convert.matrix_to_pose(base, Units()),
            floor=cell.world.floor,
            bodies=[convert.cell_body_to_pb(body) for body in cell_view.bodies(scene)],
            world_in_cell=world_in_cell, shared_cell=cell.shared_cell)

    @_FIXED
    def GetRobotDescription(self, request, context):
        arm = self.device.arm
        return control_pb2.GetRobotDescriptionResponse(
            ret_val=convert.ok(), robot_type=arm.name, urdf=urdf(arm),
            joint_names=[f"joint_{i}" for i in range(1, 7)])
