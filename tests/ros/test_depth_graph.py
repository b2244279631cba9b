"""The installed lifter with a depth topic, on the real graph: camera_info, depth images and
keypoints in; every frame answered; frames paired with their depth image counted in
/diagnostics; a depth topic gone silent is a WARN; bad depth input (no camera_info yet, another
encoding) warns in one line and the frames are lifted from the 2D alone."""

from __future__ import annotations

import array
import time
from typing import Any

import numpy as np
import pytest
from pose_lifter.messages import convert as m
from pose_lifter.messages.names import TOPIC_DEPTH

from .conftest import GraphClient, all_finite
from .test_lifter_graph import STANDING, coco_keypoints, frame

pytestmark = pytest.mark.ros

W, H, FX = 640, 480, 500.0
#: The depth images' wall: the monocular lift of these keypoints places the person ~3.1 m away.
DEPTH_MM = 3600
#: The fused joints lie behind the wall's surface by the joints' surface offsets (at most ~0.12 m,
#: pose_lifter.core.depth.SURFACE_OFFSET_M) and their spread along the ray: within this of it.
NEAR_WALL_M = 0.2


def _status(msg: Any) -> tuple[int, str, dict[str, str]]:
    (s,) = [s for s in msg.status if s.name == "pose_lifter: lifter"]
    level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
    return level, s.message, {kv.key: kv.value for kv in s.values}


def _depth_image(stamp_ns: int, encoding: str = "16UC1", mm: int = DEPTH_MM) -> Any:
    from sensor_msgs.msg import Image

    from_mm = np.full(H * W, mm, dtype="<u2").view(np.uint8)
    pixels = from_mm if encoding == "16UC1" else np.zeros(H * W * 3, dtype=np.uint8)
    return Image(header=m.make_header(stamp_ns, "camera_optical", m.rclpy_types()), height=H, width=W,
                 encoding=encoding, is_bigendian=0, step=len(pixels) // H,
                 data=array.array("B", pixels.tobytes()))


def _setup(start_lifter: Any, graph: GraphClient, **params: Any) -> tuple[Any, Any, list[Any]]:
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image

    diags: list[Any] = []
    graph.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    reliable = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
    pub = graph.node.create_publisher(Image, TOPIC_DEPTH, reliable)
    lifter = start_lifter(params={"depth_topic": TOPIC_DEPTH, "diagnostics_period": 0.5, **params})
    graph.wait_for_lifter(lifter)
    graph.spin_until(lambda: pub.get_subscription_count() > 0, 60.0, "the lifter's depth subscription")
    # reliable, as cameras publish depth (over best effort most 0.6 MB images never arrive whole)
    (sub,) = graph.node.get_subscriptions_info_by_topic(TOPIC_DEPTH)
    assert sub.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    return lifter, pub, diags


def _send_with_depth(graph: GraphClient, pub: Any, stamp_ns: int, depth: Any | None) -> Any:
    """One frame whose depth image (when given) was published just before its keypoints."""
    kp, c = coco_keypoints(STANDING, 30.0, centre=(400.0, 240.0))
    if depth is not None:
        pub.publish(depth)
        end = time.monotonic() + 0.15  # the image is on its way before the keypoints
        while time.monotonic() < end:
            graph.executor.spin_once(timeout_sec=0.02)
    return graph.send(frame(graph.types, stamp_ns, [(0, kp, c)]))


def test_depth_paired_counted_and_silence_warned(start_lifter: Any, graph: GraphClient) -> None:
    lifter, pub, diags = _setup(start_lifter, graph)
    t = graph.types
    info = m.camera_info(m.make_header(10**9, "camera_optical", t), W, H, FX, FX, 320.0, 240.0, t)
    answers = []
    for i in range(8):
        graph.pub_camera_info.publish(info)
        stamp = 10**9 + i * 33_000_000
        answers.append(_send_with_depth(graph, pub, stamp, _depth_image(stamp)))
    wall = DEPTH_MM / 1000.0
    at_wall = []  # the person placed on the depth, not where the 2D alone puts it (~0.5 m nearer)
    for a in answers:
        (s,) = a.skeletons.skeletons
        assert all_finite(a.skeletons) and len(s.joints) == 12
        if 0.0 < m.skeleton3d_to_joints(s)[:, 2].mean() - wall < NEAR_WALL_M:
            at_wall.append(s)
            assert np.isfinite(m.skeleton3d_to_std(s)).all()  # each joint with its uncertainty
    # the first images may come before the lifter's reader has matched this writer
    assert len(at_wall) >= 4 and at_wall[-1] is answers[-1].skeletons.skeletons[0], \
        f"{len(at_wall)} of 8 frames placed on their depth image"
    graph.spin_until(lambda: any(int(_status(d)[2].get("frames with depth", "0")) > 0 for d in diags), 30.0,
                     "a diagnostics window with frames lifted with depth")
    assert f"depth from {TOPIC_DEPTH}" in lifter.log()

    # the depth topic goes silent: the frames are lifted from the 2D alone, counted, and WARN
    n = len(diags)
    for i in range(12):
        graph.pub_camera_info.publish(info)
        a = _send_with_depth(graph, pub, 3 * 10**9 + i * 150_000_000, None)
        assert len(a.skeletons.skeletons) == 1
    graph.spin_until(lambda: any(_status(d)[0] == 1 and "no depth image" in _status(d)[1] for d in diags[n:]),
                     30.0, "a WARN for the silent depth topic")
    assert any(int(_status(d)[2].get("frames without depth: depth: no partner", "0")) > 0 for d in diags[n:])


def test_bad_depth_input_warns_and_the_lift_goes_on(start_lifter: Any, graph: GraphClient) -> None:
    lifter, pub, diags = _setup(start_lifter, graph)
    t = graph.types
    # depth images before any camera_info: one warning, the 2D lift (the first images may come
    # before the lifter's reader has matched this writer: sent until one is read)
    for i in range(20):
        stamp = i * 33_000_000
        a = _send_with_depth(graph, pub, stamp, _depth_image(stamp))
        assert len(a.skeletons.skeletons) == 1
        if "no camera_info" in lifter.log():
            break
    info = m.camera_info(m.make_header(10**9, "camera_optical", t), W, H, FX, FX, 320.0, 240.0, t)
    for i in range(1, 5):  # another encoding: warned once, each frame lifted from the 2D
        graph.pub_camera_info.publish(info)
        stamp = 10**9 + i * 33_000_000
        a = _send_with_depth(graph, pub, stamp, _depth_image(stamp, encoding="rgb8"))
        assert len(a.skeletons.skeletons) == 1 and all_finite(a.skeletons)
    log = lifter.log()
    assert "no camera_info" in log
    assert log.count("'rgb8' is not a depth encoding") == 1  # rate-limited: once per period
    key = "frames without depth: depth: unsupported encoding"
    graph.spin_until(lambda: any(int(_status(d)[2].get(key, "0")) > 0 for d in diags), 30.0,
                     "the refused images counted in /diagnostics")


def test_one_topics_qos_override_stays_on_its_topic(start_lifter: Any, graph: GraphClient) -> None:
    """rclpy writes a topic's ``qos_overrides`` into the profile it is given: camera_info made
    reliable must leave the keypoints best effort (a shared profile carried it over, and a
    best-effort detector's keypoints then never arrived)."""
    from rclpy.qos import ReliabilityPolicy

    lifter = start_lifter(params={"qos_overrides./camera_info.subscription.reliability": "reliable",
                                  "depth_topic": TOPIC_DEPTH})
    graph.wait_for_lifter(lifter)
    graph.spin_until(lambda: bool(graph.node.get_subscriptions_info_by_topic(TOPIC_DEPTH)), 60.0,
                     "the lifter's depth subscription")
    policy = {t: graph.node.get_subscriptions_info_by_topic(t)[0].qos_profile.reliability
              for t in ("/camera_info", "/keypoints_2d", TOPIC_DEPTH)}
    reliable, best_effort = ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT
    assert policy == {"/camera_info": reliable, "/keypoints_2d": best_effort, TOPIC_DEPTH: reliable}
