"""The per-joint measurement update of a hybrid track's published pose (core.track.measurement, options
``measurement_update`` / ``measurement_depth`` / ``measurement_gate``): the published joints go
where the observed 2D puts them, outliers excepted, each limb's depth toward its foreshortening;
causal and output-only."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions, p_mpjpe
from pose_lifter.core.model.skeleton import LIMB_NAMES, LIMBS, RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.later import LaterFrame, update_later
from pose_lifter.core.track.measurement import MeasurementUpdate, kalman_gain
from pose_lifter.core.track.policy import TrackedLift, TrackPolicy
from pose_lifter.mocap.scenes import corrupt_2d
from walker_tracks import assert_only_the_output_differs, person, track

OFF = {"measurement_update": False}


@pytest.fixture(scope="module")
def walker() -> tuple[np.ndarray, np.ndarray]:
    """A real walker (bags/walk_clean.mcap, CMU 07_05, an evaluation-split trial), 90 frames."""
    return person("walk_clean", 90)


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
    on = track(LifterOptions(), x[:20])
    off = track(LifterOptions(**OFF), x[:20])
    assert_only_the_output_differs(on, off)
    for a, b in zip(on, off, strict=True):
        np.testing.assert_array_equal(a.fit_pose_camera, b.fit_pose_camera)


def test_the_update_brings_a_clean_track_closer() -> None:
    """A punch (bags/punch_clean.mcap, CMU 02_05, never trained on), where the fit stays off the
    2D: the published pose is much closer to the truth with the update (measured 62.9 against
    76.4 mm over 90 frames)."""
    x, truth = person("punch_clean", 90)
    on, off = _p_mpjpe(track(LifterOptions(), x), truth), _p_mpjpe(track(LifterOptions(**OFF), x), truth)
    assert on < off - 5.0, (on, off)


def test_outliers_do_not_make_the_update_worse(walker: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walker
    leg_px = 160.0 * limb_lengths(truth)[:, RIGHT_LOWER_LEG]
    bad, conf = corrupt_2d(x, leg_px, 0.0, 0.2, 0.0, np.random.default_rng(3))
    on = _p_mpjpe(track(LifterOptions(), bad, conf), truth)
    off = _p_mpjpe(track(LifterOptions(**OFF), bad, conf), truth)
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
    on, off = track(LifterOptions(), noisy, conf), track(LifterOptions(**OFF), noisy, conf)
    policy = TrackPolicy(Lifter(options=LifterOptions()))
    for i in range(len(x)):
        policy.lift(0, i * 33_333_333, noisy[i], conf[i])
    assert policy._tracks[0].noise_median() > MAX_NOISE  # this noise is above the limit ...
    for a, b in zip(on, off, strict=True):  # ... so the update never ran
        np.testing.assert_array_equal(a.result.pose_camera, b.result.pose_camera)
    clean_on, clean_off = track(LifterOptions(), x), track(LifterOptions(**OFF), x)
    moved = [np.abs(a.result.pose_camera - b.result.pose_camera).max()
             for a, b in zip(clean_on, clean_off, strict=True)]
    assert max(moved) > 0.01  # leg units: on exact 2D it does


# ---------------------------------------------------------------- offline: the smoothed 2D


def _batch_smoother(z: np.ndarray, seen: np.ndarray, dt: np.ndarray, q: float, r: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares problem the smoother solves, posed whole: the unknowns are the first
    state (position, velocity; prior N(0, SMOOTH_PRIOR_VAR)) and each step's acceleration a_t (variance q);
    the positions are linear in them (x_t = F_t x_{t-1} + G_t a_t), each seen one measured with
    variance r. Returns the posterior means and variances of the positions (T,)."""
    n = len(z)
    m = np.zeros((n, 2 + n - 1))  # position t as a row over the unknowns
    state = np.zeros((2, 2 + n - 1))
    state[0, 0] = state[1, 1] = 1.0
    m[0] = state[0]
    for t in range(1, n):
        h = dt[t]
        state = np.array([[1.0, h], [0.0, 1.0]]) @ state
        state[:, 2 + t - 1] += [h * h / 2.0, h]
        m[t] = state[0]
    from pose_lifter.core.track.smooth2d import SMOOTH_PRIOR_VAR

    # the whitened system (its QR factors: the normal equations' conditioning squared costs digits)
    a = np.vstack([m[seen] / np.sqrt(r),
                   np.diag(np.r_[1.0, 1.0, np.full(n - 1, np.sqrt(SMOOTH_PRIOR_VAR / q))]
                           / np.sqrt(SMOOTH_PRIOR_VAR))])
    b = np.r_[z[seen] / np.sqrt(r), np.zeros(n + 1)]
    qf, rf = np.linalg.qr(a)
    theta = np.linalg.solve(rf, qf.T @ b)
    rows = np.linalg.solve(rf.T, m.T)  # R^-T m': the positions' covariance is its columns' squares
    return m @ theta, (rows ** 2).sum(axis=0)


def test_the_smoother_solves_its_least_squares_problem() -> None:
    """The offline smoother's two recursive passes (smooth2d._rts_kernel) give the posterior
    means and variances of the whole least-squares problem solved at once, with frames missing
    and uneven steps."""
    from pose_lifter.core.track.smooth2d import _rts_kernel
    from tolerances import SMOOTHER_AGREEMENT, SMOOTHER_VARIANCE_AGREEMENT

    rng = np.random.default_rng(0)
    n = 14
    t = np.cumsum(rng.uniform(0.5, 2.0, n))
    dt = np.r_[1.0, np.diff(t)]
    z = np.stack([np.sin(0.3 * t), 0.1 * t ** 1.5], axis=1) + 0.05 * rng.standard_normal((n, 2))
    seen = rng.random((n, 2)) > 0.3
    seen[0, 0] = seen[-1, 1] = False  # the first and last frames unseen in one series each
    q, r = 0.02 ** 2, 0.05 ** 2
    out, var = np.empty((n, 2)), np.empty((n, 2))
    _rts_kernel(z, seen, dt, q, r, out, var)
    for s in range(2):
        mean, v = _batch_smoother(z[:, s], seen[:, s], dt, q, r)
        np.testing.assert_allclose(out[:, s], mean, rtol=SMOOTHER_AGREEMENT, atol=SMOOTHER_AGREEMENT)
        np.testing.assert_allclose(var[:, s], v, rtol=SMOOTHER_VARIANCE_AGREEMENT)
    none = np.empty((n, 1))
    _rts_kernel(z[:, :1].copy(), np.zeros((n, 1), dtype=bool), dt, q, r, none, none.copy())
    assert np.isnan(none).all()  # a joint never used has no smoothed 2D


def test_the_smoothed_2d_halves_white_noise(walker: tuple[np.ndarray, np.ndarray]) -> None:
    """White 2D noise of 0.05 leg lengths on the real walker: the smoothed 2D is about half as far
    from the exact 2D (measured 0.45 of the raw RMS error, seeds 5 and 6), and the smoother's own
    ratio says about as much (measured 0.50-0.51); on exact 2D it moves the points by a small
    share of a pixel."""
    from pose_lifter.core.track.smooth2d import smooth_track_2d

    x, truth = walker
    leg_px = 160.0 * float(np.median(limb_lengths(truth)[:, RIGHT_LOWER_LEG]))
    stamps = np.arange(len(x), dtype=np.int64) * 33_333_333
    used = np.ones(x.shape[:2], dtype=bool)
    noisy, _ = corrupt_2d(x, np.full(len(x), leg_px), 0.05, 0.0, 0.0, np.random.default_rng(5))
    smoothed, ratio = smooth_track_2d(noisy, used, stamps)
    raw = float(np.sqrt(np.mean((noisy - x) ** 2)))
    assert float(np.sqrt(np.mean((smoothed - x) ** 2))) < 0.6 * raw
    assert 0.35 < ratio < 0.65
    exact, _ = smooth_track_2d(x, used, stamps)
    assert float(np.sqrt(np.mean((exact - x) ** 2))) < 0.2 * raw
    used[10:20, 2] = False  # a wrist the lift did not use is not read ...
    part, _ = smooth_track_2d(noisy, used, stamps)
    wild = noisy.copy()
    wild[10:20, 2] = 1e4
    np.testing.assert_array_equal(smooth_track_2d(wild, used, stamps)[0], part)
    assert float(np.abs(part[10:20, 2] - x[10:20, 2]).max()) < 0.5 * leg_px  # ... but bridged


def _offline(options: LifterOptions, x: np.ndarray, conf: np.ndarray) -> tuple[list[TrackedLift], np.ndarray]:
    """A track lifted as pose-lifter lift lifts it (TrackPolicy.smoothed_later, the offline
    update after the track's last frame; no centred smoothing): the lifts and the published poses."""
    policy = TrackPolicy(Lifter(options=options))
    policy.smoothed_later = True
    out = [policy.lift(0, i * 33_333_333, x[i], conf[i]) for i in range(len(x))]
    poses = np.array([t.result.pose_camera for t in out])
    kept = policy.kept_later().get(0, [])  # none without the measurement update
    assert policy.kept_later() == {}  # the kept frames are handed over once
    opts = policy.lifter.options
    for f, pose in zip(kept, update_later(kept, opts.measurement_depth, opts.measurement_gate), strict=True):
        if pose is not None:
            poses[f.stamp_ns // 33_333_333] = pose
    return out, poses


def test_offline_the_update_runs_on_noisy_2d_from_its_smoothed_2d() -> None:
    """The punch (never trained on) with white noise of 0.05 leg lengths, above MAX_NOISE: live
    the update does not run; offline it runs from the smoothed 2D and the published pose is
    closer to the truth (measured 64.1 / 64.4 against 68.5 / 69.5 mm, seeds 5 / 6), the fits
    themselves unchanged (output-only)."""
    x, truth = person("punch_clean", 90)
    leg = limb_lengths(truth)[:, RIGHT_LOWER_LEG]
    noisy, conf = corrupt_2d(x, np.full(len(x), 160.0 * float(np.median(leg))), 0.05, 0.0, 0.0,
                             np.random.default_rng(5))
    later, poses = _offline(LifterOptions(), noisy, conf)
    off, off_poses = _offline(LifterOptions(**OFF), noisy, conf)
    for a, b in zip(later, off, strict=True):
        np.testing.assert_array_equal(a.result.alpha, b.result.alpha)
        np.testing.assert_array_equal(a.result.pose_camera, b.result.pose_camera)  # nothing live

    def err(p: np.ndarray) -> float:
        return 1000.0 * float(np.mean(p_mpjpe(p * leg[:, None, None], truth)))

    assert err(poses) < err(off_poses) - 2.0, (err(poses), err(off_poses))
    assert np.isfinite(poses).all()


def test_offline_the_update_runs_both_ways_in_time_and_does_not_lag() -> None:
    """A still pose whose 2D puts the left wrist 0.2 leg lengths off, on a track noisy enough for
    a low gain: the forward pass alone would reach the 2D's wrist only after some frames (its
    first updated frame moves it by the gain's share); the mean of the forward and backward passes
    moves it as far on the track's first frames as on its last, and the frames whose noise the
    track did not know yet are published too."""

    pose = _pose()
    points = 100.0 * pose[:, :2] + 320.0
    points[2] += [20.0, 0.0]  # the wrist 0.2 leg lengths right in the image
    used = np.ones(12, dtype=bool)
    frames = [LaterFrame(i * 33_333_333, pose, points, used, None if i < 2 else 0.05, i > 0)
              for i in range(40)]
    out = update_later(frames, 0.0, 10.0)
    assert all(p is not None for p in out)
    moved = np.array([p[2, 0] - pose[2, 0] for p in out if p is not None])
    # measured: 0.107 on the first frame both passes update and on the last (the forward pass
    # alone: 0.035 on its first), 0.18 on the two frames only the backward pass updates
    assert moved.min() > 0.09
    assert abs(moved[2] - moved[-1]) < 0.01


def test_a_copy_of_the_state_goes_on_as_the_original_and_leaves_it_alone() -> None:
    """The refiner with a horizon (core/track/later.py) continues a track's forward pass on a copy."""
    pose = _pose()
    rng = np.random.default_rng(3)
    frames = [(pose + rng.normal(scale=0.02, size=pose.shape),
               100.0 * pose[:, :2] + rng.normal(scale=2.0, size=(12, 2))) for _ in range(12)]
    used = np.ones(12, dtype=bool)

    def run(update: MeasurementUpdate, part: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        return np.array([update.update(p, x, used, 0.01, 0.5, 0.3) for p, x in part])

    original, reference = MeasurementUpdate(), MeasurementUpdate()
    run(original, frames[:8])  # past SPAN_MIN_FRAMES: the copy carries the limb lengths too
    run(reference, frames[:8])
    expected = run(reference, frames[8:])
    copied = original.copy()
    np.testing.assert_array_equal(run(copied, frames[8:]), expected)
    np.testing.assert_array_equal(run(original, frames[8:]), expected)  # the copy's steps left it alone


def test_a_run_of_frames_is_the_update_frame_by_frame() -> None:
    """``MeasurementUpdate.run`` (one call over a sequence, as the offline and lagged passes use it)
    gives what :meth:`update` gives frame by frame: a frame without a noise is skipped and leaves
    the state alone, a restart or a non-finite update starts the state again, and the frames are
    taken in the order given."""
    pose = _pose()
    rng = np.random.default_rng(5)
    n = 24
    poses = pose + rng.normal(scale=0.02, size=(n, 12, 3))
    points = 100.0 * poses[..., :2] + rng.normal(scale=2.0, size=(n, 12, 2))
    used = rng.random((n, 12)) > 0.1
    noise = np.full(n, 0.01)
    noise[[3, 4]] = np.nan  # not known then
    restart = np.zeros(n, dtype=bool)
    restart[15] = True
    poses[19, 2, 2] = np.nan  # a non-finite update
    order = np.array(list(range(12)) + list(range(n - 1, 11, -1)))  # forward, then backward

    out, done = MeasurementUpdate().run(poses, points, used, noise, order, 0.5, 0.3, restart)

    state = MeasurementUpdate()
    expected_done = np.zeros(n, dtype=bool)
    for i in order:
        if restart[i]:
            state = MeasurementUpdate()
        if np.isnan(noise[i]):
            continue
        got = state.update(poses[i], points[i], used[i], noise[i], 0.5, 0.3)
        if not np.isfinite(got).all():
            state = MeasurementUpdate()
            continue
        expected_done[i] = True
        np.testing.assert_array_equal(out[i], got)
    np.testing.assert_array_equal(done, expected_done)
    assert not done[[3, 4, 19]].any() and done.sum() == n - 3


def test_a_limb_never_seen_across_the_image_keeps_its_depth() -> None:
    """Seen from above, a standing person's shins are foreshortened on every frame (0.64 of their
    length in the image, the rest in depth): the image's length of the shin underrates it, and the
    depth step must not flatten a shin the pose has at its true depth (its length is at least
    OWN_LIMB_SHARE of the pose's own)."""
    truth = _pose()
    for knee, ankle in (LIMBS[RIGHT_LOWER_LEG], LIMBS[LIMB_NAMES.index("left_lower_leg")]):
        truth[ankle] = truth[knee] + np.array([0.0, 0.64, 0.768])  # 1.0 long, away from the camera
    truth -= truth.mean(axis=0)
    points = 100.0 * truth[:, :2] + 320.0
    update = MeasurementUpdate()
    out = _run(update, truth, points, 20, depth=1.0)
    est = update.limb_lengths()
    assert est is not None and est[RIGHT_LOWER_LEG] < 0.7  # the image's shin: 0.64
    knee, ankle = LIMBS[RIGHT_LOWER_LEG]
    dz = out[ankle, 2] - out[knee, 2]
    # from the image's length alone the step would take the depth to 0; the pose's own shin
    # (1.0, at least 0.9 of it) keeps it: sqrt(0.9^2 - 0.64^2) = 0.63 or more, towards 0.768
    assert 0.6 < dz <= 0.768 + 1e-9
