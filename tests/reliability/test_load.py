"""Load (issue 17): 32 clients hammering reads (and trying commands of their own) and 8
subscribers, in a process of their own, while the lock holder runs a path of 1,000 tags:
the path completes, every subscriber reads every tag event in order, and no command but the
lock holder's is accepted. The lock-step clock is paced at real time, as a cell runs."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from landscape.v1 import motion_pb2, types_pb2

from support import Arm

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
TAGS = 1000


def test_a_path_of_1000_tags_under_load_reaches_every_subscriber(tmp_path):
    arm = Arm(tmp_path, pace=1.0)
    crowd = subprocess.Popen([sys.executable, str(Path(__file__).parent / "load_child.py"),
                              arm.server.target], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert crowd.stdout.readline().strip() == "ready"
        tags = [types_pb2.TagStruct(
            joint_values=[-1.0 + 2.0 * i / TAGS, 0.2 * math.sin(i / 50), 1.5708, 0, 1.5708, 0],
            transition_speed=100, tag_name=f"t{i}", tag_index=i) for i in range(TAGS)]
        header = motion_pb2.PathHeader(path_name="long", frame=JOINT,
                                       motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                       offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
        arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]),
                            timeout=60)
        command_id = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="long"),
                                         timeout=30).ret_val.command_id
        events = arm.wait_command(command_id, timeout=120)
        assert events[-1].event_id == "command_done"
        crowd.stdin.write("stop\n")
        crowd.stdin.flush()
        result = json.loads(crowd.stdout.readline())
        assert crowd.wait(30) == 0
    finally:
        crowd.kill()
        arm.close()
    expected = [f"t{i}" for i in range(TAGS)]
    print(f"{result['reads']} reads and {result['refused']} refused commands by the crowd")
    for seen in result["subscribers"]:
        assert not seen["lost"]
        assert [name for cid, name in seen["tags"] if cid == command_id] == expected
    assert result["accepted"] == []
    assert result["refused"] > 0 and result["reads"] > 0
