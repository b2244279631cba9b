"""REP-155 bodies and TF from the installed ``lifter`` on a real graph.

A subscriber in the test process, with the real message types (``hri_msgs``, ``tf2_msgs``,
``sensor_msgs``, ``std_msgs``), receives ``/humans/bodies/tracked``, ``/tf``, each body's
``joint_states`` and latched ``urdf`` (also when it joins late), ``skeleton2d`` and ``roi``, and
sees the bodies leave with their tracks. The TF frames are composed up to the camera frame and
compared with ``skeletons_3d``; the URDF is parsed here (its own forward kinematics, not the
package's) and driven by the published joint states.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pytest
from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages import convert as m
from pose_lifter.messages.hri import body_id
from scipy.spatial.transform import Rotation

from .conftest import GraphClient, _load_workspace_messages
from .test_lifter_graph import CHEAP, STANDING, coco_keypoints, frame

pytestmark = pytest.mark.ros

#: TF composed to the camera frame lands on skeletons_3d's joints within this (metres).
TF_TOLERANCE_M = 1e-3
#: The URDF's forward kinematics of the joint states points every limb segment along the
#: published joints' segment (unit vectors within this; the URDF's numbers have 6 digits).
URDF_DIRECTION_TOLERANCE = 1e-4
#: The URDF is the body's first frame, rigid: its FK reproduces a later frame's joints up to
#: the shoulder's / hip's offset from the URDF's plus the segments' length changes (the triangle
#: inequality along the chain), within this (metres).
URDF_FK_SLACK_M = 1e-3
#: The chains (root, middle, end) of the 12 joints, paper order.
CHAINS = ((0, 1, 2), (3, 4, 5), (6, 7, 8), (9, 10, 11))
#: The joint link of each of the 12 joints (REP-155 names, without the id suffix).
JOINT_LINKS = {"left_shoulder": "l_shoulder", "left_elbow": "l_elbow", "left_wrist": "l_wrist",
               "right_shoulder": "r_shoulder", "right_elbow": "r_elbow", "right_wrist": "r_wrist",
               "left_hip": "l_hip", "left_knee": "l_knee", "left_ankle": "l_ankle",
               "right_hip": "r_hip", "right_knee": "r_knee", "right_ankle": "r_ankle"}


def compose_tf(transforms: list[Any], root: str) -> dict[str, np.ndarray]:
    """Each child frame's 4x4 pose in ``root`` from a flat list of TransformStamped."""
    edges = {t.child_frame_id: t for t in transforms}
    out: dict[str, np.ndarray] = {root: np.eye(4)}

    def pose(name: str) -> np.ndarray:
        if name not in out:
            t = edges[name]
            q = t.transform.rotation
            local = np.eye(4)
            local[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
            v = t.transform.translation
            local[:3, 3] = [v.x, v.y, v.z]
            out[name] = pose(t.header.frame_id) @ local
        return out[name]

    for child in edges:
        pose(child)
    return out


def urdf_link_positions(urdf: str, positions: dict[str, float]) -> dict[str, np.ndarray]:
    """Every link's origin in the URDF's root link, for the given joint positions (radians):
    URDF semantics, child = parent · origin(xyz, rpy) · rotation(axis, q) for revolute joints."""
    root = ET.fromstring(urdf)
    joints = {}
    for j in root.iter("joint"):
        origin = j.find("origin")
        xyz = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
        rpy = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
        axis_el = j.find("axis")
        axis = [float(v) for v in axis_el.get("xyz").split()] if axis_el is not None else [1.0, 0.0, 0.0]
        joints[j.find("child").get("link")] = (j.get("name"), j.get("type"), j.find("parent").get("link"),
                                               np.array(xyz), rpy, np.array(axis))
    out: dict[str, np.ndarray] = {}

    def pose(link: str) -> np.ndarray:
        if link in out:
            return out[link]
        if link not in joints:
            out[link] = np.eye(4)
            return out[link]
        name, kind, parent, xyz, rpy, axis = joints[link]
        local = np.eye(4)
        local[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
        local[:3, 3] = xyz
        if kind == "revolute":
            turn = np.eye(4)
            turn[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * positions[name]).as_matrix()
            local = local @ turn
        out[link] = pose(parent) @ local
        return out[link]

    for link in [el.get("name") for el in root.iter("link")]:
        pose(link)
    return out


def test_rep155_bodies_tf_joint_states_urdf_and_leaving(start_lifter: Any, graph: GraphClient) -> None:
    for package in ("hri_msgs", "tf2_msgs"):
        _load_workspace_messages(package)
    from hri_msgs.msg import IdsList, NormalizedRegionOfInterest2D, Skeleton2D
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    lifter = start_lifter(params={**CHEAP, "track_timeout": 0.5})
    graph.wait_for_lifter(lifter)
    node, t = graph.node, graph.types
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    tracked: list[Any] = []
    tf: list[Any] = []
    node.create_subscription(IdsList, "/humans/bodies/tracked", tracked.append, reliable)
    node.create_subscription(TFMessage, "/tf", tf.append, reliable)
    graph.spin_until(lambda: all(node.count_publishers(topic) > 0
                                 for topic in ("/humans/bodies/tracked", "/tf")),
                     60.0, "the lifter's REP-155 publishers")

    ids = {4: body_id(4), 9: body_id(9)}
    assert len(set(ids.values())) == 2 and all(len(i) == 5 and i.isalpha() for i in ids.values())
    info = m.camera_info(m.make_header(10**9, "camera_optical", t), 640, 480, 500.0, 500.0, 320.0, 240.0, t)
    kp, c = coco_keypoints(STANDING, 30.0)
    kp2 = kp + np.array([150.0, 0.0])
    per_body: dict[str, dict[str, list[Any]]] = {}

    def listen(bid: str) -> None:
        per_body[bid] = {"joint_states": [], "skeleton2d": [], "roi": []}
        for kind, cls in (("joint_states", JointState), ("skeleton2d", Skeleton2D),
                          ("roi", NormalizedRegionOfInterest2D)):
            node.create_subscription(cls, f"/humans/bodies/{bid}/{kind}", per_body[bid][kind].append,
                                     reliable)

    answers = []
    for i in range(1, 7):
        graph.pub_camera_info.publish(info)
        answers.append(graph.send(frame(t, 10**9 + i * 10**8, [(4, kp, c), (9, kp2, c), (-1, kp, c)])))
        if i == 1:  # the per-body topics exist once the bodies appeared
            for bid in ids.values():
                listen(bid)
            graph.spin_until(lambda: all(node.count_publishers(f"/humans/bodies/{b}/joint_states") > 0
                                         for b in ids.values()), 60.0, "the per-body publishers")
    last = answers[-1].skeletons
    stamp = m.stamp_to_ns(last.header.stamp)
    def at(messages: list[Any], ns: int) -> list[Any]:
        return [x for x in messages if m.stamp_to_ns(x.header.stamp) == ns]

    graph.spin_until(lambda: at(tracked, stamp) and any(at(x.transforms, stamp) for x in tf)
                     and all(at(per_body[b]["joint_states"], stamp) and at(per_body[b]["roi"], stamp)
                             for b in ids.values()), 60.0, "the REP-155 messages of the last frame")
    (now,) = at(tracked, stamp)
    assert sorted(now.ids) == sorted(ids.values())  # the untracked skeleton has no body

    # TF: body_<id> under the input's frame, the joint links on skeletons_3d's joints
    (frames,) = [x for x in tf if at(x.transforms, stamp)]
    poses = compose_tf(list(frames.transforms), "camera_optical")
    for s in last.skeletons:
        if s.track_id < 0:
            continue
        bid = ids[int(s.track_id)]
        joints = m.skeleton3d_to_joints(s)
        got = np.array([poses[f"{JOINT_LINKS[n]}_{bid}"][:3, 3] for n in JOINT_NAMES])
        np.testing.assert_allclose(got, joints, atol=TF_TOLERANCE_M)
        body_pose = poses[f"body_{bid}"]
        np.testing.assert_allclose(body_pose[:3, 3], joints[[6, 9]].mean(axis=0), atol=TF_TOLERANCE_M)
        # z up along the torso: the shoulders are above the hips in the body frame
        local = (joints - body_pose[:3, 3]) @ body_pose[:3, :3]
        assert local[[0, 3], 2].min() > local[[6, 9], 2].max()

        # the URDF, to a subscriber that joins late (latched), through its own kinematics
        urdfs: list[Any] = []
        node.create_subscription(String, f"/humans/bodies/{bid}/urdf", urdfs.append, latched)
        graph.spin_until(lambda got=urdfs: bool(got), 60.0, f"the latched URDF of body {bid}")
        (state,) = at(per_body[bid]["joint_states"], stamp)
        assert all(n.endswith(f"_{bid}") for n in state.name)
        assert {"l_elbow", "r_knee", "l_y_shoulder", "r_p_hip", "waist", "y_head"} <= {
            n[: -len(bid) - 1] for n in state.name}
        links = urdf_link_positions(urdfs[0].data, dict(zip(state.name, state.position, strict=True)))
        fk = np.array([links[f"{JOINT_LINKS[n]}_{bid}"][:3, 3] for n in JOINT_NAMES])
        for root, mid, end in CHAINS:
            for a, b in ((root, mid), (mid, end)):
                want = (local[b] - local[a]) / np.linalg.norm(local[b] - local[a])
                np.testing.assert_allclose((fk[b] - fk[a]) / np.linalg.norm(fk[b] - fk[a]), want,
                                           atol=URDF_DIRECTION_TOLERANCE)
            slack = np.linalg.norm(fk[root] - local[root]) + URDF_FK_SLACK_M
            for a, b in ((root, mid), (mid, end)):
                slack += abs(np.linalg.norm(fk[b] - fk[a]) - np.linalg.norm(local[b] - local[a]))
                assert np.linalg.norm(fk[b] - local[b]) <= slack

        # the 2D: normalised by camera_info's image size, in the OpenPose-COCO order
        (sk2d,) = at(per_body[bid]["skeleton2d"], stamp)
        assert len(sk2d.skeleton) == 18
        src = kp if s.track_id == 4 else kp2
        left_wrist = sk2d.skeleton[Skeleton2D.LEFT_WRIST]
        np.testing.assert_allclose([left_wrist.x * 640, left_wrist.y * 480], src[9], atol=1e-3)
        (box,) = at(per_body[bid]["roi"], stamp)
        assert 0 <= box.xmin < box.xmax <= 1 and 0 <= box.ymin < box.ymax <= 1

    # track 9 stops; after track_timeout it leaves `tracked` and its topics go
    gone = ids[9]
    for i in range(7, 15):
        answer = graph.send(frame(t, 10**9 + i * 10**8, [(4, kp, c)]))
    stamp = m.stamp_to_ns(answer.skeletons.header.stamp)
    graph.spin_until(lambda: at(tracked, stamp) and any(at(x.transforms, stamp) for x in tf), 60.0,
                     "tracked and /tf of the last frame")
    (now,) = at(tracked, stamp)
    assert list(now.ids) == [ids[4]]
    graph.spin_until(lambda: node.count_publishers(f"/humans/bodies/{gone}/joint_states") == 0, 60.0,
                     "the departed body's topics to go")
    assert node.count_publishers(f"/humans/bodies/{ids[4]}/joint_states") > 0
    late = [x for x in tf if at(x.transforms, stamp)]
    assert late and not any(tr.child_frame_id.endswith(f"_{gone}") for x in late for tr in x.transforms)


def test_publish_hri_off(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params={**CHEAP, "publish_hri": False})
    graph.wait_for_lifter(lifter)
    kp, c = coco_keypoints(STANDING, 30.0)
    graph.send(frame(graph.types, 10**9, [(4, kp, c)]))
    assert graph.node.count_publishers("/humans/bodies/tracked") == 0
    assert graph.node.count_publishers("/tf") == 0
