"""A lifted skeleton as a REP-155 body (pose_lifter.messages.body / .hri), without ROS.

Checked: the TF chain lands on the joints; the joint angles through the URDF reproduce any
pose of a body whose torso and limb lengths are the URDF's (including straight limbs and the
arm hanging straight down, where the Euler angles are singular); the URDF is well formed with
REP-155's names; the messages (built with rosbags' classes) and the body book's comings and
goings.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest
from numpy.typing import NDArray
from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages import body, hri
from pose_lifter.messages.cdr import SkeletonFrame, header_cdr, stamp_cdr
from pose_lifter.messages.convert import skeleton3d_to_joints
from pose_lifter.messages.layouts import get_layout
from pose_lifter.offline.bags import read_messages

REPO = Path(__file__).resolve().parents[2]
HRI_MSG_DIR = REPO / "ros2_ws" / "vendor" / "hri_msgs" / "msg"
#: Composing exact transforms in float64: a few ulps of metres.
EXACT_M = 1e-9
#: The 12 joints' chains (root, middle, end), paper order.
CHAINS = ((0, 1, 2), (3, 4, 5), (6, 7, 8), (9, 10, 11))


def ground_truth_poses(n: int = 40) -> list[np.ndarray]:
    """Real mocap poses (metres, camera frame) from a committed bag's ground truth."""
    out = []
    for msg in read_messages(REPO / "bags" / "punch_clean.mcap", ["/ground_truth/skeletons_3d"]):
        out += [skeleton3d_to_joints(s) for s in msg.msg.skeletons]
        if len(out) >= n:
            break
    return out[:n]


def rigid_body_pose(rng: np.random.Generator, torso: np.ndarray, lengths: np.ndarray,
                    directions: np.ndarray | None = None) -> np.ndarray:
    """A pose (12, 3) with ``torso``'s shoulders and hips and the given segment lengths (8,), the
    segments along ``directions`` (8, 3) or random ones, then turned and moved at random."""
    if directions is None:
        directions = rng.normal(size=(8, 3))
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    joints = np.zeros((12, 3))
    k = 0
    for root, mid, end in CHAINS:
        joints[root] = torso[root]
        joints[mid] = joints[root] + lengths[k] * directions[k]
        joints[end] = joints[mid] + lengths[k + 1] * directions[k + 1]
        k += 2
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return joints @ q.T + rng.normal(size=3)


def joint_positions(frames: list[body.LinkTransform]) -> np.ndarray:
    composed = body.compose(frames)
    links = body.joint_link_names()
    return np.array([composed[links[n]][0] for n in JOINT_NAMES])


def test_tf_chain_lands_on_the_joints_and_frames_are_rotations() -> None:
    for joints in ground_truth_poses():
        frames = body.body_frames(joints)
        np.testing.assert_allclose(joint_positions(frames), joints, atol=EXACT_M)
        for f in frames:
            np.testing.assert_allclose(f.rotation @ f.rotation.T, np.eye(3), atol=EXACT_M)
            assert np.linalg.det(f.rotation) == pytest.approx(1.0)
        origin, rotation = body.compose(frames)["body"]
        np.testing.assert_allclose(origin, joints[[6, 9]].mean(axis=0), atol=EXACT_M)
        local = (joints - origin) @ rotation
        assert local[[0, 3], 2].min() > 0.2  # z up: the shoulders above the hips
        assert local[6, 1] > 0 > local[9, 1]  # y toward the left hip
        # each segment link's -z runs along its segment
        composed = body.compose(frames)
        for name, child in (("l_shoulder", 1), ("r_knee", 11)):
            pos, rot = composed[name]
            seg = joints[child] - pos
            np.testing.assert_allclose(-rot[:, 2], seg / np.linalg.norm(seg), atol=1e-9)


def test_angles_through_the_urdf_reproduce_a_body_of_the_urdf_s_proportions() -> None:
    rng = np.random.default_rng(0)
    # the URDF's torso: hips on the body's y axis, shoulders level above them (no twist)
    torso = np.zeros((12, 3))
    torso[[0, 3, 6, 9]] = [[0.0, 0.18, 0.5], [0.0, -0.17, 0.5], [0.0, 0.11, 0.0], [0.0, -0.1, 0.0]]
    lengths = np.array([0.30, 0.25, 0.31, 0.26, 0.45, 0.42, 0.44, 0.43])
    base = rigid_body_pose(rng, torso, lengths, np.tile([[0.0, 0.0, -1.0]], (8, 1)))
    dims = body.body_dimensions(base)
    origin, rotation = body.compose(body.body_frames(base))["body"]
    local_torso = (base - origin) @ rotation
    down = -rotation[:, 2]
    cases = [base, rigid_body_pose(rng, local_torso, lengths, np.tile(down @ rotation, (8, 1)))]
    cases += [rigid_body_pose(rng, local_torso, lengths) for _ in range(300)]
    for joints in cases:  # the URDF's body moved rigidly, its limbs anywhere (straight ones too)
        o, r = body.compose(body.body_frames(joints))["body"]
        fk = body.forward_kinematics(dims, body.joint_angles(joints))
        np.testing.assert_allclose(fk, (joints - o) @ r, atol=EXACT_M)


def test_real_poses_legs_exact_arms_off_by_the_torso_s_twist() -> None:
    """Real mocap bodies: the hips define the body frame, so the legs come back exactly; the
    shoulders (and the arms with them) are off by the torso's twist and lean against the URDF's
    rigid torso (the bound: the shoulder's own offset; the arms' directions are exact)."""
    poses = ground_truth_poses()
    dims = body.body_dimensions(poses[0])
    for joints in poses:
        o, r = body.compose(body.body_frames(joints))["body"]
        local = (joints - o) @ r
        fk = body.forward_kinematics(dims, body.joint_angles(joints))
        np.testing.assert_allclose(fk[6:], local[6:], atol=1e-6)
        for root, mid, end in CHAINS[:2]:
            offset = fk[root] - local[root]
            np.testing.assert_allclose(fk[[mid, end]] - offset, local[[mid, end]], atol=1e-6)


def test_urdf_has_rep155_names_and_the_body_s_dimensions() -> None:
    joints = ground_truth_poses(1)[0]
    dims = body.body_dimensions(joints)
    text = body.body_urdf("abcde", dims)
    root = ET.fromstring(text)
    links = {el.get("name") for el in root.iter("link")}
    joints_el = {el.get("name"): el for el in root.iter("joint")}
    revolute = {n for n, el in joints_el.items() if el.get("type") == "revolute"}
    assert revolute == {f"{n}_abcde" for n in body.REVOLUTE_JOINTS}
    assert {f"{n}_abcde" for n in ("body", "torso", "head", "l_wrist", "r_ankle", "l_y_shoulder")} <= links
    for el in joints_el.values():  # every joint links existing links
        assert el.find("parent").get("link") in links and el.find("child").get("link") in links
    # the elbow sits the upper arm's length below the shoulder link
    elbow = joints_el["l_elbow_abcde"].find("origin").get("xyz").split()
    assert float(elbow[2]) == pytest.approx(-np.linalg.norm(joints[1] - joints[0]), abs=1e-5)


def test_body_ids_are_stable_distinct_and_rep155_shaped() -> None:
    ids = [hri.body_id(i) for i in range(5000)]
    assert len(set(ids)) == len(ids)
    assert all(len(i) == 5 and i.isalpha() and i.islower() for i in ids)
    assert hri.body_id(42) == hri.body_id(42)
    assert hri.body_id(2**40) != hri.body_id(2**40 + 1)
    with pytest.raises(ValueError):
        hri.body_id(-1)


def _store() -> Any:
    """rosbags' Jazzy typestore with the vendored hri_msgs registered from their .msg text."""
    from pose_lifter.messages.typestore import register_msg_package
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    register_msg_package(store, "hri_msgs", HRI_MSG_DIR)
    return store


def test_cdr_bytes_are_rosbags_serialisation_of_the_same_messages() -> None:
    """The hand-written CDR of every REP-155 output equals rosbags' serialisation of the message
    built from the decoded fields, and decodes to what was written."""
    store = _store()
    joints = ground_truth_poses(1)[0]
    pose = body.body_pose(joints)
    points = np.column_stack([np.linspace(100, 400, 12), np.linspace(50, 350, 12)])
    conf = np.linspace(0.0, 1.0, 12)
    cases = {
        "hri_msgs/msg/IdsList": hri.ids_list_cdr(7 * 10**9 + 5, "cam", ["abcde", "xyz"]),
        "hri_msgs/msg/IdsList#empty": hri.ids_list_cdr(1, "", []),
        "tf2_msgs/msg/TFMessage": hri.tf_message_cdr(3, "camera_optical", [("abcde", pose), ("fghij", pose)]),
        "sensor_msgs/msg/JointState": hri.joint_state_cdr(3, "abcde", pose),
        "std_msgs/msg/String": hri.string_cdr(body.body_urdf("abcde", body.body_dimensions(joints))),
        "hri_msgs/msg/Skeleton2D": hri.skeleton2d_cdr(3, "cam", points, conf, (640.0, 480.0)),
        "hri_msgs/msg/NormalizedRegionOfInterest2D": hri.roi_cdr(3, "cam", points, conf, (640.0, 480.0)),
    }
    for key, data in cases.items():
        msgtype = key.split("#")[0]
        msg = store.deserialize_cdr(data, msgtype)
        assert bytes(store.serialize_cdr(msg, msgtype)) == data, msgtype
    tf = store.deserialize_cdr(cases["tf2_msgs/msg/TFMessage"], "tf2_msgs/msg/TFMessage")
    assert len(tf.transforms) == 2 * len(body.LINKS)
    first = tf.transforms[0]
    assert (first.header.frame_id, first.child_frame_id, first.header.stamp.nanosec) == (
        "camera_optical", "body_abcde", 3)
    js = store.deserialize_cdr(cases["sensor_msgs/msg/JointState"], "sensor_msgs/msg/JointState")
    assert list(js.name) == [f"{n}_abcde" for n in body.REVOLUTE_JOINTS]
    np.testing.assert_array_equal(js.position, pose.angles)


class Person(NamedTuple):
    """One lifted skeleton as a body book reads it."""

    track_id: int
    joints_m: NDArray[np.float64]  #: (12, 3) metres
    points: NDArray[np.float64]  #: (12, 2) pixels
    confidence: NDArray[np.float64]  #: (12,)


def _header(stamp_ns: int, frame_id: str) -> bytes:
    """A body book's header: the CDR of ``stamp_ns`` and ``frame_id``."""
    return header_cdr(stamp_cdr(stamp_ns), frame_id)


def bodies(people: Sequence[Person]) -> SkeletonFrame:
    """``people`` as the columns a body book reads (the fields it does not read zero)."""
    n, z = len(people), np.zeros
    return SkeletonFrame(np.array([p.track_id for p in people], dtype=np.int64),
                         np.array([p.joints_m for p in people], dtype=np.float64).reshape(n, 12, 3),
                         z((n, 6)), z(n), z((n, 4)), z((n, 2)), z(n), z(n), z(n, np.int64), z(n, bool), z(n),
                         z(n, bool), z((n, 12)),
                         np.array([p.points for p in people], dtype=np.float64).reshape(n, 12, 2),
                         np.array([p.confidence for p in people], dtype=np.float64).reshape(n, 12))


def crowd(rng: np.random.Generator, n: int) -> list[Person]:
    """``n`` plausible people: mocap poses turned and moved at random (metres, in front of the
    camera), their 2D input partly outside a 640 x 480 image (boxes clipped at 0 and 1), some
    joints missing; one person with no joint seen, one without shoulders (no neck), one with a
    -0.0 pixel coordinate."""
    poses = ground_truth_poses(n)
    out = []
    for k in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        joints = poses[k] @ q.T + rng.normal(scale=[2.0, 1.0, 0.5]) + [0.0, 0.0, 4.0]
        points = rng.uniform([-60.0, -40.0], [700.0, 520.0], size=(12, 2))
        conf = np.where(rng.random(12) < 0.2, 0.0, rng.uniform(0.05, 1.0, 12))
        if k == 1:
            conf[:] = 0.0
        elif k == 2:
            conf[[0, 3]] = 0.0
        elif k == 3:
            points[4, 0], conf[4] = -0.0, 0.7
        out.append(Person(100 + 7 * k, joints, points, conf))
    return out


def expected_messages(store: Any, stamp_ns: int, frame_id: str, people: list[Person],
                      image_size: tuple[float, float] | None, ids: list[str],
                      new: set[str]) -> dict[str, tuple[Any, str]]:
    """Every message of a body book's frame of ``people`` (all tracked, none degenerate) built as
    rosbags objects from their definitions: {topic: (message, type)}."""
    t = store.types
    sec, nanosec = divmod(stamp_ns, 10**9)

    def header(frame: str) -> Any:
        return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                        frame_id=frame)

    coco = get_layout("coco18").model_indices
    poses = body.body_poses(np.stack([p.joints_m for p in people]))
    out: dict[str, tuple[Any, str]] = {}
    transforms = []
    for person, pose in zip(people, poses, strict=True):
        assert pose is not None
        bid = hri.body_id(person.track_id)
        ns = f"{hri.BODIES_NS}/{bid}"
        if bid in new:
            urdf = body.body_urdf(bid, body.body_dimensions(person.joints_m))
            out[f"{ns}/urdf"] = (t["std_msgs/msg/String"](data=urdf), "std_msgs/msg/String")
        out[f"{ns}/joint_states"] = (t["sensor_msgs/msg/JointState"](
            header=header(""), name=[f"{n}_{bid}" for n in body.REVOLUTE_JOINTS],
            position=np.array(pose.angles), velocity=np.zeros(0), effort=np.zeros(0)),
            "sensor_msgs/msg/JointState")
        for (parent, child), tr, q in zip(body.LINKS, pose.translations, pose.quaternions, strict=True):
            transforms.append(t["geometry_msgs/msg/TransformStamped"](
                header=header(f"{parent}_{bid}" if parent else frame_id), child_frame_id=f"{child}_{bid}",
                transform=t["geometry_msgs/msg/Transform"](
                    translation=t["geometry_msgs/msg/Vector3"](x=tr[0], y=tr[1], z=tr[2]),
                    rotation=t["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))))
        if image_size is None:
            continue
        norm = np.clip(person.points / np.array(image_size), 0.0, 1.0)
        xyc = np.zeros((18, 3))
        for j, slot in enumerate(coco):
            xyc[slot] = [norm[j, 0], norm[j, 1], person.confidence[j]]
        if person.confidence[0] > 0 and person.confidence[3] > 0:  # the neck: the shoulders' midpoint
            xyc[1] = [*(0.5 * (norm[0] + norm[3])), min(person.confidence[0], person.confidence[3])]
        point = t["hri_msgs/msg/NormalizedPointOfInterest2D"]
        out[f"{ns}/skeleton2d"] = (t["hri_msgs/msg/Skeleton2D"](
            header=header(frame_id), skeleton=[point(x=x, y=y, c=c) for x, y, c in xyc]),
            "hri_msgs/msg/Skeleton2D")
        seen = person.confidence > 0
        box = [0.0] * 5
        if seen.any():
            lo, hi = norm[seen].min(axis=0), norm[seen].max(axis=0)
            box = [lo[0], lo[1], hi[0], hi[1], np.mean(person.confidence[seen])]
        out[f"{ns}/roi"] = (t["hri_msgs/msg/NormalizedRegionOfInterest2D"](
            header(frame_id), *box), "hri_msgs/msg/NormalizedRegionOfInterest2D")
    out[hri.TF_TOPIC] = (t["tf2_msgs/msg/TFMessage"](transforms=transforms), "tf2_msgs/msg/TFMessage")
    out[f"{hri.BODIES_NS}/tracked"] = (t["hri_msgs/msg/IdsList"](header=header(frame_id), ids=ids),
                                       "hri_msgs/msg/IdsList")
    return out


def test_crowd_frames_are_rosbags_serialisation_of_messages_built_from_their_fields() -> None:
    """A body book's frames of 30 people, with and without the image size, the input's frame id
    of every length mod 8 (the padding of the headers and of each body's first transform moves
    with it): every message's bytes are rosbags' serialisation of the message built as objects
    from the bodies' fields, so a wrong offset, padding or value fails."""
    store = _store()
    rng = np.random.default_rng(155)
    people = crowd(rng, 30)
    for length in range(10):
        frame_id = "abcdefghi"[:length]
        book = hri.BodyBook(timeout_s=10.0)
        alive: set[str] = set()
        steps = [(people, (640.0, 480.0)), (people[::-1][:25], None), (people[5:], (1280, 720))]
        for step, (shown, size) in enumerate(steps):
            stamp_ns = 1_700_000_000 * 10**9 + 123_456_789 * step + length
            out = book.frame(stamp_ns, _header(stamp_ns, frame_id), bodies(shown), size)
            bids = [hri.body_id(p.track_id) for p in shown]
            new = set(bids) - alive
            alive |= new
            expected = expected_messages(store, stamp_ns, frame_id, list(shown), size, sorted(alive), new)
            got = {topic: (data, msgtype) for topic, data, msgtype in out.messages()}
            assert set(got) == set(expected), (length, step)
            for topic, (data, msgtype) in got.items():
                msg, expected_type = expected[topic]
                assert msgtype == expected_type
                assert bytes(store.serialize_cdr(msg, msgtype)) == data, (length, step, topic)


def test_book_messages_and_bodies_coming_and_going() -> None:
    store = _store()
    book = hri.BodyBook(timeout_s=0.5)
    poses = ground_truth_poses(3)
    coco = get_layout("coco18").model_indices
    points = np.column_stack([np.linspace(100, 400, 12), np.linspace(50, 350, 12)])
    conf = np.full(12, 0.8)
    conf[2] = 0.0  # the left wrist is missing

    def lifted(tid: int, k: int) -> Person:
        return Person(tid, poses[k], points, conf)

    def decode(data: bytes, name: str) -> Any:
        return store.deserialize_cdr(data, name)

    out = book.frame(10**9, _header(10**9, "cam"), bodies([lifted(3, 0), lifted(8, 1), lifted(-1, 2)]),
                     (640.0, 480.0))
    a, b = hri.body_id(3), hri.body_id(8)
    tracked = decode(out.tracked, "hri_msgs/msg/IdsList")
    assert sorted(tracked.ids) == sorted([a, b]) and set(out.new) == {a, b} and out.gone == []
    urdf = decode(out.new[a], "std_msgs/msg/String").data
    assert "<robot" in urdf and f"l_elbow_{a}" in urdf
    js = decode(out.bodies[a]["joint_states"], "sensor_msgs/msg/JointState")
    assert js.name[0] == f"waist_{a}" and len(js.name) == len(body.REVOLUTE_JOINTS) == len(js.position)
    sk = decode(out.bodies[a]["skeleton2d"], "hri_msgs/msg/Skeleton2D")
    assert len(sk.skeleton) == 18
    left_elbow = sk.skeleton[coco[1]]
    assert (left_elbow.x, left_elbow.y, left_elbow.c) == pytest.approx(
        (points[1, 0] / 640, points[1, 1] / 480, 0.8))
    assert sk.skeleton[coco[2]].c == 0.0  # missing stays missing
    neck = sk.skeleton[1]
    assert neck.x == pytest.approx((points[0, 0] + points[3, 0]) / 2 / 640)
    tf = decode(out.tf, "tf2_msgs/msg/TFMessage")
    roots = {tr.header.frame_id for tr in tf.transforms if tr.child_frame_id.startswith("body_")}
    assert roots == {"cam"}
    box = decode(out.bodies[b]["roi"], "hri_msgs/msg/NormalizedRegionOfInterest2D")
    seen = points[conf > 0]
    assert (box.xmin, box.ymax) == pytest.approx((seen[:, 0].min() / 640, seen[:, 1].max() / 480))

    # track 8 stops: still tracked within the timeout, gone after it; no URDF twice
    out = book.frame(int(1.4e9), _header(int(1.4e9), "cam"), bodies([lifted(3, 0)]), None)
    assert sorted(decode(out.tracked, "hri_msgs/msg/IdsList").ids) == sorted([a, b])
    assert out.new == {} and set(out.bodies) == {a}
    assert "skeleton2d" not in out.bodies[a]  # no image size: no normalised 2D
    out = book.frame(int(1.6e9), _header(int(1.6e9), "cam"), bodies([lifted(3, 0)]), None)
    assert list(decode(out.tracked, "hri_msgs/msg/IdsList").ids) == [a] and out.gone == [b]
    assert not any(tr.child_frame_id.endswith(b)
                   for tr in decode(out.tf, "tf2_msgs/msg/TFMessage").transforms)
    out = book.frame(int(3.0e9), _header(int(3.0e9), "cam"), bodies([]), None)
    assert list(decode(out.tracked, "hri_msgs/msg/IdsList").ids) == [] and out.gone == [a] and out.tf is None
    # a degenerate skeleton (both hips at one point) has no body, the frame goes on
    flat = poses[0].copy()
    flat[9] = flat[6]
    out = book.frame(int(3.1e9), _header(int(3.1e9), "cam"), bodies([Person(5, flat, points, conf)]), None)
    assert out.tf is None and len(book) == 0
