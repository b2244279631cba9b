"""pose_lifter.messages.convert with rosbags message classes (CDR round trips through our typestore)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core.errors import InvalidInputError, UnknownLayoutError
from pose_lifter.core.model.skeleton import BONES_FOR_DRAWING, JOINT_NAMES
from pose_lifter.core.results import Camera, LiftResult
from pose_lifter.core.track.placement import place_in_camera
from pose_lifter.messages import convert as m
from pose_lifter.messages.layouts import frame_joints, get_layout
from pose_lifter.messages.typestore import pose_lifter_typestore
from scipy.spatial.transform import Rotation

T = m.rosbags_types()


def roundtrip(msg: object, msgtype: str) -> object:
    store = pose_lifter_typestore()
    return store.deserialize_cdr(store.serialize_cdr(msg, msgtype), msgtype)


def fake_result(rotation: np.ndarray, scale: float, translation: np.ndarray, seed: int = 0) -> LiftResult:
    rng = np.random.default_rng(seed)
    pose = rng.normal(size=(12, 3))
    pose -= pose.mean(axis=0)
    cam = Camera(rotation, scale, translation)
    return LiftResult(
        pose=pose, pose_camera=pose @ rotation.T, camera=cam, alpha=np.zeros(5), objective=1.5,
        reprojection_error=2.5, limb_violation=0.0, n_iter=7, converged=True, n_starts=3,
        start_index=1, weights=np.ones(12), total_alternations=19,
    )


def test_skeleton2d_roundtrip_selects_model_joints() -> None:
    rng = np.random.default_rng(1)
    kp = rng.uniform(0, 640, size=(17, 2))
    conf = rng.uniform(0.2, 1.0, size=17)
    msg = m.arrays_to_skeleton2d(kp, conf, track_id=4, types=T)
    arr = m.skeleton2d_array(m.make_header(123_000_000_456, "cam", T), "coco17", [msg], T)
    back = roundtrip(arr, "pose_lifter_msgs/msg/Skeleton2DArray")
    assert back.layout == "coco17" and back.header.stamp.sec == 123 and back.header.stamp.nanosec == 456
    assert m.stamp_to_ns(back.header.stamp) == 123_000_000_456
    pts, c = m.skeleton2d_to_arrays(back.skeletons[0], back.layout)
    idx = list(get_layout("coco17").model_indices)
    np.testing.assert_allclose(pts, kp[idx])
    np.testing.assert_allclose(c, conf[idx].astype(np.float32), rtol=tol.FLOAT32_REL)  # float32 on the wire
    assert back.skeletons[0].track_id == 4


def test_skeleton2d_bad_input() -> None:
    kp = np.zeros((17, 2))
    conf = np.ones(17)
    msg = m.arrays_to_skeleton2d(kp, conf, 0, T)
    with pytest.raises(UnknownLayoutError):
        m.skeleton2d_to_arrays(msg, "coco19")
    with pytest.raises(InvalidInputError):
        m.skeleton2d_to_arrays(msg, "body25")  # 17 keypoints for a 25-keypoint layout
    kp_nan = kp.copy()
    kp_nan[5] = np.nan  # left shoulder, visible
    with pytest.raises(InvalidInputError, match="left_shoulder"):
        m.skeleton2d_to_arrays(m.arrays_to_skeleton2d(kp_nan, conf, 0, T), "coco17")
    conf_missing = conf.copy()
    conf_missing[5] = 0.0  # the same NaN on a missing joint is fine
    pts, c = m.skeleton2d_to_arrays(m.arrays_to_skeleton2d(kp_nan, conf_missing, 0, T), "coco17")
    assert np.all(np.isfinite(pts)) and c[0] == 0.0
    kp_nose = kp.copy()
    kp_nose[0] = np.inf  # not a model joint: ignored
    m.skeleton2d_to_arrays(m.arrays_to_skeleton2d(kp_nose, conf, 0, T), "coco17")


def test_place_in_camera_recovers_metric_position() -> None:
    # a person whose centroid is at (0.4, -0.2, 5.0) m, right lower leg 0.45 m, seen by a
    # pinhole camera: the weak-perspective camera of that view has scale f * leg / Z and
    # translation = the projected centroid
    fx, fy, cx, cy = 500.0, 520.0, 320.0, 240.0
    leg, centroid = 0.45, np.array([0.4, -0.2, 5.0])
    rot = Rotation.from_euler("xyz", [170, 20, 5], degrees=True).as_matrix()
    f = 0.5 * (fx + fy)
    t = np.array([fx * centroid[0] / centroid[2] + cx, fy * centroid[1] / centroid[2] + cy])
    res = fake_result(rot, f * leg / centroid[2], t)
    joints = place_in_camera(res, leg, (fx, fy), (cx, cy), default_distance_m=3.0)
    np.testing.assert_allclose(joints.mean(axis=0), centroid, atol=tol.ROUND_OFF)
    # the pose seen along the ray to its centroid, turned into the camera frame
    from pose_lifter.core.track.placement import ray_rotation

    turn = ray_rotation(centroid)
    ray = centroid / np.linalg.norm(centroid)
    np.testing.assert_allclose(turn @ [0.0, 0.0, 1.0], ray, atol=tol.ROUND_OFF)
    np.testing.assert_allclose(turn @ turn.T, np.eye(3), atol=tol.ROUND_OFF)
    assert np.linalg.det(turn) == pytest.approx(1.0, abs=tol.ROUND_OFF)
    np.testing.assert_allclose(joints - joints.mean(axis=0), res.pose_camera @ turn.T * leg,
                               atol=tol.ROUND_OFF)
    np.testing.assert_allclose(ray_rotation(np.array([0.0, 0.0, 4.0])), np.eye(3), atol=tol.ROUND_OFF)
    # no principal point: on the optical axis at the same depth
    np.testing.assert_allclose(place_in_camera(res, leg, (fx, fy), None, 3.0).mean(axis=0), [0, 0, 5.0],
                               atol=tol.ROUND_OFF)
    # no camera info: the default distance
    np.testing.assert_allclose(place_in_camera(res, leg, None, None, 3.0).mean(axis=0), [0, 0, 3.0],
                               atol=tol.ROUND_OFF)
    with pytest.raises(InvalidInputError):
        place_in_camera(res, -1.0, None, None, 3.0)
    with pytest.raises(InvalidInputError):
        place_in_camera(fake_result(rot, 0.0, t), leg, (fx, fy), (cx, cy), 3.0)


def test_place_poses_places_a_crowd_as_each_alone() -> None:
    """The people of a frame placed in one pass are placed as each alone: the centroid from the
    pinhole model, the pose turned by the smallest rotation from the optical axis onto the ray
    to it (an axis perpendicular to both), a person on the axis not turned; and a scale not
    > 0 refused. Through :func:`place_lifted`, that refusal costs only its own person."""
    from pose_lifter.core.track.placement import place_poses
    from pose_lifter.core.track.policy import TrackedLift
    from pose_lifter.messages.frame import FrameSettings, SkeletonInput, SkipSkeleton, place_lifted

    fx, fy, cx, cy, leg = 600.0, 580.0, 320.0, 240.0, 0.43
    rng = np.random.default_rng(4)
    n = 7
    rots = Rotation.random(n, random_state=5).as_matrix()
    scales = rng.uniform(40.0, 200.0, size=n)
    trans = rng.uniform(0.0, 640.0, size=(n, 2))
    trans[3] = [cx, cy]  # on the optical axis
    results = [fake_result(rots[i], float(scales[i]), trans[i], seed=i) for i in range(n)]
    poses = np.array([r.pose_camera for r in results])
    joints = place_poses(poses, scales, trans, leg, (fx, fy), (cx, cy), 5.0)
    assert joints.shape == (n, 12, 3)
    z_axis = np.array([0.0, 0.0, 1.0])
    for i in range(n):
        np.testing.assert_array_equal(joints[i], place_in_camera(results[i], leg, (fx, fy), (cx, cy), 5.0))
        z = 0.5 * (fx + fy) * leg / scales[i]
        centroid = np.array([(trans[i, 0] - cx) * z / fx, (trans[i, 1] - cy) * z / fy, z])
        np.testing.assert_allclose(joints[i].mean(axis=0), centroid, atol=tol.ROUND_OFF)
        # the turn: local -> joints - centroid, found by least squares from the 12 joints
        local = poses[i] * leg
        turn = np.linalg.lstsq(local, joints[i] - centroid, rcond=None)[0].T
        ray = centroid / np.linalg.norm(centroid)
        np.testing.assert_allclose(turn @ z_axis, ray, atol=tol.ROUND_OFF)
        np.testing.assert_allclose(turn @ turn.T, np.eye(3), atol=tol.ROUND_OFF)
        axis = np.cross(z_axis, ray)
        np.testing.assert_allclose(turn @ axis, axis, atol=tol.ROUND_OFF)  # turned about it
        if i == 3:
            np.testing.assert_allclose(turn, np.eye(3), atol=tol.ROUND_OFF)
    np.testing.assert_allclose(place_poses(poses, scales, trans, leg, None, None, 4.0).mean(axis=1),
                               np.tile([0.0, 0.0, 4.0], (n, 1)), atol=tol.ROUND_OFF)
    bad = scales.copy()
    bad[2] = 0.0
    with pytest.raises(InvalidInputError, match="scale"):
        place_poses(poses, bad, trans, leg, (fx, fy), (cx, cy), 5.0)
    # in the frame pipeline, the person with the bad scale is refused and the others placed
    solved = [(SkeletonInput(i, np.zeros((12, 2)), np.ones(12)),
               TrackedLift(fake_result(rots[i], float(bad[i]), trans[i], seed=i), False, False))
              for i in range(n)]
    out = place_lifted([(FrameSettings(lower_leg_length=leg), ((fx, fy), (cx, cy)), *s) for s in solved])
    assert [isinstance(o, SkipSkeleton) for o in out] == [i == 2 for i in range(n)]
    for i, o in enumerate(out):
        if i != 2:
            assert not isinstance(o, SkipSkeleton) and o.track_id == i
            np.testing.assert_array_equal(o.joints_m, joints[i])


def test_result_to_skeleton3d_fields_and_inverse() -> None:
    rot = Rotation.from_euler("zyx", [30, -60, 100], degrees=True).as_matrix()
    res = fake_result(rot, 80.0, np.array([300.0, 200.0]))
    joints = np.arange(36, dtype=float).reshape(12, 3) / 10
    msg = m.result_to_skeleton3d(res, 7, joints, T, solve_time=0.01, warm_started=True)
    arr = m.skeletons3d_array(m.make_header(5, "camera_optical", T), [msg], T)
    back = roundtrip(arr, "pose_lifter_msgs/msg/Skeleton3DArray").skeletons[0]
    assert back.track_id == 7 and list(back.joint_names) == list(JOINT_NAMES)
    assert back.iterations == 19 and back.converged and back.warm_started
    assert back.objective == 1.5 and back.reprojection_error == 2.5 and back.solve_time == 0.01
    np.testing.assert_allclose(m.skeleton3d_to_joints(back), joints)
    np.testing.assert_allclose(np.asarray(back.camera.projection).reshape(2, 3), 80.0 * rot[:2])
    q = back.camera.orientation
    np.testing.assert_allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), rot, atol=tol.ROUND_OFF)
    assert back.camera.scale == 80.0
    np.testing.assert_allclose(back.camera.translation, [300.0, 200.0])
    assert list(back.observed) == [bool(w > 0) for w in res.weights]
    np.testing.assert_allclose(back.joint_weights, res.weights, rtol=tol.FLOAT32_REL)


def test_skeleton3d_to_joints_reorders_by_name() -> None:
    joints = np.arange(36, dtype=float).reshape(12, 3)
    msg = m.skeleton3d_from_joints(0, joints, T)
    perm = np.random.default_rng(0).permutation(12)
    msg.joint_names = [JOINT_NAMES[i] for i in perm]
    msg.joints = [msg.joints[i] for i in perm]
    np.testing.assert_allclose(m.skeleton3d_to_joints(msg), joints)
    msg.joint_names = msg.joint_names[:-1]
    with pytest.raises(InvalidInputError):
        m.skeleton3d_to_joints(msg)


def test_joint_std_round_trips_reorders_by_name_and_is_nan_where_unknown() -> None:
    """``joint_std`` through rosbags' CDR comes back as written (float64, bit for bit), in the core
    order when the message lists its joints in another order; an empty field, ground truth and a
    message of the definition before the field (no attribute) read as NaN; a bad std is refused
    with one line."""
    res = fake_result(np.eye(3), 80.0, np.array([300.0, 200.0]))
    rng = np.random.default_rng(4)
    joints, std = rng.normal(size=(12, 3)), rng.uniform(0.01, 0.3, size=(12, 3))
    msg = m.result_to_skeleton3d(res, 7, joints, T, std_m=std)
    arr = m.skeletons3d_array(m.make_header(5, "cam", T), [msg, m.result_to_skeleton3d(res, 8, joints, T)], T)
    with_std, without = roundtrip(arr, "pose_lifter_msgs/msg/Skeleton3DArray").skeletons
    assert np.array_equal(m.skeleton3d_to_std(with_std), std)
    assert len(without.joint_std) == 0 and np.isnan(m.skeleton3d_to_std(without)).all()
    assert len(m.skeleton3d_from_joints(0, joints, T).joint_std) == 0
    perm = rng.permutation(12)
    with_std.joint_names = [JOINT_NAMES[i] for i in perm]
    with_std.joints = [with_std.joints[i] for i in perm]
    with_std.joint_std = [with_std.joint_std[i] for i in perm]
    np.testing.assert_array_equal(m.skeleton3d_to_std(with_std), std)
    np.testing.assert_array_equal(m.skeleton3d_to_joints(with_std), joints)
    with_std.joint_std = with_std.joint_std[:-1]
    with pytest.raises(InvalidInputError, match="joint_names and joint_std differ"):
        m.skeleton3d_to_std(with_std)

    older = SimpleNamespace(joint_names=list(JOINT_NAMES), joints=msg.joints)  # read before joint_std
    assert np.isnan(m.skeleton3d_to_std(older)).all()
    for bad, expected in [(std[:11], r"\(12, 3\) metres, got shape \(11, 3\)"),
                          (np.where(np.eye(12, 3) > 0, np.nan, std), "finite and non-negative"),
                          (-std, "finite and non-negative")]:
        with pytest.raises(InvalidInputError, match=expected):
            m.result_to_skeleton3d(res, 7, joints, T, std_m=bad)


def test_skeleton_markers() -> None:
    header = m.make_header(0, "cam", T)
    j0 = np.zeros((12, 3))
    j1 = np.ones((12, 3))
    arr = m.skeleton_markers(header, [(3, j0), (5, j1), (-1, j0)], "people", 0.5, T,
                             deleted_track_ids=[9])
    back = roundtrip(arr, "visualization_msgs/msg/MarkerArray")
    mk = back.markers
    assert len(mk) == 3 * 2 + 2
    assert [(x.ns, x.id, x.type, x.action) for x in mk[:2]] == [("people/joints", 3, 7, 0),
                                                                 ("people/bones", 3, 5, 0)]
    assert mk[4].id == -1 and mk[5].id == -1
    assert len(mk[0].points) == 12 and len(mk[1].points) == 2 * len(BONES_FOR_DRAWING)
    assert mk[2].points[0].x == 1.0
    assert (mk[0].color.r, mk[0].color.g, mk[0].color.b) != (mk[2].color.r, mk[2].color.g, mk[2].color.b)
    assert mk[0].lifetime.nanosec == 500_000_000
    assert [(x.ns, x.id, x.action) for x in mk[6:]] == [("people/joints", 9, 2), ("people/bones", 9, 2)]
    # ids and colours are stable across calls
    again = m.skeleton_markers(header, [(5, j1)], "people", 0.5, T)
    assert again.markers[0].id == 5
    assert again.markers[0].color.g == pytest.approx(mk[2].color.g, rel=tol.FLOAT32_REL)


def test_camera_info_roundtrip() -> None:
    info = m.camera_info(m.make_header(0, "cam", T), 640, 480, 500.0, 510.0, 319.5, 239.5, T)
    back = roundtrip(info, "sensor_msgs/msg/CameraInfo")
    assert (back.width, back.height) == (640, 480)
    assert m.intrinsics_from_camera_info(back) == ((500.0, 510.0), (319.5, 239.5))


def test_a_frame_s_joints_are_read_with_its_layout_looked_up_once() -> None:
    """Each skeleton of a frame read as :func:`skeleton2d_to_arrays` reads it, a malformed one
    giving its error in its place; an unknown layout refuses the frame."""
    rng = np.random.default_rng(3)
    good = [m.arrays_to_skeleton2d(rng.uniform(0, 500, (17, 2)), np.full(17, 0.8), k, T) for k in range(2)]
    bad = m.arrays_to_skeleton2d(rng.uniform(0, 500, (10, 2)), np.full(10, 0.8), 9, T)
    first, wrong, second = frame_joints([good[0], bad, good[1]], "coco17")
    assert isinstance(wrong, InvalidInputError)
    for got, skel in ((first, good[0]), (second, good[1])):
        assert not isinstance(got, Exception)
        want = m.skeleton2d_to_arrays(skel, "coco17")
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    with pytest.raises(UnknownLayoutError):
        frame_joints(good, "no_such_layout")
