"""The node publishes ``skeletons_3d`` as CDR written from arrays
(:func:`pose_lifter.messages.cdr.skeleton3d_array_cdr`). rclpy, with the workspace's generated
``pose_lifter_msgs``, must read them as the ``Skeleton3DArray`` built as message objects
(:func:`pose_lifter.messages.convert.result_to_skeleton3d`), and they must be exactly as long as
rclpy's own serialisation of it, byte for byte outside the alignment padding (which rclpy leaves
uninitialised; the writer zeroes it, as rosbags does: ``tests/messages/test_cdr.py`` checks every byte
against rosbags), with each skeleton's ``joint_std`` filled or empty."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from lift_samples import random_frame
from pose_lifter.messages import cdr
from pose_lifter.messages import convert as m

from .conftest import _load_workspace_messages

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("frame_id", ["", "cam", "camera_", "virtual_camera_optical_frame"])
def test_the_written_skeletons_are_the_bytes_rclpy_serialises(frame_id: str) -> None:
    _load_workspace_messages()
    from pose_lifter_msgs.msg import Skeleton3DArray
    from rclpy.serialization import deserialize_message, serialize_message

    rng = np.random.default_rng(len(frame_id) + 1)
    types = m.rclpy_types()
    header = m.make_header(1_234_567_890_123, frame_id, types)
    track_ids = [4, -1, 9, 2**40 + 3, 0]
    results, joints, times, warm = random_frame(rng, len(track_ids), depth=4.0)
    filled = [rng.uniform(0.005, 0.4, size=(12, 3)) for _ in track_ids]
    mixed = [filled[0], None, filled[2], None, filled[4]]  # joint_std filled, empty, filled, ...
    for n, stds in itertools.product((0, 1, len(track_ids)), ([None] * len(track_ids), mixed)):
        skels = [m.result_to_skeleton3d(r, t, j, types, s, w, std_m=sd)
                 for r, t, j, s, w, sd in zip(results[:n], track_ids[:n], joints[:n], times[:n], warm[:n],
                                              stds[:n], strict=True)]
        msg = m.skeletons3d_array(header, skels, types)
        want = bytes(serialize_message(msg))
        frame = cdr.SkeletonFrame.from_results(track_ids[:n], joints[:n], results[:n], times[:n], warm[:n],
                                               std_m=stds[:n])
        got = cdr.skeleton3d_array_cdr(cdr.message_header(header), frame)
        assert deserialize_message(got, Skeleton3DArray) == msg
        assert len(got) == len(want)
        differ = [i for i, (a, b) in enumerate(zip(got, want, strict=True)) if a != b]
        assert all(got[i] == 0 for i in differ), differ  # only padding, which the writer zeroes
        for sk, sd in zip(deserialize_message(got, Skeleton3DArray).skeletons, stds, strict=False):
            std = m.skeleton3d_to_std(sk)
            assert np.isnan(std).all() if sd is None else np.array_equal(std, sd)


def test_the_node_reads_a_frame_as_arrays_and_what_the_reader_refuses_through_rclpy() -> None:
    """The node subscribes to the serialised frame (``raw``) and reads it into arrays
    (:func:`~pose_lifter.messages.cdr.read_skeleton2d_array`, rclpy's deserialiser its fallback):
    the frame rclpy serialises reads as rclpy's message does, keypoint for keypoint; a frame the
    array reader refuses (big-endian CDR) is deserialised by rclpy instead; a message object
    passes as it is."""
    _load_workspace_messages()
    from pose_lifter.messages.cdr import DecodedSkeleton2DArray, read_skeleton2d_array
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import read_messages
    from pose_lifter_msgs.msg import Skeleton2DArray
    from rclpy.serialization import deserialize_message, serialize_message

    from .conftest import REPO

    store = pose_lifter_typestore()

    def read_frame(data: object) -> Any:  # as the node reads a frame
        return read_skeleton2d_array(data, lambda raw: deserialize_message(raw, Skeleton2DArray))

    x = next(r for r in read_messages(REPO / "bags" / "two_people.mcap") if r.topic.endswith("keypoints_2d"))
    msg = deserialize_message(bytes(store.serialize_cdr(x.msg, x.msgtype)), Skeleton2DArray)
    msg.header.frame_id = "camera_optical"
    little = bytes(serialize_message(msg))
    read = read_frame(little)
    assert isinstance(read, DecodedSkeleton2DArray)
    assert (read.header.stamp.sec, read.header.stamp.nanosec, read.header.frame_id, read.layout) == (
        msg.header.stamp.sec, msg.header.stamp.nanosec, "camera_optical", msg.layout)
    assert [s.track_id for s in read.skeletons] == [s.track_id for s in msg.skeletons]
    for got, want in zip(read.skeletons, msg.skeletons, strict=True):
        xyc = np.array([[k.x, k.y, k.confidence] for k in want.keypoints])
        assert np.array_equal(got.xyc, xyc)
    big = bytes(store.serialize_cdr(x.msg, x.msgtype, little_endian=False))
    fallback = read_frame(big)
    assert isinstance(fallback, Skeleton2DArray)
    assert fallback == deserialize_message(bytes(store.serialize_cdr(x.msg, x.msgtype)), Skeleton2DArray)
    assert read_frame(msg) is msg
