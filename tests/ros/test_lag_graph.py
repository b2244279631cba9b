"""The installed ``lifter`` with ``output_lag`` on a real ROS 2 graph: every frame is answered
once, in order, ``output_lag`` frames late, with what the frame pipeline and
:class:`~pose_lifter.messages.lagged.LaggedFrames` give in-process for the same frames; the
frames held when the input stops are published after the node's idle time."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from pose_lifter.messages import convert as m

from .conftest import ANSWER_TIMEOUT, REPO, GraphClient, all_finite

pytestmark = pytest.mark.ros

BAG = REPO / "bags" / "two_people.mcap"
N_FRAMES = 24


@pytest.mark.parametrize("lag", [3, 6])
def test_a_lagged_node_answers_every_frame_late_with_the_in_process_poses(
    start_lifter: Any, graph: GraphClient, lag: int
) -> None:
    """With a lag of 6 the node's lift itself reads each track's next 3 frames (the offline
    prior), as `pose-lifter lift` does."""
    from pose_lifter.core import Lifter, LifterOptions
    from pose_lifter.messages.frame import FramePipeline, FrameSettings, LiftedSkeleton
    from pose_lifter.messages.lagged import AHEAD_LAG, LaggedFrames
    from pose_lifter.messages.names import TOPIC_KEYPOINTS
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import read_messages
    from pose_lifter.ros.node import LAG_IDLE_S

    store = pose_lifter_typestore()
    keypoints = [x for x in read_messages(BAG, [TOPIC_KEYPOINTS])][:N_FRAMES]
    lifter = start_lifter(params={
        "output_lag": lag, "max_waiting_frames": 100,
        "qos_overrides./keypoints_2d.subscription.reliability": "reliable",
        "qos_overrides./keypoints_2d.subscription.depth": 100})
    graph.wait_for_lifter(lifter)
    # a detector's frames, each published once the answer LAG frames before it has come
    for k, x in enumerate(keypoints):
        n = len(graph.skeletons)
        graph.pub_keypoints.publish(bytes(store.serialize_cdr(x.msg, x.msgtype)))
        if k >= lag:
            graph.spin_until(lambda n=n: len(graph.skeletons) > n, ANSWER_TIMEOUT,
                             f"the answer to frame {k - lag}")
            assert len(graph.skeletons) == k - lag + 1  # one answer a frame, none early
    # the input stops: the frames held are published once it has been idle
    graph.spin_until(lambda: len(graph.skeletons) >= N_FRAMES, ANSWER_TIMEOUT + 2 * LAG_IDLE_S,
                     "the held answers")
    answers = list(graph.skeletons)
    assert [m.stamp_to_ns(a.header.stamp) for a in answers] == [x.stamp_ns for x in keypoints]
    assert all(all_finite(a) for a in answers)

    # in-process: the same lift, the same lag
    pipeline = FramePipeline(Lifter(None, LifterOptions(), reads_ahead=lag >= AHEAD_LAG), FrameSettings())
    lagged: LaggedFrames[None] = LaggedFrames(pipeline, lag)
    expected: list[list[LiftedSkeleton]] = []
    for x in keypoints:
        expected += [f.lifted for f in lagged.lift(None, x.stamp_ns, None, pipeline.check(x.msg))]
    expected += [f.lifted for f in lagged.flush()]
    assert [[s.track_id for s in a.skeletons] for a in answers] == [[s.track_id for s in e] for e in expected]
    node_joints = np.array([m.skeleton3d_to_joints(s) for a in answers for s in a.skeletons])
    np.testing.assert_allclose(node_joints, np.array([s.joints_m for e in expected for s in e]), atol=1e-6)
