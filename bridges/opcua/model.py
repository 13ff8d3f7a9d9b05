"""A cell's arms as OPC 40010-1 (OPC UA for Robotics, "Vertical Integration", release 1.01)
models a motion device system, built in code from the specification's published facts: its
browse names, the NodeIds of its types in the Robotics namespace, and UNECE units. The
companion specification's NodeSet is not loaded (neither is OPC 10000-100's, Devices, whose
ParameterSet and identification properties the Robotics types use): the types are declared
here, with their published NodeIds, as subtypes of BaseObjectType, and each instance carries
the components a client reads. Sections cited are the specification's.

    Objects/DeviceSet (DI)
      <cell>                      MotionDeviceSystemType (7.1)
        MotionDevices/<arm>       MotionDeviceType (7.2): DI Manufacturer, Model,
                                  MotionDeviceCategory (10.1: ARTICULATED_ROBOT)
          Axes/joint_1..6         AxisType (7.3): MotionProfile (10.2: ROTARY),
                                  DI ParameterSet: ActualPosition (rad), ActualSpeed (rad/s),
                                  AnalogUnitType with EngineeringUnits
          LandScape               the device's state, lock holder and running command
                                  (our namespace: not the specification's)
        Controllers/<arm>_controller   ControllerType (7.18): DI Manufacturer, Model
        SafetyStates/<arm>_safety      SafetyStateType (7.7): DI ParameterSet:
                                       OperationalMode, EmergencyStop, ProtectiveStop
"""
from __future__ import annotations

from dataclasses import dataclass, field

from asyncua import Node, Server, ua

ROBOTICS = "http://opcfoundation.org/UA/Robotics/"
DI = "http://opcfoundation.org/UA/DI/"
LANDSCAPE = "urn:landscape-grpc:cell"
UNITS = "http://www.opcfoundation.org/UA/units/un/cefact"

# The Robotics namespace's published NodeIds of the types used here.
TYPES = {"MotionDeviceSystemType": 1002, "ControllerType": 1003, "MotionDeviceType": 1004,
         "SafetyStateType": 1013, "AxisType": 16601}
ENUMS = {  # published NodeId, members (section 10)
    "MotionDeviceCategoryEnumeration": (18193, ("OTHER", "ARTICULATED_ROBOT", "SCARA_ROBOT",
                                                "CARTESIAN_ROBOT", "SPHERICAL_ROBOT",
                                                "PARALLEL_ROBOT", "CYLINDRICAL_ROBOT")),
    "AxisMotionProfileEnumeration": (3008, ("OTHER", "ROTARY", "ROTARY_ENDLESS", "LINEAR",
                                            "LINEAR_ENDLESS")),
    "OperationalModeEnumeration": (3006, ("OTHER", "MANUAL_REDUCED_SPEED", "MANUAL_HIGH_SPEED",
                                          "AUTOMATIC", "AUTOMATIC_EXTERNAL")),
}
ARTICULATED_ROBOT, ROTARY = 1, 1
MANUAL_REDUCED_SPEED, AUTOMATIC_EXTERNAL = 1, 4


def unece(code: str) -> int:
    """A UNECE Recommendation 20 code as OPC UA's UnitId (OPC 10000-8): its ASCII bytes."""
    value = 0
    for char in code:
        value = value << 8 | ord(char)
    return value


RADIAN = ua.EUInformation(NamespaceUri=UNITS, UnitId=unece("C81"),
                          DisplayName=ua.LocalizedText("rad"),
                          Description=ua.LocalizedText("radian"))
RADIAN_PER_SECOND = ua.EUInformation(NamespaceUri=UNITS, UnitId=unece("2A"),
                                     DisplayName=ua.LocalizedText("rad/s"),
                                     Description=ua.LocalizedText("radian per second"))


@dataclass
class ArmNodes:
    """The variables one arm's feed writes."""

    positions: list[Node] = field(default_factory=list)
    speeds: list[Node] = field(default_factory=list)
    emergency_stop: Node | None = None
    protective_stop: Node | None = None
    operational_mode: Node | None = None
    device_state: Node | None = None
    lock_holder: Node | None = None
    command_id: Node | None = None
    connected: Node | None = None


class RoboticsModel:
    """The address space of one cell; `add_arm` for each device, after `build`."""

    def __init__(self, server: Server, cell: str):
        self.server, self.cell = server, cell

    async def build(self) -> None:
        server = self.server
        self.rob = await server.register_namespace(ROBOTICS)
        self.di = await server.register_namespace(DI)
        self.own = await server.register_namespace(LANDSCAPE)
        base = server.nodes.base_object_type
        self.types = {name: (await base.add_object_type(ua.NodeId(number, self.rob), name)).nodeid
                      for name, number in TYPES.items()}
        self.enums = {}
        for name, (number, members) in ENUMS.items():
            node = await server.nodes.enum_data_type.add_data_type(ua.NodeId(number, self.rob),
                                                                   name)
            await node.add_property(0, "EnumStrings",
                                    [ua.LocalizedText(member) for member in members])
            self.enums[name] = node.nodeid
        device_set = await server.nodes.objects.add_folder(ua.NodeId("DeviceSet", self.di),
                                                            ua.QualifiedName("DeviceSet", self.di))
        system = await device_set.add_object(
            ua.NodeId(self.cell, self.own), ua.QualifiedName(self.cell, self.own),
            objecttype=self.types["MotionDeviceSystemType"], instantiate_optional=False)
        self.folders = {name: await system.add_folder(ua.NodeId(f"{self.cell}/{name}", self.own),
                                                      ua.QualifiedName(name, self.rob))
                        for name in ("MotionDevices", "Controllers", "SafetyStates")}

    async def add_arm(self, name: str, model: str, joints: tuple[str, ...]) -> ArmNodes:
        nodes = ArmNodes()
        device = await self._object(self.folders["MotionDevices"], name, "MotionDeviceType")
        await self._identify(device, name, model)
        await self._enum(device, f"{name}/MotionDeviceCategory", "MotionDeviceCategory",
                         "MotionDeviceCategoryEnumeration", ARTICULATED_ROBOT)
        axes = await device.add_folder(ua.NodeId(f"{name}/Axes", self.own),
                                       ua.QualifiedName("Axes", self.rob))
        for joint in joints:
            axis = await self._object(axes, f"{name}/{joint}", "AxisType", joint)
            await self._enum(axis, f"{name}/{joint}/MotionProfile", "MotionProfile",
                             "AxisMotionProfileEnumeration", ROTARY)
            parameters = await self._parameter_set(axis, f"{name}/{joint}")
            nodes.positions.append(await self._analog(parameters, f"{name}/{joint}",
                                                      "ActualPosition", RADIAN))
            nodes.speeds.append(await self._analog(parameters, f"{name}/{joint}",
                                                   "ActualSpeed", RADIAN_PER_SECOND))
        controller = await self._object(self.folders["Controllers"], f"{name}_controller",
                                        "ControllerType")
        await self._identify(controller, name, "CS8 (simulated)")
        safety = await self._object(self.folders["SafetyStates"], f"{name}_safety",
                                    "SafetyStateType")
        parameters = await self._parameter_set(safety, f"{name}_safety")
        nodes.operational_mode = await self._enum(
            parameters, f"{name}_safety/OperationalMode", "OperationalMode",
            "OperationalModeEnumeration", AUTOMATIC_EXTERNAL, variable=True)
        nodes.emergency_stop = await self._variable(parameters, f"{name}_safety/EmergencyStop",
                                                    ua.QualifiedName("EmergencyStop", self.rob),
                                                    False, ua.VariantType.Boolean)
        nodes.protective_stop = await self._variable(
            parameters, f"{name}_safety/ProtectiveStop",
            ua.QualifiedName("ProtectiveStop", self.rob), False, ua.VariantType.Boolean)
        own = await device.add_object(ua.NodeId(f"{name}/LandScape", self.own),
                                      ua.QualifiedName("LandScape", self.own))
        for key, value, kind in (("DeviceState", "", ua.VariantType.String),
                                 ("LockHolder", "", ua.VariantType.String),
                                 ("CommandId", "", ua.VariantType.String),
                                 ("Connected", False, ua.VariantType.Boolean)):
            variable = await self._variable(own, f"{name}/LandScape/{key}",
                                            ua.QualifiedName(key, self.own), value, kind)
            setattr(nodes, {"DeviceState": "device_state", "LockHolder": "lock_holder",
                            "CommandId": "command_id", "Connected": "connected"}[key], variable)
        return nodes

    # ---- building blocks

    async def _object(self, parent: Node, key: str, type_name: str, browse: str | None = None):
        return await parent.add_object(ua.NodeId(key, self.own),
                                       ua.QualifiedName(browse or key.rsplit("/", 1)[-1],
                                                        self.own),
                                       objecttype=self.types[type_name],
                                       instantiate_optional=False)

    async def _identify(self, node: Node, key: str, model: str) -> None:
        """The identification properties the Robotics types take from DI (OPC 10000-100)."""
        for name, value in (("Manufacturer", "Staubli (simulated by LandScape-gRPC)"),
                            ("Model", model)):
            await node.add_property(ua.NodeId(f"{node.nodeid.Identifier}/{name}", self.own),
                                    ua.QualifiedName(name, self.di), ua.LocalizedText(value))

    async def _parameter_set(self, node: Node, key: str) -> Node:
        return await node.add_object(ua.NodeId(f"{key}/ParameterSet", self.own),
                                     ua.QualifiedName("ParameterSet", self.di))

    async def _variable(self, parent: Node, key: str, browse, value, kind) -> Node:
        """A read-only variable (no write access: a client's write is refused)."""
        return await parent.add_variable(ua.NodeId(key, self.own), browse,
                                         ua.Variant(value, kind))

    async def _analog(self, parent: Node, key: str, name: str, unit) -> Node:
        """An AnalogUnitType Double with its EngineeringUnits."""
        variable = await self._variable(parent, f"{key}/{name}", ua.QualifiedName(name, self.rob),
                                        0.0, ua.VariantType.Double)
        await variable.delete_reference(ua.NodeId(ua.ObjectIds.BaseDataVariableType),
                                        ua.ObjectIds.HasTypeDefinition)
        await variable.add_reference(ua.NodeId(ua.ObjectIds.AnalogUnitType),
                                     ua.ObjectIds.HasTypeDefinition)
        await variable.add_property(ua.NodeId(f"{key}/{name}/EngineeringUnits", self.own),
                                    ua.QualifiedName("EngineeringUnits", 0), unit)
        return variable

    async def _enum(self, parent: Node, key: str, name: str, enum: str, value: int, *,
                    variable: bool = False) -> Node:
        """A property (or a variable) of one of the specification's enumerations."""
        browse = ua.QualifiedName(name, self.rob)
        if variable:
            node = await parent.add_variable(ua.NodeId(key, self.own), browse,
                                             ua.Variant(value, ua.VariantType.Int32),
                                             datatype=self.enums[enum])
        else:
            node = await parent.add_property(ua.NodeId(key, self.own), browse,
                                             ua.Variant(value, ua.VariantType.Int32),
                                             datatype=self.enums[enum])
        return node
