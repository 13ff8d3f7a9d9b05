"""Writes the seed corpora of the fuzz targets (tests/fuzz/corpus/), from the project's own
documents and path files (NIST's examples are never copied in). Inputs the fuzzers found and
kept worth having are added beside them by hand, under their libFuzzer names.

    python tests/fuzz/make_corpus.py
"""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "gateway"))
from crcl_support import command, pose, program, reachable_program  # noqa: E402
from test_gateway import IMMEDIATE_SAMPLES  # noqa: E402


def crcl_seeds() -> list[bytes]:
    move = "<MoveStraight>true</MoveStraight>"
    seeds = [command(kind, i, body) for i, (kind, body) in enumerate(IMMEDIATE_SAMPLES.items())]
    seeds += [
        command("InitCanon", 1), command("EndCanon", 2), command("GetStatus", 3),
        command("MoveTo", 4, move + pose(0.5, 0.1, 0.6)),
        command("MoveTo", 5, move + pose(0.5, 0.1, 0.6).replace(
            "<EndPosition>", '<EndPosition xsi:type="PoseAndSetType">').replace(
            "</EndPosition>", "<Coordinated>true</Coordinated><Tolerance><XPointTolerance>0.001"
                              "</XPointTolerance></Tolerance></EndPosition>")),
        command("MoveThroughTo", 6, move + pose(0.5, 0, 0.5, tag="Waypoint") +
                pose(0.5, 0.1, 0.5, tag="Waypoint") + "<NumPositions>2</NumPositions>"),
        command("MoveScrew", 7, pose(0.5, 0, 0.6, tag="StartPosition") + "<AxisPoint><X>0.5</X>"
                "<Y>0</Y><Z>0.6</Z></AxisPoint><AxialDistanceFree>0.01</AxialDistanceFree>"
                "<AxialDistanceScrew>0.01</AxialDistanceScrew><Turn>1.5</Turn>"),
        command("ActuateJoints", 8, '<ActuateJoint><JointNumber>1</JointNumber><JointPosition>0.1'
                '</JointPosition><JointDetails xsi:type="JointSpeedAccelType"><JointSpeed>0.5'
                "</JointSpeed></JointDetails></ActuateJoint>"),
        command("StopMotion", 9, "<StopCondition>Immediate</StopCondition>"),
        command("Message", 10, "<Message>hello</Message>"),
        command("EnableSensor", 11, "<SensorID>force_sensor</SensorID>"),
        command("SetEndEffector", 12, "<Setting>0.5</Setting>"),
        command("RunProgram", 13, "<ProgramText>version</ProgramText>"),
        command("SetRobotParameters", 14, "<ParameterSetting><ParameterName>ToolOffset"
                "</ParameterName><ParameterValue>0 0 0.1 0 0 0</ParameterValue>"
                "</ParameterSetting>"),
        reachable_program(),
        program([("LoopBlockStart", "<LoopName>a</LoopName>"),
                 ("Dwell", "<DwellTime>0</DwellTime>"),
                 ("LoopBlockEnd", "<LoopName>a</LoopName><MaxCount>3</MaxCount>")]),
        command("GetStatus", 15) + b"\n " + command("GetStatus", 16),
    ]
    return seeds


def pathfile_seeds() -> list[bytes]:
    json_points = {"frame": "world", "motion": "straight", "points": [
        {"values": [0.5, 0.1, 0.6, 3.14, 0, 0], "tag_name": "a", "speed": 20},
        {"values": [0.5, -0.1, 0.6, 3.14, 0, 0], "transition_speed": 10,
         "aux_commands": ["dout gripper_close 1"]}]}
    return [
        b"\x00" + json.dumps(json_points).encode(),
        b"\x00" + json.dumps([{"values": [0, 0, 1.57, 0, 1.57, 0]}]).encode(),
        b"\x01tag_name,j1,j2,j3,j4,j5,j6\na,0,0,90,0,90,0\nb,10,0,90,0,90,0\n",
        b"\x01x,y,z,roll,pitch,yaw,speed,time_delay,aux_commands\n"
        b"0.5,0.1,0.6,180,0,0,20,0.5,dout lamp_green 1;dout lamp_red 0\n",
    ]


def write(folder: Path, seeds: list[bytes]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        (folder / f"seed-{hashlib.sha1(seed).hexdigest()[:12]}").write_bytes(seed)


if __name__ == "__main__":
    write(HERE / "corpus" / "crcl", crcl_seeds())
    write(HERE / "corpus" / "pathfile", pathfile_seeds())
