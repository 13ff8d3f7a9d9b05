"""Path files: a path's points (seed 3.5.1 tag_struct) in JSON or CSV, for PathLoad.

JSON: {"frame": "joint", "motion": "joint", "points": [{"values": [...], "tag_name": "a",
"time_delay": 0, "transition_speed": 0, "speed": 0, "accel": 0, "aux_commands": []}, ...]}
(or just the list of points; "frame" defaults to joint, "motion" to joint; a point needs only
"values").

CSV: a header row, then one point per row. Value columns are either j1..jN (joint frame) or
x, y, z, roll, pitch, yaw (a Cartesian frame: the file's `frame` argument, world by default).
Optional columns: tag_name, tag_index, time_delay (s), transition_speed, speed, accel (percent
of maximum) and aux_commands (separated by ";", e.g. "dout gripper_close 1").

Values are in the device's units (GetUnits).
"""
from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass
from pathlib import Path

from landscape.client.values import Frame, Motion, TagPoint

CARTESIAN = ("x", "y", "z", "roll", "pitch", "yaw")
NUMBERS = {"tag_index": int, "time_delay": float, "transition_speed": float, "speed": float,
           "accel": float}
FRAMES = {"joint": Frame.JOINT, "base": Frame.BASE, "world": Frame.WORLD}
MOTIONS = {"joint": Motion.JOINT, "straight": Motion.STRAIGHT}


class PathFileError(ValueError):
    """The file is not a path file; the message names the file and the row or point."""


@dataclass(frozen=True)
class PathFile:
    frame: Frame
    motion: Motion
    points: list[TagPoint]

    @property
    def tags(self) -> int:
        """Points with a tag name: each sends a tag-reached event when the arm gets there."""
        return sum(1 for point in self.points if point.tag_name)


def read_path(path: str | Path, frame: str | None = None, motion: str | None = None) -> PathFile:
    """Read a .json or .csv path file; `frame` / `motion` override (or supply) the file's."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise PathFileError(f"{path}: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise PathFileError(f"{path}: not UTF-8 text (byte {error.start})") from None
    if path.suffix.lower() == ".csv":
        points, found_frame = _csv_points(path, text)
        found_motion = None
    else:
        points, found_frame, found_motion = _json_points(path, text)
    chosen_frame = _choose(FRAMES, frame or found_frame or "joint", "frame", path)
    chosen_motion = _choose(MOTIONS, motion or found_motion or "joint", "motion", path)
    if not points:
        raise PathFileError(f"{path}: no points")
    return PathFile(chosen_frame, chosen_motion, points)


def write_path(path: str | Path, frame: str, motion: str, points: list[TagPoint]) -> None:
    """Write a JSON path file that read_path reads back."""
    data = {"frame": frame, "motion": motion,
            "points": [{**asdict(p), "values": list(p.values), "aux_commands": list(p.aux_commands)}
                       for p in points]}
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def _choose(table: dict, name: str, what: str, path: Path):
    try:
        return table[name.lower()]
    except KeyError:
        raise PathFileError(f"{path}: {what} must be one of {', '.join(table)}, "
                            f"got {name!r}") from None


def _json_points(path: Path, text: str):
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise PathFileError(f"{path}: not JSON: {error}") from None
    if isinstance(data, list):
        data = {"points": data}
    if not isinstance(data, dict) or not isinstance(data.get("points", []), list):
        raise PathFileError(f"{path}: expected an object with a list of points, or that list")
    for key in ("frame", "motion"):
        if not isinstance(data.get(key, ""), str):
            raise PathFileError(f"{path}: {key} must be a name, got {data[key]!r}")
    points = []
    for number, item in enumerate(data.get("points", []), 1):
        try:
            fields = {k: v for k, v in item.items() if k in TagPoint.__dataclass_fields__}
            points.append(TagPoint(**{**fields, "values": [float(v) for v in item["values"]]}))
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as error:
            raise PathFileError(f"{path}: point {number}: {error!r}") from None
    return points, data.get("frame"), data.get("motion")


def _csv_points(path: Path, text: str):
    rows = list(csv.DictReader(text.splitlines()))
    columns = rows[0].keys() if rows else ()
    joints = sorted((c for c in columns if c and c[0] == "j" and c[1:].isdigit()),
                    key=lambda c: int(c[1:]))
    if joints:
        value_columns, frame = joints, "joint"
    elif set(CARTESIAN) <= set(columns):
        value_columns, frame = list(CARTESIAN), None
    else:
        raise PathFileError(f"{path}: the header needs j1..jN or x,y,z,roll,pitch,yaw columns")
    points = []
    for number, row in enumerate(rows, 2):
        try:
            extra = {k: NUMBERS[k](row[k]) for k in NUMBERS if row.get(k)}
            aux = tuple(c.strip() for c in (row.get("aux_commands") or "").split(";") if c.strip())
            points.append(TagPoint([float(row[c]) for c in value_columns],
                                   tag_name=row.get("tag_name") or "", aux_commands=aux, **extra))
        except (TypeError, ValueError) as error:
            raise PathFileError(f"{path}: row {number}: {error}") from None
    return points, frame
