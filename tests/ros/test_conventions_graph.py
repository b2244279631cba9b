"""ROS conventions of the installed lifter, on the real graph: ``/diagnostics`` levels and
content, markers with a lifetime and a DELETEALL first, the ``frame_id`` fallback for empty input
frames, and the per-joint ``observed`` / ``joint_weights`` / ``joint_std`` of ``Skeleton3D``."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from pose_lifter.messages import convert as m

from .conftest import GraphClient
from .test_lifter_graph import CHEAP, STANDING, coco_keypoints, frame

pytestmark = pytest.mark.ros


def _status(msg: Any) -> tuple[int, str, dict[str, str]]:
    (s,) = [s for s in msg.status if s.name == "pose_lifter: lifter"]
    level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
    return level, s.message, {kv.key: kv.value for kv in s.values}


def test_diagnostics_ok_error_and_no_input(start_lifter: Any, graph: GraphClient) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    diags: list[Any] = []
    graph.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    graph.wait_for_lifter(start_lifter(params={**CHEAP, "diagnostics_period": 0.5}))
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    for i in range(6):
        graph.send(frame(t, 10**9 + i * 10**8, [(0, kp, c)]))
    graph.spin_until(lambda: any(_status(d)[2]["skeletons lifted"] != "0" for d in diags), 30.0,
                     "a diagnostics window with lifted skeletons")
    level, message, values = next(_status(d) for d in diags if _status(d)[2]["skeletons lifted"] != "0")
    assert (level, message) == (0, "lifting")
    for key in ("input rate (Hz)", "frames", "warm share", "cold share", "latency median (ms)",
                "latency p95 (ms)", "solve median (ms)", "solve p95 (ms)", "skipped total"):
        assert key in values
    assert float(values["input rate (Hz)"]) > 0 and 0.0 <= float(values["warm share"]) <= 1.0
    assert float(values["warm share"]) + float(values["cold share"]) == pytest.approx(1.0, abs=2e-3)

    # a window of nothing but unusable skeletons (no confident keypoint) is an ERROR, by kind
    n = len(diags)
    graph.spin_until(lambda: len(diags) > n, 10.0, "the next diagnostics window")
    n = len(diags)
    for i in range(4):
        graph.send(frame(t, 5 * 10**9 + i * 10**8, [(1, kp, np.zeros_like(c))]))
    graph.spin_until(lambda: any(_status(d)[0] == 2 for d in diags[n:]), 10.0, "an ERROR status")
    level, message, values = next(_status(d) for d in diags[n:] if _status(d)[0] == 2)
    assert "no skeleton could be lifted" in message
    assert int(values["skipped: no confident keypoints"]) >= 1

    # no input at all: WARN
    n = len(diags)
    time.sleep(1.2)
    graph.spin_until(lambda: any(_status(d)[1] == "no input on keypoints_2d" for d in diags[n:]), 10.0,
                     "a 'no input' status")
    assert next(_status(d)[0] for d in diags[n:] if _status(d)[1] == "no input on keypoints_2d") == 1


def test_markers_lifetime_deleteall_first_frame_fallback_observed(start_lifter: Any, graph: GraphClient
                                                                   ) -> None:
    t = graph.types
    first: list[Any] = []
    graph.node.create_subscription(t.MarkerArray, "skeleton_markers", first.append, 100)
    graph.wait_for_lifter(start_lifter(params={**CHEAP, "marker_lifetime": 0.5,
                                               "frame_id": "fallback_optical_frame"}))
    graph.spin_until(lambda: len(first) > 0, 10.0, "the first MarkerArray")
    head = first[0].markers[:2]
    assert [(mk.action, mk.ns) for mk in head] == [(t.Marker.DELETEALL, "pose_lifter/joints"),
                                                   (t.Marker.DELETEALL, "pose_lifter/bones")]
    assert all(mk.action != t.Marker.DELETEALL for a in first[1:] for mk in a.markers)

    kp, c = coco_keypoints(STANDING, 30.0)
    c[[9, 15]] = 0.0  # COCO left wrist and left ankle missing
    msg = frame(t, 10**9, [(3, kp, c)], frame_id="")
    n_sk = len(graph.skeletons)
    graph.pub_keypoints.publish(msg)
    graph.spin_until(lambda: len(graph.skeletons) > n_sk, 30.0, "the answer")
    answer = graph.skeletons[n_sk]
    assert answer.header.frame_id == "fallback_optical_frame"
    graph.spin_until(lambda: any(mk.header.frame_id == "fallback_optical_frame" for a in graph.markers
                                 for mk in a.markers), 10.0, "markers in the fallback frame")
    adds = [mk for a in graph.markers for mk in a.markers if mk.action == t.Marker.ADD]
    assert adds and all(mk.lifetime.sec == 0 and mk.lifetime.nanosec == 500_000_000 for mk in adds)
    (skel,) = answer.skeletons
    names = list(skel.joint_names)
    observed = dict(zip(names, skel.observed, strict=True))
    assert not observed["left_wrist"] and not observed["left_ankle"]
    assert sum(observed.values()) == 10
    weights = np.asarray(skel.joint_weights)
    assert weights[names.index("left_wrist")] == 0.0
    assert weights[names.index("right_wrist")] == pytest.approx(0.9)
    # joint_std reaches rclpy as the field's layout: 12 standard deviations, or empty when unknown
    std = m.skeleton3d_to_std(skel)
    assert len(skel.joint_std) in (0, 12)
    assert np.isnan(std).all() if len(skel.joint_std) == 0 else (np.isfinite(std).all() and (std >= 0).all())


def test_a_burst_faster_than_the_lift_drops_whole_frames_and_says_so(start_lifter: Any,
                                                                     graph: GraphClient) -> None:
    """Frames published faster than the node lifts them: the node answers whole frames in
    arrival order, drops the others whole (the oldest waiting first: the newest frame of the
    burst is always answered), and /diagnostics counts every frame it dropped. A reliable input
    queue (QoS override) keeps the middleware from dropping any, so answered + dropped is every
    frame published."""
    from diagnostic_msgs.msg import DiagnosticArray

    diags: list[Any] = []
    graph.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 100)
    # cold multi-start solves of 6 people: each frame takes far longer than the burst's spacing
    graph.wait_for_lifter(start_lifter(params={
        "n_starts": 30, "warm_start": False, "diagnostics_period": 0.5, "max_waiting_frames": 1,
        "qos_overrides./keypoints_2d.subscription.reliability": "reliable",
        "qos_overrides./keypoints_2d.subscription.depth": 100}))
    t = graph.types
    people = [(i, *coco_keypoints(STANDING, 30.0 * i, centre=(100.0 + 90 * i, 240.0))) for i in range(6)]
    n_sk = len(graph.skeletons)
    stamps = [10**9 + i * 10**7 for i in range(12)]
    for s in stamps:
        graph.pub_keypoints.publish(frame(t, s, people))
        graph.executor.spin_once(timeout_sec=0.001)
    graph.spin_until(lambda: any(m.stamp_to_ns(a.header.stamp) == stamps[-1] for a in graph.skeletons[n_sk:]),
                     60.0, "the answer to the burst's last frame")

    def dropped() -> int:
        return sum(int(_status(d)[2]["frames dropped"]) for d in diags)

    answers = graph.skeletons[n_sk:]
    answered = [m.stamp_to_ns(a.header.stamp) for a in answers]
    graph.spin_until(lambda: dropped() + len(answered) >= len(stamps), 10.0,
                     "/diagnostics counting the dropped frames")
    assert answered == sorted(answered) and set(answered) <= set(stamps)
    assert all(len(a.skeletons) == len(people) for a in answers)  # whole frames only
    assert answered[-1] == stamps[-1]  # the newest frame never waits behind another
    assert 2 <= len(answered) < len(stamps)  # the lift is slower than the burst
    assert dropped() + len(answered) == len(stamps)
    level, message, _ = next(_status(d) for d in diags if _status(d)[2]["frames dropped"] != "0")
    assert level == 1 and "frames dropped" in message
