"""The installed ``lifter`` on a real ROS 2 graph (separate process, Fast DDS, localhost).

Frames go in lock step: the next frame is published only after the answer to the previous one,
as a detector running at the lifter's rate would do.
"""

from __future__ import annotations

import signal
from typing import Any

import numpy as np
import pytest
import tolerances as tol
import yaml
from params_cases import LIVE_ONLY_PARAMS, NON_DEFAULT_PARAMS
from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages import convert as m
from pose_lifter.messages.layouts import get_layout
from scipy.spatial.transform import Rotation

from .conftest import PARAMS_YAML, REPO, SHUTDOWN_TIMEOUT, GraphClient, all_finite

pytestmark = pytest.mark.ros

#: Solver settings for tests that check the node's plumbing, not accuracy: cheap solves.
#: Start-up parameters of the tests that only need answers: the default hybrid lift (the paper mode's
#: starts and caps, which made the paper's solves cheap, are refused in it).
CHEAP: dict[str, Any] = {}

#: A standing person (metres; x to the subject's left, y up, z forward), paper joint order.
STANDING = np.array([
    [0.19, 1.42, 0.0], [0.24, 1.13, 0.05], [0.26, 0.88, 0.12],
    [-0.19, 1.42, 0.0], [-0.24, 1.13, 0.05], [-0.26, 0.88, 0.12],
    [0.10, 0.92, 0.0], [0.11, 0.50, 0.03], [0.11, 0.08, 0.0],
    [-0.10, 0.92, 0.0], [-0.11, 0.50, 0.03], [-0.11, 0.08, 0.0],
])


def coco_keypoints(pose_m: np.ndarray, yaw_deg: float, centre: tuple[float, float] = (320.0, 240.0),
                   px_per_m: float = 150.0) -> tuple[np.ndarray, np.ndarray]:
    """Scaled-orthographic image of a pose in COCO-17 order (face keypoints missing)."""
    rotated = pose_m @ Rotation.from_euler("y", yaw_deg, degrees=True).as_matrix().T
    xy = np.column_stack([-rotated[:, 0], -rotated[:, 1]]) * px_per_m  # image x right, y down
    xy -= xy.mean(axis=0) - np.asarray(centre)
    kp = np.zeros((17, 2))
    conf = np.zeros(17)
    idx = list(get_layout("coco17").model_indices)
    kp[idx] = xy
    conf[idx] = 0.9
    return kp, conf


def frame(t: Any, stamp_ns: int, skeletons: list[tuple[int, np.ndarray, np.ndarray]],
          layout: str = "coco17", frame_id: str = "camera_optical") -> Any:
    """A Skeleton2DArray (rclpy) from (track_id, keypoints (K, 2), confidence (K,)) triples."""
    return t.Skeleton2DArray(
        header=m.make_header(stamp_ns, frame_id, t), layout=layout,
        skeletons=[m.arrays_to_skeleton2d(kp, c, tid, t) for tid, kp, c in skeletons])


def good_frame(t: Any, i: int, track_id: int = 0, yaw_deg: float = 30.0) -> Any:
    kp, c = coco_keypoints(STANDING, yaw_deg + 2.0 * i)
    return frame(t, 1_000_000_000 + i * 100_000_000, [(track_id, kp, c)])


def test_params_yaml_is_the_generated_one() -> None:
    from pose_lifter.ros.params import params_yaml

    source = REPO / "ros2_ws" / "src" / "pose_lifter" / "config" / "lifter.yaml"
    assert source.read_text() == params_yaml(), (
        "config/lifter.yaml is stale: python -m pose_lifter.ros.node --params-yaml > config/lifter.yaml")
    assert PARAMS_YAML.read_text() == source.read_text(), "the installed copy is stale: make ros"


def test_params_yaml_is_loaded_and_every_key_declared(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params_file=PARAMS_YAML)
    graph.wait_for_lifter(lifter)
    declared = yaml.safe_load(PARAMS_YAML.read_text())["/**"]["ros__parameters"]
    reported = graph.get_parameters(*declared)
    assert reported == declared


def test_a_params_file_of_non_default_values_reaches_the_node(start_lifter: Any, graph: GraphClient,
                                                              tmp_path: Any) -> None:
    from pose_lifter.ros.params import SPECS

    values = {**NON_DEFAULT_PARAMS, **LIVE_ONLY_PARAMS}
    for name, value in values.items():  # every value differs from its default
        assert value != SPECS[name].default and type(value) is type(SPECS[name].default), name
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({"pose_lifter": {"ros__parameters": values}}))
    lifter = start_lifter(params_file=path)
    graph.wait_for_lifter(lifter)
    assert graph.get_parameters(*values) == values
    # and the node runs with them: the empty frame_id becomes the file's, the untracked person
    # stands at the file's distance, cold (no warm starts), no markers
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    n_markers = len(graph.markers)
    from rclpy.serialization import serialize_message

    for i in range(2):  # sent as bytes: GraphClient.send would expect the sent (empty) frame_id back
        answer = graph.send(serialize_message(frame(t, (i + 1) * 10**9, [(3, kp, c)], frame_id="")),
                            expect_markers=False)
    (s,) = answer.skeletons.skeletons
    assert answer.skeletons.header.frame_id == "yaml_frame" and not s.warm_started
    np.testing.assert_allclose(m.skeleton3d_to_joints(s).mean(axis=0)[2], 4.25, atol=1e-9)
    assert len(graph.markers) == n_markers


def test_declared_descriptors_are_the_option_metadata(start_lifter: Any, graph: GraphClient) -> None:
    """Every option parameter is declared with its LifterOptions field's doc, range and choices,
    and the live node refuses just outside each range and takes the closed bounds."""
    import dataclasses
    import math

    from pose_lifter.core.options import NODE_OPTIONS, OPTION_META, LifterOptions
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import DescribeParameters

    lifter = start_lifter()
    graph.wait_for_lifter(lifter)
    client = graph.node.create_client(DescribeParameters, f"{graph.lifter_name}/describe_parameters")
    graph.spin_until(client.service_is_ready, 30.0, "describe_parameters")
    names = list(NODE_OPTIONS)
    described = graph.call(client, DescribeParameters.Request(names=names)).descriptors
    defaults = {f.name: f.default for f in dataclasses.fields(LifterOptions)}
    ros_type = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
                float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}
    for name, d in zip(names, described, strict=True):
        meta, kind = OPTION_META[name], type(defaults[name])
        assert (d.name, d.type, d.read_only) == (name, ros_type[kind], False), name
        assert d.description == meta.doc and d.additional_constraints == meta.constraint_text(), name
        ints = [(r.from_value, r.to_value, r.step) for r in d.integer_range]
        floats = [(r.from_value, r.to_value) for r in d.floating_point_range]
        assert ints == ([(meta.low, meta.high, 1)] if kind is int else []), name
        assert floats == ([(meta.low, meta.high)] if kind is float else []), name
    assert graph.get_parameters(*names) == {n: defaults[n] for n in names}

    for name in names:
        meta, kind = OPTION_META[name], type(defaults[name])
        if kind not in (int, float):
            continue
        assert meta.low is not None and meta.high is not None
        if kind is int:
            below, above = int(meta.low) - 1, int(meta.high) + 1
        else:
            below, above = math.nextafter(meta.low, -math.inf), math.nextafter(meta.high, math.inf)
        if meta.modes:  # an option of another mode: tried in its mode (the default one refuses it)
            assert graph.set_parameters(mode=meta.modes[0])[0].successful
        for value in (below, above):
            (r,) = graph.set_parameters(**{name: value})
            assert not r.successful, (name, value)
        for value, refused in ((meta.low, meta.open_low), (meta.high, meta.open_high)):
            (r,) = graph.set_parameters(**{name: kind(value)})
            assert r.successful is not refused, (name, value, r.reason)
        (r,) = graph.set_parameters(**{name: defaults[name]})
        assert r.successful, (name, r.reason)
        if meta.modes:
            assert graph.set_parameters(mode=defaults["mode"])[0].successful
    assert graph.get_parameters(*names) == {n: defaults[n] for n in names}
    assert lifter.alive()


def test_qos_sensor_data_input_reliable_outputs_and_overrides(start_lifter: Any, graph: GraphClient,
                                                              tmp_path: Any) -> None:
    from rclpy.qos import ReliabilityPolicy

    lifter = start_lifter()
    graph.wait_for_lifter(lifter)

    node = graph.node

    def reliability(topic: str, kind: str) -> list[Any]:
        infos = (node.get_subscriptions_info_by_topic(topic) if kind == "sub"
                 else node.get_publishers_info_by_topic(topic))
        return [i.qos_profile.reliability for i in infos if i.node_name == "pose_lifter"]

    # endpoint -> node names come with the graph's discovery info, shortly after the endpoints
    for topic, kind in (("/keypoints_2d", "sub"), ("/skeletons_3d", "pub"), ("/skeleton_markers", "pub")):
        graph.spin_until(lambda t=topic, k=kind: reliability(t, k) != [], 10.0, f"node name of {topic}")
    assert reliability("/keypoints_2d", "sub") == [ReliabilityPolicy.BEST_EFFORT]
    assert reliability("/skeletons_3d", "pub") == [ReliabilityPolicy.RELIABLE]
    assert reliability("/skeleton_markers", "pub") == [ReliabilityPolicy.RELIABLE]
    assert lifter.interrupt() == 0
    graph.spin_until(lambda: reliability("/keypoints_2d", "sub") == [], 10.0, "the lifter to leave the graph")

    # the YAML form documented at the end of config/lifter.yaml
    overrides = tmp_path / "qos.yaml"
    overrides.write_text(yaml.safe_dump({"pose_lifter": {"ros__parameters": {"qos_overrides": {
        "/keypoints_2d": {"subscription": {"reliability": "reliable", "depth": 20}}}}}}))
    lifter = start_lifter(extra_ros_args=("--params-file", str(overrides)))
    graph.wait_for_lifter(lifter)
    graph.spin_until(lambda: reliability("/keypoints_2d", "sub") != [], 10.0, "the new lifter's subscription")
    assert reliability("/keypoints_2d", "sub") == [ReliabilityPolicy.RELIABLE]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_clean_shutdown_on_signal(start_lifter: Any, graph: GraphClient, sig: int) -> None:
    lifter = start_lifter()
    graph.wait_for_lifter(lifter)
    graph.send(frame(graph.types, 10**9, []))  # it is up and answering
    lifter.proc.send_signal(sig)
    assert lifter.proc.wait(SHUTDOWN_TIMEOUT) == 0
    assert "Traceback" not in lifter.log()


def test_runtime_parameters_validated_by_core_options(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter()
    graph.wait_for_lifter(lifter)

    ok = graph.set_parameters(theta=0.2, warm_start=False)
    assert all(r.successful for r in ok), [r.reason for r in ok]
    assert graph.get_parameters("theta", "warm_start") == {"theta": 0.2, "warm_start": False}
    # an option only the paper mode reads: refused in the hybrid mode, with the reason; taken
    # with the paper mode, which cannot then be left while it is set
    (r,) = graph.set_parameters(n_starts=3)
    assert not r.successful and "n_starts = 3 is read only in paper mode" in r.reason
    ok = graph.set_parameters(mode="paper", n_starts=3)
    assert all(r.successful for r in ok), [r.reason for r in ok]
    (r,) = graph.set_parameters(mode="hybrid")
    assert not r.successful and "n_starts = 3 is read only in paper mode" in r.reason

    # out of the descriptor's range: refused by rclpy before our callback
    (r,) = graph.set_parameters(confidence_threshold=1.5)
    assert not r.successful and r.reason
    # inside the descriptor's range but refused by LifterOptions, with its reason
    (r,) = graph.set_parameters(alternation_tol=0.0)
    assert not r.successful and "alternation_tol" in r.reason
    (r,) = graph.set_parameters(variant="L3XX")
    assert not r.successful and "variant" in r.reason
    (r,) = graph.set_parameters(limb_proportions="giraffe")
    assert not r.successful and "limb_proportions" in r.reason
    (r,) = graph.set_parameters(bases_file="/nonexistent/bases.npz")
    assert not r.successful and "/nonexistent/bases.npz" in r.reason
    # wrong type: refused
    (r,) = graph.set_parameters(n_starts="many")
    assert not r.successful
    # read-only
    (r,) = graph.set_parameters(stats_period=1.0)
    assert not r.successful
    # nothing of the refused changes stuck
    names = ("alternation_tol", "variant", "limb_proportions", "bases_file", "n_starts")
    from pose_lifter.ros.params import PARAMS

    defaults = {p.name: p.default for p in PARAMS}
    assert graph.get_parameters(*names) == {**{n: defaults[n] for n in names}, "n_starts": 3}
    assert graph.get_parameters("mode") == {"mode": "paper"}
    assert lifter.alive()


def test_bad_input_never_kills_the_node_nor_publishes_nan(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params={**CHEAP, "stats_period": 2.0})
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    stamp = iter(range(10**9, 10**12, 10**8))  # strictly increasing stamps, 0.1 s apart

    def skel(track_id: int = 0, keypoints: np.ndarray = kp, confidence: np.ndarray = c) -> Any:
        return (track_id, keypoints, confidence)

    def with_nan(joint: int, value: float) -> np.ndarray:
        bad = kp.copy()
        bad[joint] = value
        return bad

    bad_frames: list[tuple[str, Any, int]] = [  # (what, frame, skeletons expected in the answer)
        ("empty array", frame(t, next(stamp), []), 0),
        ("unknown layout", frame(t, next(stamp), [skel()], layout="coco18"), 0),
        ("wrong keypoint count", frame(t, next(stamp), [skel(0, kp[:10], c[:10])]), 0),
        ("absurd keypoint count", frame(t, next(stamp), [skel(0, np.zeros((5000, 2)), np.ones(5000))]), 0),
        ("NaN keypoint", frame(t, next(stamp), [skel(0, with_nan(5, np.nan))]), 0),
        ("inf keypoint", frame(t, next(stamp), [skel(0, with_nan(11, np.inf))]), 0),
        ("NaN confidence", frame(t, next(stamp), [skel(0, kp, np.where(c > 0, np.nan, 0.0))]), 0),
        ("all-zero confidence", frame(t, next(stamp), [skel(0, kp, np.zeros(17))]), 0),
        ("absurd coordinates", frame(t, next(stamp), [skel(0, kp * 1e9)]), 0),
        ("duplicate track ids", frame(t, next(stamp), [skel(7), skel(7)]), 1),
        ("bad and good mixed", frame(t, next(stamp), [skel(0, with_nan(5, np.nan)), skel(-1)]), 1),
    ]
    for what, bad, expected in bad_frames:
        answer = graph.send(bad)
        assert len(answer.skeletons.skeletons) == expected, what
        assert all_finite(answer.skeletons), what
        good = graph.send(frame(t, next(stamp), [skel(0)]))
        assert len(good.skeletons.skeletons) == 1, f"good frame after {what}"
        assert all_finite(good.skeletons)

    # out-of-order stamp for a track: that skeleton is skipped, the untracked one still answered
    last = next(stamp)
    graph.send(frame(t, last, [skel(3)]))
    answer = graph.send(frame(t, last - 50_000_000, [skel(3), skel(-1)]))
    assert [s.track_id for s in answer.skeletons.skeletons] == [-1]

    # degenerate geometry (every keypoint on one pixel): whatever happens, no NaN and no crash
    answer = graph.send(frame(t, next(stamp), [skel(0, np.full((17, 2), 100.0))]))
    assert all_finite(answer.skeletons)

    # more people than max_skeletons: the largest in the image are lifted, in the frame's order
    (r,) = graph.set_parameters(max_skeletons=2)
    assert r.successful
    sizes = [1.0, 1.6, 0.7, 2.0, 1.2]  # people 3 and 1 are the largest
    crowd = [skel(i, (kp - kp.mean(axis=0)) * f + kp.mean(axis=0)) for i, f in enumerate(sizes)]
    answer = graph.send(frame(t, next(stamp), crowd))
    assert [s.track_id for s in answer.skeletons.skeletons] == [1, 3]

    assert lifter.alive()
    # rate-limited per kind (5 s): at most one warning per kind here, far fewer than bad skeletons
    warnings = [line for line in lifter.log().splitlines() if line.startswith("[WARN]")]
    assert 5 <= len(warnings) <= 12 and all("rate-limited" in w for w in warnings), warnings
    # the periodic statistics line counts every skipped skeleton by kind, with the latencies
    def stats_lines() -> list[str]:
        lines = lifter.log().splitlines()
        return [line for line in lines if line.startswith("[INFO]") and "skipped:" in line]

    graph.spin_until(lambda: any("absurd coordinates" in line for line in stats_lines()), 30.0,
                     "a statistics line counting the absurd coordinates")
    assert all("latency median" in line for line in stats_lines()), stats_lines()


def test_markers_per_track_and_deleted_when_a_track_disappears(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params=CHEAP)
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    kp2 = kp + np.array([150.0, 0.0])
    two = graph.send(frame(t, 10**9, [(4, kp, c), (9, kp2, c), (-1, kp, c)]))
    adds = [mk for mk in two.markers.markers if mk.action == t.Marker.ADD]
    assert sorted((mk.ns, mk.id) for mk in adds) == sorted(
        (f"pose_lifter/{kind}", i) for kind in ("joints", "bones") for i in (4, 9, -1))
    for mk in adds:
        assert mk.header.frame_id == "camera_optical"
        assert all(np.isfinite([p.x, p.y, p.z]).all() for p in mk.points)
    joints = {mk.id: mk for mk in adds if mk.ns.endswith("joints")}
    assert len(joints[4].points) == len(JOINT_NAMES)
    colour = {i: (mk.color.r, mk.color.g, mk.color.b) for i, mk in joints.items()}
    assert len(set(colour.values())) == 3  # one colour per track

    # track 9 and the untracked skeleton vanish: their markers are deleted, track 4 keeps id and colour
    one = graph.send(frame(t, 2 * 10**9, [(4, kp, c)]))
    adds = [mk for mk in one.markers.markers if mk.action == t.Marker.ADD]
    deletes = sorted((mk.ns, mk.id) for mk in one.markers.markers if mk.action == t.Marker.DELETE)
    assert sorted((mk.ns, mk.id) for mk in adds) == [("pose_lifter/bones", 4), ("pose_lifter/joints", 4)]
    assert deletes == sorted((f"pose_lifter/{kind}", i) for kind in ("joints", "bones") for i in (9, -1))
    same = next(mk for mk in adds if mk.ns.endswith("joints"))
    assert (same.color.r, same.color.g, same.color.b) == colour[4]

    # publish_markers off: no MarkerArray for the next frame
    (r,) = graph.set_parameters(publish_markers=False)
    assert r.successful
    graph.send(frame(t, 3 * 10**9, [(4, kp, c)]), expect_markers=False)
    n = len(graph.markers)
    graph.send(frame(t, 4 * 10**9, [(4, kp, c)]), expect_markers=False)
    assert len(graph.markers) == n


def test_depth_from_camera_info_or_default_distance(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params={**CHEAP, "default_distance": 4.5, "lower_leg_length": 0.4})
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0, centre=(400.0, 200.0))
    answer = graph.send(frame(t, 10**9, [(-1, kp, c)]))
    (s,) = answer.skeletons.skeletons
    joints = m.skeleton3d_to_joints(s)
    np.testing.assert_allclose(joints.mean(axis=0), [0.0, 0.0, 4.5], atol=tol.ROUND_OFF_ACCUMULATED)

    fx, fy, cx, cy = 500.0, 500.0, 320.0, 240.0
    info = m.camera_info(m.make_header(10**9, "camera_optical", t), 640, 480, fx, fy, cx, cy, t)
    # a camera publishes its camera_info with every image; the lifter uses the latest one
    for i in range(2, 7):
        graph.pub_camera_info.publish(info)
        answer = graph.send(frame(t, i * 10**9, [(-1, kp, c)]))
    (s,) = answer.skeletons.skeletons
    joints = m.skeleton3d_to_joints(s)
    z = fx * 0.4 / s.camera.scale
    centroid = [(s.camera.translation[0] - cx) * z / fx, (s.camera.translation[1] - cy) * z / fy, z]
    np.testing.assert_allclose(joints.mean(axis=0), centroid, rtol=tol.ROUND_OFF_ACCUMULATED)
    assert centroid[0] > 0 and centroid[1] < 0  # right of and above the principal point


# --------------------------------------------------------------------------- a committed bag, replayed

#: The committed bag replayed into the graph (see bags/README.md) and how many of its frames.
BAG = REPO / "bags" / "two_people.mcap"  # a walker (track 0) and a boxer (track 1), 2D noise
BAG_FRAMES = 8
#: The replay's error bands (P-MPJPE, MPJPE mm), measured with a margin, below the flat floor
#: (tests/tolerances.py NODE_REPLAY_TWO_PEOPLE_MM).
TWO_PEOPLE_BAND = (tol.measured_bound(tol.NODE_REPLAY_TWO_PEOPLE_MM[0], tol.NODE_REPLAY_TWO_PEOPLE_MM[2]),
                   tol.measured_bound(tol.NODE_REPLAY_TWO_PEOPLE_MM[1]))
#: Cold starts of the node in this test's paper mode (and of the offline lift it is compared with):
#: the band's setting (tests/offline/test_bags.py REPLAY; with n_refine=3 every start is refined).
N_STARTS = 3


def _to_rosbags(msg: Any, msgtype: str) -> Any:
    """An rclpy message as a rosbags one (CDR round trip), to write it with pose_lifter.offline.bags."""
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from rclpy.serialization import serialize_message

    return pose_lifter_typestore().deserialize_cdr(bytes(serialize_message(msg)), msgtype)


def test_bag_replay_answers_every_frame_like_the_offline_lift(
    start_lifter: Any, graph: GraphClient, tmp_path: Any
) -> None:
    from pose_lifter.core import Lifter, LifterOptions
    from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_GROUND_TRUTH, TOPIC_KEYPOINTS
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import BagWriter, read_messages
    from pose_lifter.offline.evaluate import evaluate_bag
    from pose_lifter.offline.lift import lift_messages
    from pose_lifter.offline.settings import LiftSettings

    store = pose_lifter_typestore()
    recorded = list(read_messages(BAG))
    keypoints = [x for x in recorded if x.topic == TOPIC_KEYPOINTS][:BAG_FRAMES]
    last = keypoints[-1].stamp_ns
    recorded = [x for x in recorded if x.stamp_ns <= last]
    camera_infos = [x for x in recorded if x.topic == TOPIC_CAMERA_INFO]
    assert camera_infos, "the bag has no camera_info"

    def raw(x: Any) -> bytes:  # replay the recorded bytes, as `ros2 bag play` would
        return bytes(store.serialize_cdr(x.msg, x.msgtype))

    lifter = start_lifter()
    graph.wait_for_lifter(lifter)
    t = graph.types
    # camera_info is best effort: wait until the lifter demonstrably uses it (an untracked probe)
    probe = frame(t, keypoints[0].stamp_ns - 10**9, [(-1, *coco_keypoints(STANDING, 30.0))],
                  frame_id="probe")
    for _ in range(50):
        graph.pub_camera_info.publish(raw(camera_infos[0]))
        graph.executor.spin_once(timeout_sec=0.05)
        (s,) = graph.send(probe).skeletons.skeletons
        if abs(m.skeleton3d_to_joints(s).mean(axis=0)[2] - 5.0) > 1e-6:  # not the default distance
            break
    else:
        pytest.fail("the lifter never used camera_info")

    def replay(n_frames: int) -> list[Any]:
        answers: list[Any] = []
        for x in recorded:
            if x.topic == TOPIC_CAMERA_INFO:
                graph.pub_camera_info.publish(raw(x))
            elif x.topic == TOPIC_KEYPOINTS and len(answers) < n_frames:
                answers.append(graph.send(raw(x)))
        return answers

    warm = replay(BAG_FRAMES)
    # the same frames again, every solve cold (the node's multi-start), changed live
    assert all(r.successful for r in graph.set_parameters(warm_start=False))
    cold = replay(BAG_FRAMES)

    # every frame answered, same stamp and frame, one Skeleton3D per input skeleton, no NaN
    for answers in (warm, cold):
        for a, x in zip(answers, keypoints, strict=True):
            assert m.stamp_to_ns(a.skeletons.header.stamp) == x.stamp_ns
            assert a.skeletons.header.frame_id == x.msg.header.frame_id
            assert [s.track_id for s in a.skeletons.skeletons] == [s.track_id for s in x.msg.skeletons]
            assert all_finite(a.skeletons)
            added = {mk.id for mk in a.markers.markers if mk.action == t.Marker.ADD}
            assert added == {s.track_id for s in x.msg.skeletons}

    # warm starts: every frame of a track after its first; they need fewer alternations than cold
    warm_flags = [[s.warm_started for s in a.skeletons.skeletons] for a in warm]
    assert not any(warm_flags[0]) and all(all(f) for f in warm_flags[1:])
    assert not any(s.warm_started for a in cold for s in a.skeletons.skeletons)
    assert len(warm) == len(cold) == BAG_FRAMES

    # the node computes what the offline lift computes (same options and bases, same warm starts)
    offline = lift_messages([(x.stamp_ns, x.msg) for x in keypoints],
                            [(x.stamp_ns, x.msg) for x in camera_infos],
                            Lifter(None, LifterOptions()), LiftSettings(smoothing_s=0.0))
    node_joints = np.array([m.skeleton3d_to_joints(s) for a in warm for s in a.skeletons.skeletons])
    np.testing.assert_allclose(node_joints, np.array([f.joints_m for f in offline]), atol=1e-6)
    # and publishes the offline lift's markers, message for message (one marker book for both;
    # from the second frame on: the node's book also saw this test's probe frames)
    from pose_lifter.offline.bags import read_raw
    from pose_lifter.offline.lift import lift_bag
    from rclpy.serialization import serialize_message

    lifted = tmp_path / "offline.mcap"
    lift_bag(BAG, lifted, Lifter(None, LifterOptions()),
             LiftSettings(smoothing_s=0.0, marker_lifetime=1.0, max_messages=BAG_FRAMES), progress=False)
    offline_markers = [r.data for r in read_raw(lifted, ["/skeleton_markers"])]
    kind = "visualization_msgs/msg/MarkerArray"
    assert len(offline_markers) == BAG_FRAMES
    for a, expected in list(zip(warm, offline_markers, strict=True))[1:]:
        # through rosbags: rclpy's serialiser leaves its padding bytes unset
        received = store.deserialize_cdr(bytes(serialize_message(a.markers)), kind)
        got = bytes(store.serialize_cdr(received, kind))
        assert got == expected

    # and its errors against the bag's ground truth: written next to it, evaluated offline
    out = tmp_path / "node_output.mcap"
    with BagWriter(out) as w:
        for x in recorded:
            if x.topic in (TOPIC_KEYPOINTS, TOPIC_GROUND_TRUTH, TOPIC_CAMERA_INFO):
                w.write(x.topic, x.stamp_ns, x.msg, x.msgtype)
        for a in warm:
            stamp = m.stamp_to_ns(a.skeletons.header.stamp)
            w.write("/skeletons_3d", stamp, _to_rosbags(a.skeletons, "pose_lifter_msgs/msg/Skeleton3DArray"),
                    "pose_lifter_msgs/msg/Skeleton3DArray")
    ev = evaluate_bag(out)
    assert ev.n_matched == sum(len(x.msg.skeletons) for x in keypoints)
    table = ev.table()
    assert table["lifter"]["p_mpjpe_mm"] < TWO_PEOPLE_BAND[0]
    assert table["lifter"]["mpjpe_mm"] < TWO_PEOPLE_BAND[1]
    assert table["lifter"]["p_mpjpe_mm"] < table["mean_pose_floor"]["p_mpjpe_mm"]

    # hybrid (default): every frame starts from the prior's pose, warm or cold, so warm starts
    # save only the camera's initialisation; the tracked answers stay those of single frames
    # within the bag's band (tracking no worse than single frames)
    node_cold = np.array([m.skeleton3d_to_joints(s) for a in cold for s in a.skeletons.skeletons])
    centred = [j - j.mean(axis=1, keepdims=True) for j in (node_joints, node_cold)]
    assert np.mean(np.linalg.norm(centred[0] - centred[1], axis=-1)) < 0.05  # metres

    # switched live to the paper's mode, the node takes the paper's packaged bases (bases_file is
    # empty) and forgets its tracks: it answers as the offline paper-mode lift does
    assert all(r.successful for r in graph.set_parameters(mode="paper", n_starts=N_STARTS, warm_start=True))
    paper = replay(BAG_FRAMES)
    paper_lifter = Lifter(None, LifterOptions(mode="paper", n_starts=N_STARTS))
    offline_paper = lift_messages([(x.stamp_ns, x.msg) for x in keypoints],
                                  [(x.stamp_ns, x.msg) for x in camera_infos], paper_lifter,
                                  LiftSettings(smoothing_s=0.0))
    node_paper = np.array([m.skeleton3d_to_joints(s) for a in paper for s in a.skeletons.skeletons])
    np.testing.assert_allclose(node_paper, np.array([f.joints_m for f in offline_paper]), atol=1e-6)
