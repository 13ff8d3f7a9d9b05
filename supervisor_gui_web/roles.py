"""Who may send which frame: the device servers' role rule (server/auth.py), applied by the
backend to every frame of a signed-in person before anything reaches a device.

Read-only calls are a viewer's; a session, the lock and every command an operator's; the rest
of the operator panel and Reset an admin's. The e-stop is the exception that decides by what
the frame asks: pressing it is allowed to every signed-in role (anyone watching the cell may
stop it), releasing it needs an operator. Where the devices use tokens they check the same
rule with the person's own token; where they do not (loopback), this is the only check.
"""
from __future__ import annotations

from landscape.server.security.auth import Role, required_role
from landscape.v1 import control_pb2

OPERATE_PANEL = "landscape.v1.DeviceService/OperatePanel"
_ESTOP_ROLES = {control_pb2.PANEL_ACTION_PRESS_ESTOP: Role.VIEWER,
                control_pb2.PANEL_ACTION_RELEASE_ESTOP: Role.OPERATOR}

WHAT_EACH_ROLE_MAY = {
    Role.VIEWER: "a viewer watches and may press the e-stop",
    Role.OPERATOR: "an operator commands",
    Role.ADMIN: "an admin also works the operator panel and resets",
}


def needed_role(rpc_name: str, request=None) -> Role:
    """The role a call of `rpc_name` ("landscape.v1.DeviceService/Lock") needs; `request`,
    the parsed request message, decides OperatePanel's."""
    if rpc_name == OPERATE_PANEL and request is not None:
        return _ESTOP_ROLES.get(request.action, Role.ADMIN)
    return required_role("/" + rpc_name)


def refusal(rpc_name: str, needed: Role, role: Role) -> str:
    """Why a person of `role` may not make this call, in the page's words."""
    method = rpc_name.rpartition("/")[2]
    return (f"{method} needs the {needed.label} role; you are signed in as {role.label} "
            f"({WHAT_EACH_ROLE_MAY[role]})")
