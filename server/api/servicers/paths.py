"""DeviceService's stored paths read back (ListPaths, GetPath): what PathLoad stored, as the
device keeps it (points resolved to joints), in the device's units.

A mixin of DeviceServicer (device.py): the guard finds these bodies through it.
"""
from __future__ import annotations

from landscape.robot.units import Units
from landscape.server.api import convert
from landscape.server.errors import NotFound
from landscape.server.planning.paths import PathPoint, StoredPath
from landscape.v1 import stored_paths_pb2, types_pb2

CHUNK = 1000    # points a GetPath message carries: a 100,000-point path is 100 messages
_MOTION = {False: types_pb2.MOTION_TYPE_JOINT_MOTION, True: types_pb2.MOTION_TYPE_STRAIGHT_MOTION}


class PathReads:
    """ListPaths and GetPath; `self.device` and `self.dispatch` are DeviceServicer's."""

    def ListPaths(self, request, context):
        paths, unreadable = self.device.path_runs.paths.snapshot()
        units = self.device.settings.units
        return stored_paths_pb2.ListPathsResponse(
            ret_val=convert.ok(f"{len(paths)} paths"),
            paths=[summary(paths[name], units) for name in sorted(paths)],
            unreadable=unreadable, units=convert.units_to_pb(units))

    async def GetPath(self, request, context):
        paths, _ = self.device.path_runs.paths.snapshot()
        path = paths.get(request.path_name)
        if path is None:
            raise NotFound(f"no path named {request.path_name!r}")
        units = self.device.settings.units
        for first in range(0, max(len(path.points), 1), CHUNK):
            # Off the event loop: 1000 points take a few milliseconds to convert.
            yield await self.dispatch.run(self.dispatch.reads, chunk, path, first, units)


def summary(path: StoredPath, units: Units) -> stored_paths_pb2.PathSummary:
    return stored_paths_pb2.PathSummary(
        name=path.name, motion_type=_MOTION[path.straight], number_of_points=len(path.points),
        number_of_tags=sum(1 for p in path.points if p.tag_name),
        tool_offset=convert.matrix_to_pose(path.tcp_matrix, units))


def chunk(path: StoredPath, first: int, units: Units) -> stored_paths_pb2.GetPathResponse:
    """The message of `path`'s points from `first` (the first message: with the summary)."""
    return stored_paths_pb2.GetPathResponse(
        ret_val=convert.ok(), path=summary(path, units) if first == 0 else None,
        first_point=first, units=convert.units_to_pb(units),
        points=[_point(p, units) for p in path.points[first:first + CHUNK]])


def _point(point: PathPoint, units: Units) -> types_pb2.TagStruct:
    return types_pb2.TagStruct(
        joint_values=units.angle_from_si(point.joints).tolist(), tag_name=point.tag_name,
        tag_index=point.tag_index, time_delay=point.time_delay,
        transition_speed=point.transition_speed, speed=point.speed, accel=point.accel,
        aux_commands=point.aux_commands)
