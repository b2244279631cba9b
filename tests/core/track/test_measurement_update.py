"""The per-joint measurement update of a hybrid track's published pose (core.track.measurement, options
``measurement_update`` / ``measurement_depth`` / ``measurement_gate``): the published joints go
where the observed 2D puts them, outliers excepted, each limb's depth toward its foreshortening;
causal and output-only."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions, p_mpjpe
from pose_lifter.core.model.skeleton import LIMBS, RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.measurement import MeasurementUpdate, kalman_gain
from pose_lifter.core.track.policy import TrackedLift, TrackPolicy
from pose_lifter.mocap.scenes import corrupt_2d

REPO = Path(__file__).resolve().parents[3]
OFF = {"measurement_update": False}


def _person(bag: str, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The ground truth of a committed bag's person, ``frames`` frames at 30 Hz, weak
    perspective: (pixels (frames, 12, 2), centred camera-frame truth in metres (frames, 12, 3))."""
    from pose_lifter.messages import convert as messages
    from pose_lifter.messages.names import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import read_messages

    msgs = [x.msg for x in read_messages(REPO / "bags" / f"{bag}.mcap", [TOPIC_GROUND_TRUTH])]
    cam = np.array([messages.skeleton3d_to_joints(m.skeletons[0]) for m in msgs[:frames]])
    cam -= cam.mean(axis=1, keepdims=True)
    return 160.0 * cam[..., :2] + 320.0, cam


@pytest.fixture(scope="module")
def walker() -> tuple[np.ndarray, np.ndarray]:
    """A real walker (bags/walk_clean.mcap, CMU 07_05, an evaluation-split trial), 90 frames."""
    return _person("walk_clean", 90)


def _track(options: LifterOptions, x: np.ndarray, conf: np.ndarray | None = None) -> list[TrackedLift]:
    policy = TrackPolicy(Lifter(options=options))
    return [policy.lift(0, i * 33_333_333, x[i], None if conf is None else conf[i]) for i in range(len(x))]


def _p_mpjpe(out: list[TrackedLift], truth: np.ndarray) -> float:
    leg = limb_lengths(truth)[:, RIGHT_LOWER_LEG]
    pred = np.array([t.result.pose_camera for t in out]) * leg[:, None, None]
    return 1000.0 * float(np.mean(p_mpjpe(pred, truth)))


def _pose() -> np.ndarray:
    """A centred standing pose (12, 3), right lower leg 1, camera frame (y down), the left arm
    reaching towards the camera (its forearm foreshortened in the image)."""
    p = np.array([[-0.8, -2.6, 0.0], [-0.9, -1.6, -0.3], [-0.9, -1.0, -1.0],
                  [0.8, -2.6, 0.0], [0.9, -1.6, 0.0], [1.0, -0.6, 0.0],
                  [-0.5, 0.0, 0.0], [-0.5, 1.0, 0.0], [-0.5, 2.0, 0.0],
                  [0.5, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, 2.0, 0.0]])
    return p - p.mean(axis=0)


def _run(update: MeasurementUpdate, pose: np.ndarray, points: np.ndarray, frames: int,
         used: np.ndarray | None = None, noise: float = 0.003, depth: float = 0.5, gate: float = 0.3
         ) -> np.ndarray:
    used = np.ones(12, dtype=bool) if used is None else used
    out = pose
    for _ in range(frames):
        out = update.update(pose, points, used, noise, depth, gate)
    return out


def test_a_joint_moves_to_where_the_2d_puts_it() -> None:
    """The pose's left wrist is 0.2 leg lengths right of (and below) where the image has it: the
    published wrist goes to the image's, in the image's direction (a flipped axis or a sign error
    would move it away), and the other joints stay where the pose and the image agree."""
    truth = _pose()
    points = 100.0 * truth[:, :2] + np.array([320.0, 240.0])  # pixels, y down like the pose
    pose = truth.copy()
    pose[2, :2] += [0.2, 0.1]
    pose -= pose.mean(axis=0)
    out = _run(MeasurementUpdate(), pose, points, 1, noise=0.0, depth=0.0)
    # compare shapes: both centred on the other joints
    keep = np.arange(12) != 2

    def rel(p: np.ndarray) -> np.ndarray:
        return p[:, :2] - p[keep, :2].mean(axis=0)

    assert np.linalg.norm(rel(pose)[2] - rel(truth)[2]) > 0.2
    # (the wrong wrist is in the least-squares alignment of the 2D: a few hundredths)
    assert np.linalg.norm(rel(out)[2] - rel(truth)[2]) < 0.05
    np.testing.assert_allclose(rel(out)[keep], rel(truth)[keep], atol=0.05)


def test_a_limbs_depth_follows_its_foreshortening() -> None:
    """The image shows the left forearm short (reaching towards the camera, 1.0 leg lengths long
    with 0.6 of it in the image); a pose that has it nearly in the image plane (a small depth
    step, right sign) gets a longer depth step, with the pose's sign: towards the camera."""
    truth = _pose()
    points = 100.0 * truth[:, :2] + 320.0
    pose = truth.copy()
    pose[2, 2] = pose[1, 2] - 0.2  # the pose's forearm almost in the image plane
    update = MeasurementUpdate()
    # the other limbs are seen at their full lengths (the track's image lengths); the forearms'
    # estimate is the left and right average: (0.6 + 1.02) / 2
    out = _run(update, pose, points, 20, depth=1.0)
    est = update.limb_lengths()
    assert est is not None
    dz_pose = pose[2, 2] - pose[1, 2]
    dz_out = out[2, 2] - out[1, 2]
    dxy = np.linalg.norm(points[2] - points[1]) / 100.0
    want = -np.sqrt(max(est[1] ** 2 - dxy**2, 0.0))
    assert want < -0.5
    assert dz_out < dz_pose - 0.2  # deeper towards the camera, not away from it
    assert abs(dz_out - want) < abs(dz_pose - want)
    # measurement_depth 0.5: between the pose's depth step and the image's
    half = _run(MeasurementUpdate(), pose, points, 20, depth=0.5)
    assert want + 0.05 < half[2, 2] - half[1, 2] < dz_pose - 0.05


def test_a_joint_far_from_the_pose_is_gated_and_held() -> None:
    """A confident outlier the lift kept (the right wrist 1 leg length off in the image) is not
    moved to its 2D; the joints around it are still updated."""
    truth = _pose()
    points = 100.0 * truth[:, :2] + 320.0
    update = MeasurementUpdate()
    _run(update, truth, points, 5)
    bad = points.copy()
    bad[5] += [100.0, -60.0]
    out = update.update(truth, bad, np.ones(12, dtype=bool), 0.003, 0.5, 0.3)
    assert np.linalg.norm(out[5, :2] - truth[5, :2]) < 0.1
    ungated = MeasurementUpdate()
    _run(ungated, truth, points, 5)
    moved = ungated.update(truth, bad, np.ones(12, dtype=bool), 0.003, 0.5, 10.0)
    assert np.linalg.norm(moved[5, :2] - truth[5, :2]) > 0.8  # the gate is what held it


def test_a_joint_the_lift_did_not_use_keeps_its_place() -> None:
    """A joint the lift did not use on a frame is not read from the 2D (whatever is there) and
    does not jump back to the fit's position: it stays near where the track had it."""
    truth = _pose()
    points = 100.0 * truth[:, :2] + 320.0
    pose = truth.copy()
    pose[2, :2] += [0.3, 0.0]  # the fit is off at the wrist; the 2D is right
    pose -= pose.mean(axis=0)
    update = MeasurementUpdate()
    before = _run(update, pose, points, 5)
    used = np.ones(12, dtype=bool)
    used[2] = False
    junk = points.copy()
    junk[2] = [1e4, -1e4]
    out = update.update(pose, junk, used, 0.003, 0.5, 0.3)
    assert np.linalg.norm(out[2, :2] - before[2, :2]) < 0.05
    assert np.linalg.norm(out[2, :2] - pose[2, :2]) > 0.2


def test_noisy_2d_moves_the_pose_less() -> None:
    assert kalman_gain(1e-4, 0.0) == 1.0
    gains = [kalman_gain(1e-4, r * r) for r in (0.003, 0.03, 0.1, 0.3)]
    assert gains[0] > 0.9 and all(a > b for a, b in itertools.pairwise(gains))
    assert gains[2] < 0.15
    truth = _pose()
    points = 100.0 * truth[:, :2] + 320.0
    pose = truth.copy()
    pose[2, :2] += [0.3, 0.0]
    pose -= pose.mean(axis=0)
    clean = _run(MeasurementUpdate(), pose, points, 1, depth=0.0)
    noisy = _run(MeasurementUpdate(), pose, points, 1, noise=0.1, depth=0.0)
    assert np.linalg.norm(noisy[2, :2] - pose[2, :2]) < 0.3 * np.linalg.norm(clean[2, :2] - pose[2, :2])


def test_the_update_feeds_nothing_back_into_the_fit(walker: tuple[np.ndarray, np.ndarray]) -> None:
    """The track's fits are the same with and without the update, the fit's own pose stays
    available, and the published body-frame and camera-frame poses stay one pose."""
    x, _ = walker
    on = _track(LifterOptions(), x[:20])
    off = _track(LifterOptions(**OFF), x[:20])
    for a, b in zip(on, off, strict=True):
        np.testing.assert_array_equal(a.result.alpha, b.result.alpha)
        np.testing.assert_array_equal(a.result.camera.rotation, b.result.camera.rotation)
        assert a.result.objective == b.result.objective
        np.testing.assert_array_equal(a.fit_pose_camera, b.fit_pose_camera)
        c = a.result.pose - a.result.pose.mean(axis=0)
        np.testing.assert_allclose(c @ a.result.camera.rotation.T, a.result.pose_camera, atol=1e-9)
    assert not np.allclose(on[10].result.pose_camera, off[10].result.pose_camera)


def test_the_update_brings_a_clean_track_closer() -> None:
    """A punch (bags/punch_clean.mcap, CMU 02_05, never trained on), where the fit stays off the
    2D: the published pose is much closer to the truth with the update (measured 62.9 against
    76.4 mm over 90 frames)."""
    x, truth = _person("punch_clean", 90)
    on, off = _p_mpjpe(_track(LifterOptions(), x), truth), _p_mpjpe(_track(LifterOptions(**OFF), x), truth)
    assert on < off - 5.0, (on, off)


def test_outliers_do_not_make_the_update_worse(walker: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walker
    leg_px = 160.0 * limb_lengths(truth)[:, RIGHT_LOWER_LEG]
    bad, conf = corrupt_2d(x, leg_px, 0.0, 0.2, 0.0, np.random.default_rng(3))
    on = _p_mpjpe(_track(LifterOptions(), bad, conf), truth)
    off = _p_mpjpe(_track(LifterOptions(**OFF), bad, conf), truth)
    assert on < off + 0.5, (on, off)


def test_limb_lengths_come_from_the_image() -> None:
    """The track's limb lengths are an upper quantile of each limb's aligned image length, left
    and right averaged: forearms and shins turning in and out of the image plane (shorter in the
    image on most frames) are estimated near their full length."""
    truth = _pose()
    truth[2] = truth[1] + [0.0, 0.9, 0.0]  # both forearms in the image plane, 0.9 and 1.0 long
    truth[5] = truth[4] + [0.0, 1.0, 0.0]
    update = MeasurementUpdate()
    rng = np.random.default_rng(0)
    for i in range(40):
        p = truth.copy()
        for a, b in ((1, 2), (4, 5), (7, 8), (10, 11)):  # foreshortened by up to a half
            p[b] = p[a] + (truth[b] - truth[a]) * (1.0 if i % 8 == 0 else rng.uniform(0.5, 1.0))
        update.update(truth, 100.0 * p[:, :2] + 320.0, np.ones(12, dtype=bool), 0.003, 0.5, 10.0)
    est = update.limb_lengths()
    assert est is not None
    full = np.array([np.linalg.norm(truth[b, :2] - truth[a, :2]) for a, b in LIMBS])
    pairs = (0.5 * (full[[0, 1, 4, 5]] + full[[2, 3, 6, 7]]))[[0, 1, 0, 1, 2, 3, 2, 3]]
    np.testing.assert_allclose(est, pairs, rtol=0.1)
    assert est[1] > 0.9 * 0.95 and est[7] > 0.9


def test_the_update_runs_only_while_the_tracks_2d_is_nearly_exact(
        walker: tuple[np.ndarray, np.ndarray]) -> None:
    """Above MAX_NOISE the published pose is the one without the update, frame for frame (a
    detector's correlated error would otherwise be followed); on exact 2D the update moves it."""
    from pose_lifter.core.track.measurement import MAX_NOISE

    x, _ = walker
    x = x[:40]
    leg_px = 160.0 * float(np.median(limb_lengths(walker[1][:40])[:, RIGHT_LOWER_LEG]))
    rng = np.random.default_rng(5)
    noisy, conf = corrupt_2d(x, np.full(len(x), leg_px), 0.05, 0.0, 0.0, rng)
    on, off = _track(LifterOptions(), noisy, conf), _track(LifterOptions(**OFF), noisy, conf)
    policy = TrackPolicy(Lifter(options=LifterOptions()))
    for i in range(len(x)):
        policy.lift(0, i * 33_333_333, noisy[i], conf[i])
    assert policy._tracks[0].noise_median() > MAX_NOISE  # this noise is above the limit ...
    for a, b in zip(on, off, strict=True):  # ... so the update never ran
        np.testing.assert_array_equal(a.result.pose_camera, b.result.pose_camera)
    clean_on, clean_off = _track(LifterOptions(), x), _track(LifterOptions(**OFF), x)
    moved = [np.abs(a.result.pose_camera - b.result.pose_camera).max()
             for a, b in zip(clean_on, clean_off, strict=True)]
    assert max(moved) > 0.01  # leg units: on exact 2D it does
