"""The node publishes ``skeletons_3d`` as CDR written from arrays
(:func:`pose_lifter.messages.cdr.skeleton3d_array_cdr`). rclpy, with the workspace's generated
``pose_lifter_msgs``, must read them as the ``Skeleton3DArray`` built as message objects
(:func:`pose_lifter.messages.convert.result_to_skeleton3d`), and they must be exactly as long as
rclpy's own serialisation of it, byte for byte outside the alignment padding (which rclpy leaves
uninitialised; the writer zeroes it, as rosbags does: ``tests/messages/test_cdr.py`` checks every byte
against rosbags)."""

from __future__ import annotations

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
    for n in (0, 1, len(track_ids)):
        skels = [m.result_to_skeleton3d(r, t, j, types, s, w)
                 for r, t, j, s, w in zip(results[:n], track_ids[:n], joints[:n], times[:n], warm[:n],
                                          strict=True)]
        msg = m.skeletons3d_array(header, skels, types)
        want = bytes(serialize_message(msg))
        frame = cdr.SkeletonFrame.from_results(track_ids[:n], joints[:n], results[:n], times[:n], warm[:n])
        got = cdr.skeleton3d_array_cdr(header, frame)
        assert deserialize_message(got, Skeleton3DArray) == msg
        assert len(got) == len(want)
        differ = [i for i, (a, b) in enumerate(zip(got, want, strict=True)) if a != b]
        assert all(got[i] == 0 for i in differ), differ  # only padding, which the writer zeroes
