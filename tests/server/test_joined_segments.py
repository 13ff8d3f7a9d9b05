"""A run timed as it plays (issue 31 item 4) grows its playing segment by parts
(run_arrays.GrowingSegments); the play steps across them (joined_rows.JoinedRows) rather than
copying the whole segment on the cycle at every part, and plays exactly what the joined
segment would."""
from __future__ import annotations

import numpy as np

from landscape.robot.arm import arm_model
from landscape.server.cycle.playback import Motion
from landscape.server.cycle.run_arrays import GrowingSegments, Segments, pack_run
from landscape.server.cycle.shared_array import SharedArrays
from landscape.server.planning.motion.timing import time_path
from landscape.server.planning.motion.trajectory import Limits

DT = 0.004
LIMITS = Limits.scaled(arm_model(), 80, 80)
WAYPOINTS = np.array([[0, 0, 1.5708, 0, 1.5708, 0], [0.6, 0.3, 1.3, 0.7, 1.2, 0.5],
                      [1.4, -0.3, 1.8, -0.6, 1.6, 1.2], [2.2, 0.1, 1.1, 0.3, 0.9, 0.2]])


class Piece:
    """Rows of a timed trajectory, as pack_run takes them (marks: (sample, label) rows)."""

    def __init__(self, positions, velocities, marks=()):
        self.positions, self.velocities, self.marks = positions, velocities, list(marks)

    def __len__(self) -> int:
        return len(self.positions)


def pieces(cuts):
    """The trajectory through WAYPOINTS cut at rows `cuts`, each piece with a mark at its
    third row (labelled by its first row)."""
    trajectory = time_path(WAYPOINTS, LIMITS, DT)
    edges = [0, *cuts, len(trajectory)]
    return trajectory, [Piece(trajectory.positions[a:b], trajectory.velocities[a:b], [(2, a)])
                        for a, b in zip(edges, edges[1:])]


def test_a_continued_segment_is_read_across_its_parts_as_one():
    trajectory, parts = pieces([7, 90, 91, 200])
    blocks = [pack_run([p], DT) for p in parts]
    segments = GrowingSegments(Segments(blocks[0]))
    for block in blocks[1:3]:
        segments.append(Segments(block), continues=True)
    segment = segments[0]
    for block in blocks[3:]:   # later parts grow the segment already read
        segments.append(Segments(block), continues=True)
    assert len(segments) == 1
    rows = segment["positions"]
    whole = trajectory.positions
    assert len(rows) == len(whole)
    assert all(np.array_equal(rows[k], whole[k]) for k in range(-len(whole), len(whole)))
    for a, b in [(0, 7), (5, 9), (6, 95), (89, 92), (0, len(whole)), (150, 400)]:
        assert np.array_equal(rows[a:b], whole[a:b])
    index = np.array([0, 6, 7, 90, 91, 92, 199, 200, len(whole) - 1])
    assert np.array_equal(rows[index], whole[index])
    assert np.array_equal(rows[list(index)], whole[index])
    assert np.array_equal(rows[5:95, 2], whole[5:95, 2])
    joint = rows[:, 3:4]
    assert np.array_equal(joint[index], whole[index, 3:4])
    assert segment["marks"] == [(a + 2, a) for a in (0, 7, 90, 91, 200)]
    # Read in place, not copied: a row is the part's own memory.
    for block, first in zip(blocks, (0, 7, 90, 91, 200)):
        assert np.shares_memory(rows[first], block["positions"])


def play(m: Motion, commands: dict, cycles: int, grow=None) -> np.ndarray:
    """The positions commanded cycle by cycle (as Executor._play does for a plain motion);
    commands: cycle -> "stop" or "resume"; grow(cycle, motion) may append parts."""
    out = []
    for cycle in range(cycles):
        if grow is not None:
            grow(cycle, m)
        what = commands.get(cycle)
        if what == "stop":
            m.stop()
        elif what == "resume":
            m.resume()
        m.advance()
        out.append(m.position().copy())
        if m.s >= m.last and not m.next_segment():
            break
    return np.array(out)


def motion(arrays) -> Motion:
    return Motion({"id": "m", "acceleration": LIMITS.acceleration, "jerk": LIMITS.jerk,
                   "segments": Segments(arrays)}, DT)


def test_the_play_across_parts_is_the_play_of_the_joined_segment():
    """Parts appended before and while the play runs, a stop and a resume across their
    joints: the same commanded positions as one segment of the whole trajectory."""
    cuts = [40, 41, 120, 180, 230]
    trajectory, parts = pieces(cuts)
    commands = {100: "stop", 150: "resume", 215: "stop", 260: "resume"}
    whole = play(motion(pack_run([Piece(trajectory.positions, trajectory.velocities)], DT)),
                 commands, 5000)

    later = [SharedArrays.create(pack_run([p], DT), shared=False) for p in parts[1:]]

    def grow(cycle, m):
        if cycle in (0, 1, 30, 60, 170) and later:   # ahead of the play, in time for it
            m.append(later.pop(0), True, 0, 0, True)

    joined = play(motion(pack_run([parts[0]], DT)), commands, 5000, grow)
    assert len(joined) == len(whole)
    assert np.allclose(joined, whole, rtol=0.0, atol=1e-12)
    assert np.allclose(joined[-1], trajectory.positions[-1])
