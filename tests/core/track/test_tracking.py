"""The per-track policy (core.track.policy) and a track's state (core.track.state): warm starts out of a
wrong basin, the temporal gate, carried-over and filled joints, the temporal prior's past frames,
malformed frames and the track's limb proportions."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core import (
    Lifter,
    LifterOptions,
    LiftOutcome,
    LiftResult,
    PoseBases,
    StartKind,
    TrackContext,
    p_mpjpe,
)
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.lift.batch import LiftRow
from pose_lifter.core.model.bases import default_bases_path
from pose_lifter.core.model.metrics import procrustes_align
from pose_lifter.core.model.prior import PosePrior
from pose_lifter.core.track.policy import OutOfOrderFrameError, TrackPolicy
from pose_lifter.mocap.views import scale_limbs

#: Tolerances of this file, stated once.
LIMB_TOL = tol.LIFT_LIMB_VIOLATION  # limb-length violation of a fused (hybrid) result, right-lower-leg units


@pytest.fixture(scope="module")
def bases() -> PoseBases:
    return PoseBases.load()


def _track(lifter: Lifter, x: np.ndarray, conf: np.ndarray | None = None) -> list[LiftResult]:
    policy = TrackPolicy(lifter)
    return [policy.lift(0, i * 33_333_333, x[i], None if conf is None else conf[i]).result
            for i in range(len(x))]


def test_the_tracker_leaves_a_wrong_depth_basin(
        bases: PoseBases, real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """A track forced into the depth-mirrored basin (its warm start is the mirrored solution)
    comes back to the image's basin: the prior's pose starts every frame."""
    x, truth = real_frames  # frames 0-3: one walker, 1/3 s apart
    lifter = Lifter(bases, LifterOptions(mode="hybrid", warm_flip=False))
    first = lifter.lift(x[0])
    mirrored = lifter.runs.start_alpha(first.pose_camera * np.array([1.0, 1.0, -1.0]))
    policy = TrackPolicy(lifter)
    wrong = replace(first.warm_start(), alpha=mirrored)
    policy.restore(0, wrong, 0)  # the track's state: the wrong basin
    r = policy.lift(0, 33_000_000, x[1]).result
    trapped = Lifter(bases, LifterOptions(mode="paper", warm_flip=False)).lift(x[1], warm=wrong)
    assert p_mpjpe(r.pose_camera, truth[1]) < p_mpjpe(trapped.pose_camera, truth[1])
    assert r.start is StartKind.PRIOR  # the prior's start won
    with pytest.raises(OutOfOrderFrameError):
        policy.lift(0, 10_000_000, x[2])


def test_the_temporal_gate_drops_a_jumping_detection_before_the_prior_sees_it(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walk_track
    leg = float(np.median(np.linalg.norm(x[:, 10] - x[:, 11], axis=1)))
    hit = [10, 15, 20, 25]
    bad = x.copy()
    bad[hit, 2] += np.array([1.2, -0.8]) * leg  # the left wrist jumps ~1.4 legs, confidence 1
    # the lifter's own outlier pass off: the gate alone
    gated = _track(Lifter(bases, LifterOptions(outlier_threshold=0.0)), bad)
    plain = _track(Lifter(bases, LifterOptions(outlier_threshold=0.0, outlier_gate=0.0)), bad)
    assert all(gated[i].weights[2] == 0.0 for i in hit)
    clean = [i for i in range(len(x)) if i not in hit]
    assert sum(int(np.count_nonzero(gated[i].weights == 0.0)) for i in clean) <= 1  # no false alarms
    err = [np.mean([p_mpjpe(r[i].pose_camera, truth[i]) for i in hit]) for r in (gated, plain)]
    assert err[0] < 0.97 * err[1], err


def test_a_track_swaps_back_the_labels_its_detector_swapped(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """A walker whose detector swaps the arms' left and right labels on two single frames and
    the legs' on two frames in a row: with ``label_swaps`` (default) the track lifts exactly what
    it lifts from the right labels, every frame; without, the swapped frames are lifted on the
    wrong sides."""
    x, truth = walk_track
    bad = x.copy()
    for i in (10, 20):
        bad[i, :6] = x[i, [3, 4, 5, 0, 1, 2]]
    for i in (15, 16):
        bad[i, 6:] = x[i, [9, 10, 11, 6, 7, 8]]
    clean = _track(Lifter(bases, LifterOptions()), x)
    checked = _track(Lifter(bases, LifterOptions()), bad)
    plain = _track(Lifter(bases, LifterOptions(label_swaps=False)), bad)
    for a, b in zip(clean, checked, strict=True):
        np.testing.assert_array_equal(a.pose_camera, b.pose_camera)
    hit = [10, 15, 16, 20]
    err = [np.mean([p_mpjpe(r[i].pose_camera, truth[i]) for i in hit]) for r in (clean, plain)]
    assert err[1] > 1.4 * err[0], err


def test_a_missing_joint_is_carried_over_by_the_track(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walk_track
    conf = np.ones(x.shape[:2])
    lost = [2, 8]  # the left wrist and left ankle, lost for half a second
    conf[10:25, lost] = 0.0
    frames = range(10, 25)
    errs = []
    for w in (3.0, 0.0):
        # the single-frame prior: the carry-over alone (the temporal prior sees the past frames
        # too, and the flip-averaged prior guesses this walker's lost joints within 1.3 % of it;
        # the output's measurement update holds a lost joint where the track had it as well).
        # The carry-over moves the prior rows' target; the pose step follows its rows the further
        # the more iterations it runs (the default configuration's gain: docs/tuning.md,
        # missing_temporal_weight). Measured on the lost joints' own error after aligning the
        # whole pose (with the carry-over over without: 0.949 with the packaged prior); the
        # whole pose's error moves more with what the prior guesses of the other joints
        res = _track(Lifter(bases, LifterOptions(missing_temporal_weight=w, temporal_prior=False,
                                                 fill_missing_frames=0, prior_flip=False,
                                                 measurement_update=False, hybrid_pose_max_iter=20)),
                     x, conf)
        errs.append(np.mean([np.linalg.norm(procrustes_align(res[i].pose_camera, truth[i])[lost]
                                            - truth[i][lost], axis=-1) for i in frames]))
    assert errs[0] < 0.975 * errs[1], errs


def test_a_lost_joint_is_given_to_the_prior_where_the_track_predicts_it(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray], monkeypatch: pytest.MonkeyPatch) -> None:
    x, truth = walk_track
    conf = np.ones(x.shape[:2])
    lost = [10, 11, 16, 17, 22, 23]
    conf[np.ix_(lost, [2, 8])] = 0.0  # the left wrist and ankle lost for 2 frames, 3 times
    conf[5:15, 5] = 0.0  # the right wrist lost for 10 frames: filled on its first 3 only
    seen: list[np.ndarray | None] = []
    lift = Lifter.lift_people

    def spy(self: Lifter, calls: Sequence[LiftRow]) -> list[LiftOutcome]:
        for c in calls:
            f = None if c.track is None else c.track.fill
            seen.append(None if f is None else np.asarray(f[1]).copy())
        return lift(self, calls)

    errs = []
    for n in (3, 0):
        # the fill's effect on the fit alone: the output's measurement update holds a lost joint
        # where the track had it, which takes part of the same error off both runs (ratio with it
        # on: 0.955-0.964; off: 0.914-0.929, measured under both floating-point set-ups)
        opts = LifterOptions(fill_missing_frames=n, missing_temporal_weight=0.0, measurement_update=False)
        if n:
            monkeypatch.setattr(Lifter, "lift_people", spy)
        res = _track(Lifter(bases, opts), x, conf)
        monkeypatch.setattr(Lifter, "lift_people", lift)
        errs.append(np.mean([p_mpjpe(res[i].pose_camera, truth[i]) for i in lost]))
    assert errs[0] < 0.97 * errs[1], errs
    assert seen[0] is None  # the first frame has no track to predict from
    allowed = np.array([m is not None and bool(m[5]) for m in seen])
    assert allowed[5:8].all() and not allowed[8:15].any()  # 3 frames, then it is left missing
    assert np.all([m is not None and m[2] for i, m in enumerate(seen) if i in lost])
    with pytest.raises(InvalidInputError, match="fill"):
        Lifter(bases).lift(x[0], track=TrackContext(fill=(np.zeros((11, 2)), np.ones(12, dtype=bool))))
    # no fill while the track's fit is being lost (its last objective far above its median)
    policy = TrackPolicy(Lifter(bases))
    for i in range(5):
        policy.lift(0, i * 33_333_333, x[i])
    seen.clear()
    monkeypatch.setattr(Lifter, "lift_people", spy)
    policy.lift(0, 5 * 33_333_333, x[5], conf[10])
    assert seen[-1] is not None
    policy._tracks[0].objectives.append(1e6)
    policy.lift(0, 6 * 33_333_333, x[6], conf[10])
    assert seen[-1] is None
    monkeypatch.setattr(Lifter, "lift_people", lift)


def test_a_temporal_prior_sees_the_tracks_past_frames(
        bases: PoseBases, real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """A window-2 prior (random weights: the plumbing, not the accuracy) gets the previous frame
    from the lift's ``past``; no past means the current frame repeated; the per-track policy
    hands over only evenly spaced frames."""
    from pose_lifter.core.track.state import Track

    rng = np.random.default_rng(0)
    net = PosePrior((rng.normal(size=(72, 16)) * 0.3, rng.normal(size=(16, 36)) * 0.3),
                    (np.zeros(16), np.zeros(36)), np.zeros(36), np.ones(36), np.ones((12, 3)), window=2)
    lifter = Lifter(bases, LifterOptions(mode="learned", temporal_prior=False), prior=net)
    x = real_frames[0]
    vis = np.ones(12, dtype=bool)
    now = lifter.lift(x[1]).prior_pose
    assert now is not None
    same = lifter.lift(x[1], track=TrackContext(past=(x[1][None], vis[None]))).prior_pose
    moved = lifter.lift(x[1], track=TrackContext(past=(x[0][None], vis[None]))).prior_pose
    np.testing.assert_allclose(same, now, rtol=0, atol=tol.ROUND_OFF_ACCUMULATED)
    assert moved is not None and np.abs(moved - now).max() > 1e-3
    with pytest.raises(InvalidInputError):
        lifter.lift(x[1], track=TrackContext(past=(x[0], vis)))
    track = Track(None, 0)
    for stamp in (0, 100, 133, 166):  # a gap, then 33 ms steps
        track.history.append((stamp, np.full((12, 2), float(stamp)), np.ones(12, dtype=bool)))
    past = track.past(199, 5)
    assert past is not None
    assert past[0][:, 0, 0].tolist() == [100.0, 133.0, 166.0]
    assert track.past(199, 2)[0][:, 0, 0].tolist() == [133.0, 166.0]  # the last 2 of them
    assert track.past(166, 5) is None  # not after the last frame
    # a frame entered since: the same stamp's past holds it
    track.history.append((199, np.full((12, 2), 199.0), np.ones(12, dtype=bool)))
    assert track.past(232, 5)[0][:, 0, 0].tolist() == [100.0, 133.0, 166.0, 199.0]
    assert track.past(199, 5) is None


def test_an_offline_prior_reads_the_tracks_next_frames(
        bases: PoseBases, real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """A prior of the middle frame of a 3-frame window (random weights: the plumbing) gets the
    previous frame from ``past`` and the next one from ``future``, a missing next frame padded
    with this one; the per-track policy hands over the evenly spaced next frames of
    :class:`FramesAhead` with their visible joints; only a lifter that reads ahead takes the
    prior, and a causal prior ignores the next frames."""
    from pose_lifter.core.errors import PriorFileError
    from pose_lifter.core.track.policy import FramesAhead

    rng = np.random.default_rng(1)
    net = PosePrior((rng.normal(size=(108, 16)) * 0.3, rng.normal(size=(16, 36)) * 0.3),
                    (np.zeros(16), np.zeros(36)), np.zeros(36), np.ones(36), np.ones((12, 3)), window=3,
                    metadata={"future_frames": 1})
    with pytest.raises(PriorFileError, match="offline lift"):
        _ = Lifter(bases, LifterOptions(mode="learned"), temporal_prior=net).temporal_prior
    lifter = Lifter(bases, LifterOptions(mode="learned"), temporal_prior=net, reads_ahead=True)
    x = real_frames[0]
    vis = np.ones(12, dtype=bool)
    vis3 = np.ones((3, 12), dtype=bool)

    def lifted(past: np.ndarray, future: np.ndarray | None) -> np.ndarray:
        ctx = TrackContext(past=(past[None], vis[None]),
                           future=None if future is None else (future[None], vis[None]))
        pose = lifter.lift(x[1], track=ctx).prior_pose
        assert pose is not None
        return pose

    def predicted(frames: list[np.ndarray], visible: np.ndarray = vis3) -> np.ndarray:
        return net.predict(np.stack(frames), visible, lifter.options.prior_flip)

    np.testing.assert_array_equal(lifted(x[0], x[2]), predicted([x[0], x[1], x[2]]))
    np.testing.assert_array_equal(lifted(x[0], None), predicted([x[0], x[1], x[1]]))
    assert np.abs(predicted([x[0], x[1], x[2]]) - predicted([x[0], x[1], x[1]])).max() > 1e-3
    # the policy: frame 1 with frames 2 and 3 ahead (evenly spaced), then with an uneven step
    step = 33_333_333
    conf = np.ones((4, 12))
    conf[2, 5] = 0.0  # joint 5 of frame 2 below the confidence threshold
    for stamps, want in (([2 * step, 3 * step], [x[0], x[1], x[2]]), ([3 * step], [x[0], x[1], x[1]])):
        policy = TrackPolicy(lifter)
        policy.lift(0, 0, x[0])
        ahead = FramesAhead(np.array(stamps, dtype=np.int64), x[2:2 + len(stamps)], conf[2:2 + len(stamps)])
        got = policy.lift(0, step, x[1], None, None, ahead).result.prior_pose
        visible = vis3.copy()
        visible[2, 5] = len(stamps) == 1  # the padded frame is this one, every joint visible
        np.testing.assert_array_equal(got, predicted(want, visible))
    # a causal temporal prior (the packaged one) reads no next frame
    causal = Lifter(bases, LifterOptions(mode="hybrid"))
    runs = []
    for given in (None, FramesAhead(np.array([2 * step], dtype=np.int64), x[2:3])):
        policy = TrackPolicy(causal)
        policy.lift(0, 0, x[0])
        runs.append(policy.lift(0, step, x[1], None, None, given).result.pose_camera)
    np.testing.assert_array_equal(runs[0], runs[1])


def test_the_gate_screens_the_next_frames_an_offline_prior_reads(
        real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """Track.screen_ahead: a person walking on (their own motion and a shift of the image) keeps
    every joint; a joint one frame moves 2 leg lengths away from the others' motion is dropped
    on that frame, and the frame after is judged against where the joint was before it."""
    from pose_lifter.core.track.state import Track

    x = real_frames[0][:4]
    scale = 100.0  # pixels per leg length
    track = Track(None, 0)
    track.fits.append((0, x[0], scale))
    ahead = x[1:] + np.array([[[3.0, -2.0]], [[6.0, -4.0]], [[9.0, -6.0]]])
    vis = np.ones(12, dtype=bool)
    frames, kept = track.screen_ahead(x[0], vis, x[0], ahead, np.ones((3, 12), dtype=bool), 0.8)
    assert kept.all() and (frames == ahead).all()
    jumped = ahead.copy()
    jumped[1, 7] += [2.0 * scale, 0.0]
    frames, kept = track.screen_ahead(x[0], vis, x[0], jumped, np.ones((3, 12), dtype=bool), 0.8)
    assert kept[[0, 2]].all() and kept[1].tolist() == [j != 7 for j in range(12)]
    assert (frames == jumped).all()
    # a joint this frame lacks is judged from where the track predicted it
    lacking = vis.copy()
    lacking[7] = False
    predicted = x[0].copy()
    predicted[7] += [2.0 * scale, 0.0]
    _, kept = track.screen_ahead(x[0], lacking, predicted, ahead, np.ones((3, 12), dtype=bool), 0.8)
    assert kept[0].tolist() == [j != 7 for j in range(12)]


def test_the_label_check_screens_the_next_frames_an_offline_prior_reads() -> None:
    """Track.screen_ahead with ``check_labels``: a next frame whose legs' left and right labels
    the detector swapped is read with them swapped back (the others as given, the caller's array
    untouched); without the check, as given."""
    from pose_lifter.core.track.state import Track

    rng = np.random.default_rng(1)
    x0 = rng.normal(scale=60.0, size=(12, 2)) + 300.0  # joints far apart: a swap is plain
    track = Track(None, 0)
    track.fits.append((0, x0, 60.0))
    ahead = x0 + np.array([[[3.0, -2.0]], [[6.0, -4.0]], [[9.0, -6.0]]])
    swapped = ahead.copy()
    swapped[1, 6:] = ahead[1, [9, 10, 11, 6, 7, 8]]
    given = swapped.copy()
    vis = np.ones(12, dtype=bool)
    frames, kept = track.screen_ahead(x0, vis, x0, swapped, np.ones((3, 12), dtype=bool), 0.8)
    assert (frames == ahead).all() and kept.all() and (swapped == given).all()
    frames, kept = track.screen_ahead(x0, vis, x0, swapped, np.ones((3, 12), dtype=bool), 0.8,
                                      check_labels=False)
    assert (frames == swapped).all()


def test_the_packaged_temporal_prior_is_used_on_tracked_frames(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """The packaged causal temporal prior (4 frames, training split only) loads without pickle;
    a track's frames after the first are lifted with it, and on a real walker it is closer to the
    truth than the single-frame prior."""
    from pose_lifter.core.model.prior import DEFAULT_TEMPORAL_PRIOR_PATH

    temporal = PosePrior.load(DEFAULT_TEMPORAL_PRIOR_PATH)
    assert temporal.window == 4
    assert not set(temporal.metadata["training_trials"]) & {"02_01", "07_01", "08_01", "09_12"}
    x, truth = walk_track
    errs = []
    for on in (True, False):
        res = _track(Lifter(bases, LifterOptions(temporal_prior=on)), x)
        errs.append(np.mean([p_mpjpe(r.pose_camera, t) for r, t in zip(res[1:], truth[1:], strict=True)]))
        if on:  # the first frame has no past: the single-frame prior, the same as without
            off0 = Lifter(bases, LifterOptions(temporal_prior=False)).lift(x[0])
            np.testing.assert_allclose(res[0].pose_camera, off0.pose_camera, atol=tol.ROUND_OFF_ACCUMULATED)
    assert errs[0] < errs[1], errs


def test_the_temporal_prior_never_reads_a_future_frame(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """Causal as the node runs it (``TrackPolicy``, frame by frame): the packaged temporal prior
    is handed only the current frame and earlier frames of the track, oldest first and the
    current one last, and a frame's published pose does not change when the frames after it do."""
    from pose_lifter.core.model.prior import DEFAULT_TEMPORAL_PRIOR_PATH

    temporal = PosePrior.load(DEFAULT_TEMPORAL_PRIOR_PATH)
    windows: list[tuple[np.ndarray, np.ndarray]] = []

    class Spy(PosePrior):
        def features(self, points: np.ndarray, visible: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            windows.append((np.array(points), np.array(visible)))
            return super().features(points, visible)

    spy = Spy(temporal.weights, temporal.biases, temporal.out_mean, temporal.out_scale,
              temporal.abs_error, temporal.window, temporal.metadata, temporal.blocks)
    x = walk_track[0][:12]
    k = 6
    other = np.concatenate([x[:k + 1], x[k + 1:][::-1] + 40.0])  # the same past, another future
    poses = []
    for frames in (x, other):
        policy = TrackPolicy(Lifter(bases, LifterOptions(), prior=PosePrior.load(), temporal_prior=spy))
        out = []
        for i in range(len(frames)):
            windows.clear()
            out.append(policy.lift(0, i * 33_333_333, frames[i]).result.pose_camera)
            assert (len(windows) > 0) == (i > 0)  # the first frame has no past: the single-frame prior
            for pts, vis in windows:
                assert pts.shape == (spy.window, 12, 2)
                np.testing.assert_array_equal(pts[-1][vis[-1]], frames[i][vis[-1]])
                # every earlier row is a frame of the track's past, in order
                src = [int(np.argmin([np.abs(f[v] - row[v]).max() for f in frames]))
                       for row, v in zip(pts[:-1], vis[:-1], strict=True)]
                for j, row, v in zip(src, pts[:-1], vis[:-1], strict=True):
                    np.testing.assert_array_equal(row[v], frames[j][v])
                assert src == sorted(src) and src[-1] == i - 1
        poses.append(out)
    for i in range(k + 1):
        np.testing.assert_array_equal(poses[0][i], poses[1][i])
    assert np.abs(poses[0][k + 1] - poses[1][k + 1]).max() > 1e-3


def test_a_malformed_tracked_frame_is_refused_with_the_lifters_error(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """The gate and the carry-over run before the lifter's checks: a wrong shape on a warm frame
    must still be the lifter's InvalidInputError, and the track goes on."""
    x, _ = walk_track
    policy = TrackPolicy(Lifter(bases))
    policy.lift(0, 0, x[0])
    with pytest.raises(InvalidInputError):
        policy.lift(0, 33_333_333, x[1][:11])
    with pytest.raises(InvalidInputError):
        policy.lift(0, 66_666_666, x[2], np.ones(11))
    assert policy.lift(0, 99_999_999, x[3]).result.limb_violation < LIMB_TOL


def test_the_track_learns_a_persons_limb_proportions(walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """A real walker made long-shinned and short-armed: with ``prior_limbs`` the track's estimate
    (median of the prior's limbs, calibrated) moves toward the person's proportions from the
    bases', and the fit's limbs take it. (What it gains in 3D is measured by tools/accuracy.py's
    ``proportions`` condition: on one 1 s track it is within the noise.)"""
    _, truth = walk_track
    factors = np.array([1.0, 0.85, 1.0, 0.85, 1.0, 1.2, 1.0, 1.2])  # forearms -15 %, shins +20 %
    person = scale_limbs(truth, factors)
    x = 160.0 * person[..., :2] + 320.0
    bases = PoseBases.load(default_bases_path("hybrid"))
    own = Lifter(bases, LifterOptions(mode="hybrid", prior_limbs=True))
    fixed = Lifter(bases, LifterOptions(mode="hybrid", prior_limbs=False))
    policy = TrackPolicy(own)
    got = [policy.lift(0, i * 33_333_333, x[i]) for i in range(len(x) - 1)]
    used = policy._tracks[0].limb_proportions()  # what the last frame's fit is given
    got.append(policy.lift(0, (len(x) - 1) * 33_333_333, x[-1]))
    est = policy._tracks[0].limb_proportions()
    assert est is not None and used is not None

    def shape(p: np.ndarray) -> np.ndarray:  # (8,) limbs -> 4 log-proportions, size removed
        q = np.asarray(p)
        g = np.log(0.5 * (q[[0, 1, 4, 5]] + q[[2, 3, 6, 7]]))
        return g - g.mean()

    true = shape(Lifter.limb_proportions_of(person[0]))
    assert np.linalg.norm(shape(est) - true) < 0.8 * np.linalg.norm(shape(bases.limb_proportions) - true)
    # the fit's limbs follow the estimate it was given (the constraint radii), not the bases'
    # proportions (the fit's own pose: the published one is smoothed over frames, see
    # tests/core/track/test_output_smoothing.py)
    last = got[-1].fit_pose_camera
    assert last is not None
    fitted = shape(Lifter.limb_proportions_of(last))
    assert np.allclose(fitted, shape(used), atol=1e-3)
    # ... and without prior_limbs they keep the bases' proportions
    other = TrackPolicy(fixed)
    plain_fit = [other.lift(0, i * 33_333_333, x[i]) for i in range(len(x))][-1].fit_pose_camera
    assert plain_fit is not None
    plain = shape(Lifter.limb_proportions_of(plain_fit))
    assert np.allclose(plain, shape(bases.limb_proportions), atol=1e-3)


def test_noisy_2d_keeps_its_weight_and_the_previous_pose_holds_only_lost_joints(
        walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """A track's 2D noise changes neither the 2D term's weight nor the prior's target (the causal
    smoothing of noisy tracks measured worse and is gone, docs/tuning.md): the lifter gets data
    weight 1 and a previous-pose weight of 0 on every joint the frame has, live and offline
    (``TrackPolicy.smoothed_later``); a joint the frame lacks takes ``missing_temporal_weight``."""
    x, _ = walk_track
    noisy = x + np.random.default_rng(0).normal(0.0, 0.1, x.shape) * np.ptp(x[0], axis=0).max() / 4.0
    lifter = Lifter(PoseBases.load(default_bases_path("hybrid")), LifterOptions(outlier_gate=0.0))
    original = lifter.lift_people
    for later in (False, True):
        tracks: list[TrackContext] = []

        def spy(calls: Sequence[LiftRow], _t: list[TrackContext] = tracks,
                _f: Callable[[Sequence[LiftRow]], list[LiftOutcome]] = original
                ) -> list[LiftOutcome]:
            _t.extend(c.track for c in calls if isinstance(c.track, TrackContext))
            return _f(calls)

        lifter.lift_people = spy  # type: ignore[method-assign]
        policy = TrackPolicy(lifter)
        policy.smoothed_later = later
        conf = np.ones(12)
        for i in range(20):
            conf[3] = 0.0 if i == 15 else 1.0  # a joint lost on one frame
            policy.lift(0, i * 33_333_333, noisy[i], conf.copy())
        assert len(tracks) == 20
        weights = np.array([np.broadcast_to(t.temporal_weight, (12,)) for t in tracks])
        assert not np.delete(weights, 3, axis=1).any() and not weights[:15, 3].any()
        assert weights[15, 3] == LifterOptions().missing_temporal_weight


def test_the_perspective_correction_gives_the_weak_perspective_image_of_the_person() -> None:
    """perspective_corrected: with the person's true depths and scale, a pinhole image of a person
    on the optical axis becomes the weak-perspective image about the centroid's depth (exact); a
    distant person's image is left as it was (perspective and weak perspective agree)."""
    from pose_lifter.core.model.synthetic import synthetic_poses
    from pose_lifter.core.track.placement import perspective_corrected

    pose = synthetic_poses(1, seed=3)[0]  # (12, 3), leg units
    pose = pose - pose.mean(axis=0)
    leg_m, f, c = 0.43, 800.0, np.array([300.0, 250.0])
    intr = ((f, f), (float(c[0]), float(c[1])))
    for z0 in (1.5, 60.0):
        cam = pose * leg_m + np.array([0.0, 0.0, z0])  # metres, camera frame, centroid on the axis
        pinhole = f * cam[:, :2] / cam[:, 2:] + c
        weak = f * cam[:, :2] / z0 + c
        scale = f * leg_m / z0  # pixels per leg unit at the centroid's depth
        out = perspective_corrected(pinhole, intr, pose[:, 2], scale, c)
        np.testing.assert_allclose(out, weak, rtol=0, atol=tol.ROUND_OFF_ACCUMULATED)
        moved = np.abs(pinhole - weak).max()
        assert moved > 5.0 if z0 < 10 else moved < 0.5  # pixels: near, the correction matters
