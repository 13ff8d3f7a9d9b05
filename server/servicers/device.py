"""DeviceService: the LandScape server IDL (seed section 3). Thin: convert, call the device, wrap."""
from __future__ import annotations

from landscape.server import services
from landscape.server.servicers.unimplemented import complete
from landscape.sim.arm import arm_model, urdf
from landscape.v1 import control_pb2, types_pb2


class DeviceServicer(services.DEVICE.servicer_base):
    def __init__(self, arm=None):
        self._arm = arm or arm_model()

    def GetRobotDescription(self, request, context):
        return control_pb2.GetRobotDescriptionResponse(
            ret_val=types_pb2.RetVal(ret_code=types_pb2.RETURN_CODE_CMD_EXEC_OK),
            robot_type=self._arm.name,
            urdf=urdf(self._arm),
            joint_names=[f"joint_{i}" for i in range(1, 7)],
        )


complete(DeviceServicer, services.DEVICE)
