"""The MCAP recorder: what goes in per cycle comes back out of the file."""
from __future__ import annotations

import json
import os
import tracemalloc

import numpy as np
import pytest
from mcap.reader import make_reader

from landscape.sim import recorder as rec
from landscape.sim.recorder import Recorder, read_recording

CT = 0.004
FIELDS = ("cmd_pos", "cmd_vel", "fbk_pos", "fbk_vel", "fbk_torque")


def cycle_values(k: int, n: int = 6) -> tuple:
    """Distinct, non-round values for cycle k: t and five (n,) arrays."""
    base = np.arange(n) + 1.0
    return (k * CT, np.sin(k * 0.01 * base), np.cos(k * 0.02 * base) / 3,
            np.sin(k * 0.013 * base) * np.pi, base * k * 1e-3 / 7, -base * np.exp(-k * 1e-3))


def feed(recorder: Recorder, cycles: range) -> None:
    for k in cycles:
        recorder.append(*cycle_values(k))


def test_every_nth_cycle_reads_back_exactly(tmp_path):
    r = Recorder(str(tmp_path / "a.mcap"), every_nth=3, max_seconds=10.0)
    r.start()
    feed(r, range(100))
    r.stop()
    feed(r, range(100, 110))  # not recording: ignored
    assert len(r) == 34  # cycles 0, 3, ..., 99
    path = r.store()
    assert path == str(tmp_path / "a.mcap")

    data = read_recording(path)
    kept = range(0, 100, 3)
    assert data["t"].shape == (34,)
    np.testing.assert_allclose(data["t"], [k * CT for k in kept], rtol=0, atol=1e-9)
    for i, name in enumerate(FIELDS, start=1):
        expected = np.array([cycle_values(k)[i] for k in kept])
        assert data[name].shape == (34, 6)
        np.testing.assert_array_equal(data[name], expected)  # bit-identical through JSON
    assert not [p for p in os.listdir(tmp_path) if p != "a.mcap"]  # no temp file left


def test_file_is_standard_mcap_with_json_channels(tmp_path):
    r = Recorder(str(tmp_path / "b.mcap"), joint_count=6)
    r.start()
    feed(r, range(5))
    path = r.store()
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {rec.COMMAND_TOPIC, rec.STATE_TOPIC}
        for channel in topics.values():
            assert channel.message_encoding == "json"
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "jsonschema"
            assert json.loads(schema.data)["type"] == "object"
        assert summary.statistics.message_count == 10
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta[rec.METADATA_NAME]["joint_count"] == "6"
        times = []
        for _, channel, message in reader.iter_messages(topics=[rec.STATE_TOPIC]):
            body = json.loads(message.data)
            assert body["name"] == [f"joint_{i}" for i in range(1, 7)]
            assert set(body) == {"timestamp", "name", "position", "velocity", "effort"}
            times.append(message.log_time)
        assert times == [round(k * CT * 1e9) for k in range(5)]


def test_full_recorder_stops_silently(tmp_path):
    r = Recorder(str(tmp_path / "c.mcap"), every_nth=2, max_seconds=0.1)
    assert r.capacity == 13  # ceil(0.1 s / 8 ms)
    r.start()
    feed(r, range(1000))
    assert r.full and not r.recording and len(r) == 13
    data = read_recording(r.store())
    assert len(data["t"]) == 13
    np.testing.assert_allclose(data["t"][-1], 24 * CT, atol=1e-9)
    r.start()  # a new recording clears the old one
    assert not r.full and len(r) == 0


def test_store_without_recording_writes_an_empty_file(tmp_path):
    r = Recorder(str(tmp_path / "sub" / "d.mcap"), joint_count=7)
    data = read_recording(r.store())
    assert data["t"].shape == (0,)
    assert all(data[name].shape == (0, 7) for name in FIELDS)


def test_store_twice_and_while_recording(tmp_path):
    r = Recorder(str(tmp_path / "e.mcap"))
    r.start()
    feed(r, range(10))
    first = read_recording(r.store())  # a snapshot while still recording
    feed(r, range(10, 20))
    second = read_recording(r.store())
    assert len(first["t"]) == 10 and len(second["t"]) == 20
    np.testing.assert_array_equal(second["fbk_pos"][:10], first["fbk_pos"])
    r.stop()
    again = read_recording(r.store())
    np.testing.assert_array_equal(again["cmd_vel"], second["cmd_vel"])


def test_failed_store_keeps_the_previous_file(tmp_path, monkeypatch):
    r = Recorder(str(tmp_path / "f.mcap"))
    r.start()
    feed(r, range(3))
    path = r.store()
    before = open(path, "rb").read()
    feed(r, range(3, 6))

    def broken(*_args, **_kw):
        raise OSError("disk full")

    monkeypatch.setattr(Recorder, "_write", broken)
    with pytest.raises(OSError):
        r.store()
    assert open(path, "rb").read() == before
    assert os.listdir(tmp_path) == ["f.mcap"]


def test_append_allocates_nothing_that_stays(tmp_path):
    r = Recorder(str(tmp_path / "g.mcap"), max_seconds=10.0)
    values = cycle_values(1)
    r.start()
    r.append(*values)  # warm up
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        for _ in range(1000):
            r.append(*values)
        after = tracemalloc.take_snapshot()
        growth = sum(s.size_diff for s in after.compare_to(before, "filename"))
    finally:
        tracemalloc.stop()
    assert len(r) == 1001
    assert growth < 4096  # bytes: bookkeeping noise, nothing per call


def test_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError):
        Recorder(str(tmp_path / "h.mcap"), every_nth=0)
    with pytest.raises(ValueError):
        Recorder(str(tmp_path / "h.mcap"), max_seconds=0)
