"""pose_lifter.mocap.scenes: virtual camera geometry, detector-like corruption, bag contents."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tolerances as tol
from cmu_data import DATA, needs_data
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.skeleton import limb_lengths
from pose_lifter.messages import convert as m
from pose_lifter.messages.layouts import get_layout
from pose_lifter.mocap import scenes
from pose_lifter.offline import bags


def standing_person(facing_yaw_deg: float = 0.0) -> np.ndarray:
    """A T-ish pose in a Y-up world facing +Z rotated by ``facing_yaw_deg`` about +Y; left = +X."""
    pose = np.array([
        [0.20, 1.45, 0.0], [0.45, 1.45, 0.0], [0.70, 1.45, 0.0],  # left arm out to +X
        [-0.20, 1.45, 0.0], [-0.20, 1.15, 0.05], [-0.20, 0.90, 0.15],  # right arm down, forward
        [0.10, 0.95, 0.0], [0.10, 0.52, 0.05], [0.10, 0.10, 0.0],
        [-0.10, 0.95, 0.0], [-0.10, 0.52, 0.05], [-0.10, 0.10, 0.0],
    ])
    a = np.deg2rad(facing_yaw_deg)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return pose @ rot.T


def test_look_at_is_a_proper_rotation_with_y_down() -> None:
    rot = scenes.look_at(np.array([0.0, 1.0, 5.0]), np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=tol.ROUND_OFF)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    np.testing.assert_allclose(rot @ np.array([0.0, 1.0, 0.0]), [0, -1, 0], atol=tol.ROUND_OFF)  # up -> -y
    np.testing.assert_allclose(rot @ np.array([0.0, 0.0, -1.0]), [0, 0, 1], atol=tol.ROUND_OFF)  # forward
    with pytest.raises(InvalidInputError):
        scenes.look_at(np.zeros(3), np.array([0.0, 1.0, 0.0]))


@pytest.mark.parametrize("facing", [0.0, 70.0, -140.0])
def test_front_view_keeps_chirality(facing: float) -> None:
    # seen from the front, the person's LEFT hand appears on the image RIGHT and the head up:
    # a mirrored camera (y flipped alone) would swap them
    clip = np.repeat(standing_person(facing)[None], 3, axis=0)
    sc = scenes.build_scene([clip], scenes.SceneOptions(view_angle=0.0))
    uv = sc.clean_2d[0, 0]
    assert uv[2, 0] > uv[5, 0] + 50  # left wrist right of right wrist (pixels)
    assert uv[0, 1] < uv[8, 1]  # shoulder above ankle (image y down)
    # camera frame: depth positive, person centred, right arm (forward) nearer the camera
    cam = sc.joints_camera[0, 0]
    assert np.all(cam[:, 2] > 4.0)
    assert cam[5, 2] < cam[2, 2]
    # from behind, left and right swap in the image
    back = scenes.build_scene([clip], scenes.SceneOptions(view_angle=180.0)).clean_2d[0, 0]
    assert back[2, 0] < back[5, 0] - 50


def test_projection_and_distance() -> None:
    clip = np.repeat(standing_person()[None], 2, axis=0)
    sc = scenes.build_scene([clip], scenes.SceneOptions(distance=5.0))
    cam = sc.joints_camera[0, 0]
    assert cam.mean(axis=0)[2] == pytest.approx(5.0, abs=tol.ROUND_OFF_ACCUMULATED)
    np.testing.assert_allclose(sc.clean_2d[0, 0, :, 0], 800 * cam[:, 0] / cam[:, 2] + 320)
    np.testing.assert_allclose(sc.clean_2d[0, 0, :, 1], 800 * cam[:, 1] / cam[:, 2] + 240)
    # bones keep their metric lengths (a rigid placement)
    np.testing.assert_allclose(limb_lengths(cam), limb_lengths(clip[0]), atol=tol.ROUND_OFF)


def test_orbit_and_two_people() -> None:
    clip = np.repeat(standing_person()[None], 31, axis=0)
    sc = scenes.build_scene([clip, clip], scenes.SceneOptions(fps=30, orbit_speed=90.0, spacing=1.5),
                            source_fps=30, track_ids=[4, 9])
    assert sc.track_ids == [4, 9] and sc.joints_camera.shape == (2, 31, 12, 3)
    # after 1 s the camera has turned 90 degrees about the vertical
    turn = sc.rotations[30] @ sc.rotations[0].T
    assert np.degrees(np.arccos((np.trace(turn) - 1) / 2)) == pytest.approx(90.0, abs=1e-6)
    # people 1.5 m apart across the first frame
    gap = sc.joints_camera[1, 0].mean(axis=0) - sc.joints_camera[0, 0].mean(axis=0)
    np.testing.assert_allclose(gap, [1.5, 0, 0], atol=tol.ROUND_OFF_ACCUMULATED)
    assert np.all(np.abs(np.diff(sc.stamps_ns) - 1e9 / 30) <= 1)  # ns rounding
    assert sc.stamps_ns[30] - sc.stamps_ns[0] == 1_000_000_000


def test_corrupt_2d_rates() -> None:
    rng = np.random.default_rng(0)
    clean = np.zeros((2000, 12, 2))
    leg = np.full(2000, 50.0)
    pts, conf = scenes.corrupt_2d(clean, leg, noise=0.1, outliers=0.0, missing=0.0, rng=rng)
    assert np.std(pts) == pytest.approx(5.0, rel=0.03) and np.all(conf == 1)
    pts, conf = scenes.corrupt_2d(clean, leg, noise=0.0, outliers=0.1, missing=0.2, rng=rng)
    moved = np.linalg.norm(pts, axis=-1)
    assert np.mean(conf == 0) == pytest.approx(0.2, abs=0.01)
    far = (moved > 0) & (conf > 0)
    assert np.mean(far) == pytest.approx(0.1 * 0.8, abs=0.01)
    assert moved[far].min() >= 50.0 - tol.ROUND_OFF_ACCUMULATED
    assert moved[far].max() <= 150.0 + tol.ROUND_OFF_ACCUMULATED


def test_to_coco17_and_bag(tmp_path: Path) -> None:
    clip = np.repeat(standing_person()[None], 4, axis=0)
    sc = scenes.build_scene([clip, clip], scenes.SceneOptions(missing=0.2, seed=5), track_ids=[0, 1])
    kp, cf = scenes.to_coco17(sc.points_2d[0, 0], sc.confidence[0, 0])
    idx = list(get_layout("coco17").model_indices)
    np.testing.assert_array_equal(kp[idx], sc.points_2d[0, 0])
    assert np.all(cf[:5] == 0)
    path = tmp_path / "s.mcap"
    bags.write_messages(path, scenes.scene_messages(sc))
    assert bags.bag_topics(path) == {
        "/keypoints_2d": "pose_lifter_msgs/msg/Skeleton2DArray",
        "/ground_truth/skeletons_3d": "pose_lifter_msgs/msg/Skeleton3DArray",
        "/camera_info": "sensor_msgs/msg/CameraInfo",
    }
    msgs = list(bags.read_messages(path))
    assert len(msgs) == 3 * 4
    kp_msgs = [x for x in msgs if x.topic == "/keypoints_2d"]
    gt_msgs = [x for x in msgs if x.topic == "/ground_truth/skeletons_3d"]
    assert [x.stamp_ns for x in kp_msgs] == [x.stamp_ns for x in gt_msgs] == list(sc.stamps_ns)
    first = kp_msgs[0].msg
    assert first.layout == "coco17" and first.header.frame_id == scenes.CAMERA_FRAME
    pts, conf = m.skeleton2d_to_arrays(first.skeletons[1], first.layout)
    np.testing.assert_allclose(pts, sc.points_2d[1, 0])
    np.testing.assert_allclose(conf, sc.confidence[1, 0])
    np.testing.assert_allclose(m.skeleton3d_to_joints(gt_msgs[2].msg.skeletons[1]), sc.joints_camera[1, 2])
    info = next(x.msg for x in msgs if x.topic == "/camera_info")
    assert m.intrinsics_from_camera_info(info) == ((800.0, 800.0), (320.0, 240.0))


def test_scenes_in_sequence_follow_one_another_a_second_apart(tmp_path: Path) -> None:
    clip = np.repeat(standing_person()[None], 5, axis=0)
    one = scenes.build_scene([clip], scenes.SceneOptions(), track_ids=[0])
    two = scenes.build_scene([clip[:3]], scenes.SceneOptions(), track_ids=[1])
    a, b = scenes.in_sequence([one, two])
    np.testing.assert_array_equal(a.stamps_ns, one.stamps_ns)
    assert b.stamps_ns[0] == a.stamps_ns[-1] + 1_000_000_000
    np.testing.assert_array_equal(np.diff(b.stamps_ns), np.diff(two.stamps_ns))
    np.testing.assert_array_equal(b.points_2d, two.points_2d)
    with pytest.raises(InvalidInputError, match="gap_s"):
        scenes.in_sequence([one, two], gap_s=0.0)
    # without camera_info: the keypoints and the ground truth only
    path = tmp_path / "s.mcap"
    bags.write_messages(path, (x for s in (a, b) for x in scenes.scene_messages(s, camera_info=False)))
    assert set(bags.bag_topics(path)) == {"/keypoints_2d", "/ground_truth/skeletons_3d"}
    kp = [x for x in bags.read_messages(path, ["/keypoints_2d"])]
    assert [x.stamp_ns for x in kp] == [*a.stamps_ns, *b.stamps_ns]
    assert [[s.track_id for s in x.msg.skeletons] for x in kp] == [[0]] * 5 + [[1]] * 3


@needs_data
def test_trials_filmed_as_one_track_follow_one_another_a_frame_apart() -> None:
    """``make-bag --one-after-another --one-track``: one person recorded at length, the trials
    on track 0, each a frame after the previous one; refused without --one-after-another."""
    opts = scenes.SceneOptions(fps=30.0)
    a, b = scenes.film_trials(["01_01", "01_02"], DATA, opts, frames=5, one_after_another=True,
                              one_track=True)
    assert list(a.track_ids) == list(b.track_ids) == [0]
    assert b.stamps_ns[0] - a.stamps_ns[-1] == round(1e9 / 30.0)
    with pytest.raises(InvalidInputError, match="one-after-another"):
        scenes.film_trials(["01_01"], DATA, opts, frames=5, one_track=True)
