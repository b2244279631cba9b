"""The downstream example on a real graph: ``action_recognition`` behind ``skeletons_3d``."""

from __future__ import annotations

import signal
import subprocess
import time
from collections import Counter
from typing import Any

import pytest

from .conftest import DISCOVERY_TIMEOUT, INSTALL, REPO, SHUTDOWN_TIMEOUT, GraphClient

pytestmark = pytest.mark.ros

EXE = INSTALL / "pose_lifter" / "lib" / "pose_lifter" / "action_recognition"
#: Ground-truth 3D of a walk (the model's walk class includes this trial, 07_05: a plumbing test).
BAG = REPO / "bags" / "walk_clean.mcap"


def test_action_recognition_classifies_tracks_from_skeletons_3d(
    lifter_env: dict[str, str], graph: GraphClient, tmp_path: Any
) -> None:
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import read_messages
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    store = pose_lifter_typestore()
    truth = [x for x in read_messages(BAG) if x.topic == "/ground_truth/skeletons_3d"][:30]
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = graph.node.create_publisher(graph.types.Skeleton3DArray, "skeletons_3d", reliable)
    actions: list[str] = []
    sub = graph.node.create_subscription(String, "actions", lambda msg: actions.append(msg.data), reliable)

    log_path = tmp_path / "action_recognition.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([str(EXE)], env=lifter_env, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
    try:
        graph.spin_until(lambda: pub.get_subscription_count() > 0 and sub.get_publisher_count() > 0,
                         DISCOVERY_TIMEOUT, "discovery of action_recognition")
        # 30 Hz, as recorded; windows of 4 poses 0.1 s apart need 10 frames of history. The consumer's
        # `actions` writer may match this reader a little after the reverse match seen above, and
        # what it publishes before is not delivered (volatile): replay the sequence, stamps
        # shifted to keep increasing, until one whole pass is answered.
        shift_s = -(-(truth[-1].stamp_ns - truth[0].stamp_ns + 33_333_334) // 10**9)  # whole seconds
        for attempt in range(10):
            actions.clear()
            for x in truth:
                if attempt > 0:
                    x.msg.header.stamp.sec += shift_s
                pub.publish(bytes(store.serialize_cdr(x.msg, x.msgtype)))
                paced = time.monotonic() + 1.0 / 30.0  # at the bag's rate (the consumer keeps the last 10)
                while time.monotonic() < paced:
                    graph.executor.spin_once(timeout_sec=0.005)
            end = time.monotonic() + 3.0
            while len(actions) < len(truth) - 10 and time.monotonic() < end:
                graph.executor.spin_once(timeout_sec=0.05)
            if len(actions) >= len(truth) - 10:
                break
        else:
            pytest.fail(f"no pass of {len(truth)} frames was answered; log:\n{log_path.read_text()}")
    finally:
        proc.send_signal(signal.SIGINT)
        code = proc.wait(SHUTDOWN_TIMEOUT)
    log_text = log_path.read_text()
    assert code == 0 and "Traceback" not in log_text, log_text
    tracks = Counter(a.split()[0] for a in actions)
    assert set(tracks) == {"0"}
    labels = Counter(a.split()[1] for a in actions)
    assert labels.most_common(1)[0][0] == "walk", labels
    assert "track 0: walk" in log_text
