"""Issue 29 item 1: the recorder's MCAP file in Foxglove's schemas, fetched through the
contract (RecordingService.FetchRecording, streamed in chunks)."""
from __future__ import annotations

import hashlib
import io

import grpc
import numpy as np
import pytest
from foxglove.messages import FrameTransforms
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from landscape.robot.link_frames import LinkFrames
from landscape.v1 import end_effector_pb2 as ee
from landscape.v1 import recording_service_pb2 as rec
from landscape.v1 import recording_service_pb2_grpc as rec_grpc

from support import Arm, cell_file, error_info, make_keys, start_secured_server


@pytest.fixture
def arm(tmp_path):
    a = Arm(tmp_path, backend="kinematic")
    yield a
    a.close()


def _send(arm, text: str) -> str:
    return arm.device.SendCommand(ee.SendCommandRequest(input=text), timeout=30).result


def _fetch(channel, offset: int = 0, metadata=()) -> list[rec.FetchRecordingResponse]:
    stub = rec_grpc.RecordingServiceStub(channel)
    return list(stub.FetchRecording(rec.FetchRecordingRequest(offset=offset), timeout=30,
                                    metadata=metadata))


def _decoder(schema):
    """The protobuf class of an MCAP schema record (a FileDescriptorSet), by its name."""
    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def _recorded_move(arm) -> bytes:
    assert _send(arm, "recorder start") == "recording"
    arm.move_down_to(0.6, 0.0, 0.6)
    arm.move_down_to(0.5, 0.3, 0.5)
    _send(arm, "recorder stop")
    _send(arm, "recorder store")
    return arm.record.read_bytes()


def test_a_recording_fetched_in_chunks_is_the_stored_file_with_its_digest(arm):
    stored = _recorded_move(arm)
    chunks = _fetch(arm.session.channel)
    assert len(chunks) > 1 and all(len(c.data) <= 64 * 1024 for c in chunks)
    assert b"".join(c.data for c in chunks) == stored
    assert {c.size for c in chunks} == {len(stored)} and chunks[0].name == "record.mcap"
    assert chunks[-1].sha256 == hashlib.sha256(stored).hexdigest()
    assert not any(c.sha256 for c in chunks[:-1])
    assert chunks[0].media_type == "application/x-mcap"
    # a transfer cut short resumes where it stopped, and still gets the whole file's digest
    middle = len(stored) // 2 + 1
    resumed = _fetch(arm.session.channel, offset=middle)
    assert resumed[0].offset == middle
    assert b"".join(c.data for c in resumed) == stored[middle:]
    assert resumed[-1].sha256 == chunks[-1].sha256


def test_the_recording_opened_as_foxglove_does_holds_the_arm_moving_in_3d(arm):
    stored = _recorded_move(arm)
    reader = make_reader(io.BytesIO(stored))
    summary = reader.get_summary()
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    assert schemas["/tf"].name == "foxglove.FrameTransforms"
    assert schemas["/tf"].encoding == "protobuf"
    assert schemas["/tf"].data == FrameTransforms.get_schema().data
    assert "/robot_description" in schemas and "/joint_state" in schemas
    decode = _decoder(schemas["/tf"])
    tips = []
    frames = LinkFrames.for_arm(arm.server.device.arm)
    for _, channel, message in reader.iter_messages(topics=["/tf"]):
        transforms = decode.FromString(message.data).transforms
        assert [(t.parent_frame_id, t.child_frame_id) for t in transforms] == frames.pairs
        tips.append(_chain(transforms))
    tips = np.array(tips)
    assert len(tips) > 20
    # the flange moved to the point the move asked for (in the base frame)
    expected = arm.tip()[:3, 3]
    assert np.linalg.norm(tips[-1] - expected) < 1e-3
    assert np.linalg.norm(tips[0] - tips[-1]) > 0.05
    description = next(reader.iter_messages(topics=["/robot_description"]))[2]
    assert b'<robot name=' in description.data and b"link6" in description.data


def _chain(transforms) -> np.ndarray:
    """tool0's origin in base_link: the transforms composed along the chain."""
    import pinocchio as pin
    pose = pin.SE3.Identity()
    for t in transforms:
        q = t.rotation
        step = pin.SE3(pin.Quaternion(q.w, q.x, q.y, q.z).matrix(),
                       np.array([t.translation.x, t.translation.y, t.translation.z]))
        pose = pose * step
    return pose.translation.copy()


def test_nothing_stored_yet_or_an_offset_past_the_end_is_refused(arm):
    with pytest.raises(grpc.RpcError) as refused:
        _fetch(arm.session.channel)
    assert refused.value.code() is grpc.StatusCode.FAILED_PRECONDITION
    assert error_info(refused.value).reason == "NO_RECORDING"
    stored = _recorded_move(arm)
    with pytest.raises(grpc.RpcError) as refused:
        _fetch(arm.session.channel, offset=len(stored) + 1)
    assert refused.value.code() is grpc.StatusCode.OUT_OF_RANGE


def test_fetching_a_recording_needs_the_operator_role(tmp_path):
    """A viewer is refused; an operator is let through to find nothing stored yet (the
    recording goes to tmp_path: the default one, var/records, may hold a file from a run)."""
    keys = make_keys(tmp_path)
    cell = cell_file(tmp_path, {'path = "var/records/cs8.mcap"':
                                f'path = "{tmp_path / "record.mcap"}"'})
    server = start_secured_server(keys, cell=cell)
    try:
        credentials = grpc.ssl_channel_credentials(keys.certs.ca.read_bytes())
        with grpc.secure_channel(f"localhost:{server.port}", credentials) as channel:
            for role, code in (("viewer", grpc.StatusCode.PERMISSION_DENIED),
                               ("operator", grpc.StatusCode.FAILED_PRECONDITION)):
                with pytest.raises(grpc.RpcError) as refused:
                    _fetch(channel, metadata=(("authorization", f"Bearer {keys.token(role)}"),))
                assert refused.value.code() is code, (role, refused.value.details())
    finally:
        server.stop(grace=None)
