"""The per-track output smoothing (core.track.policy: the published pose of a hybrid track is its
prior's pose plus the fit's correction averaged over frames, and on a disturbed track the prior's
part follows an alpha-beta filter): causal, output-only, and what it buys."""

from __future__ import annotations

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions, p_mpjpe
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.policy import TrackedLift, TrackPolicy
from pose_lifter.mocap.scenes import corrupt_2d
from walker_tracks import assert_only_the_output_differs, person, track

OFF = {"correction_smoothing": 0.0, "disturbed_smoothing_gain": 1.0, "measurement_update": False}


@pytest.fixture(scope="module")
def walker() -> tuple[np.ndarray, np.ndarray]:
    """One real walker (bags/walk_clean.mcap's ground truth, CMU 07_05, an evaluation-split
    trial), 90 consecutive frames at 30 Hz, weak perspective: (pixels (90, 12, 2), centred
    camera-frame truth in metres (90, 12, 3))."""
    return person("walk_clean", 90)


def _errors(out: list[TrackedLift], truth: np.ndarray) -> tuple[float, float]:
    """(mean P-MPJPE, mean 3D acceleration error), millimetres (per frame^2), the poses scaled by
    the true right lower leg as tools/accuracy.py does."""
    leg = limb_lengths(truth)[:, RIGHT_LOWER_LEG]
    pred = np.array([t.result.pose_camera for t in out]) * leg[:, None, None]
    acc = (pred[2:] - 2 * pred[1:-1] + pred[:-2]) - (truth[2:] - 2 * truth[1:-1] + truth[:-2])
    return (1000.0 * float(np.mean(p_mpjpe(pred, truth))),
            1000.0 * float(np.linalg.norm(acc, axis=-1).mean()))


def test_the_smoothed_output_never_reads_a_later_frame(walker: tuple[np.ndarray, np.ndarray]) -> None:
    x, _ = walker
    n, k = 30, 18
    other = x[:n].copy()
    other[k:] = x[::-1][: n - k] + 25.0  # from frame k on, another motion
    a = track(LifterOptions(), x[:n])
    b = track(LifterOptions(), other)
    # default options: the output smoothing and the measurement update both publish causally
    for i in range(k):  # the same frames so far give the same outputs, whatever follows
        np.testing.assert_array_equal(a[i].result.pose_camera, b[i].result.pose_camera)
    assert not np.allclose(a[k].result.pose_camera, b[k].result.pose_camera)


def test_smoothing_feeds_nothing_back_into_the_fit(walker: tuple[np.ndarray, np.ndarray]) -> None:
    """The track's fits (coefficients, cameras, objectives) are the same with and without the
    output smoothing; only the published pose differs, and the fit's own stays available."""
    x, _ = walker
    on = track(LifterOptions(), x[:20])
    off = track(LifterOptions(**OFF), x[:20])
    assert_only_the_output_differs(on, off)
    for a, b in zip(on, off, strict=True):
        assert b.fit_pose_camera is None
        assert a.fit_pose_camera is not None
        np.testing.assert_array_equal(a.fit_pose_camera, b.result.pose_camera)


def test_smoothing_lowers_the_jitter_of_a_cleantrack(walker: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walker
    err_on, jit_on = _errors(track(LifterOptions(), x), truth)
    err_off, jit_off = _errors(track(LifterOptions(**OFF), x), truth)
    assert jit_on < 0.75 * jit_off, (jit_on, jit_off)  # measured 7.2 vs 12.7 mm/frame^2
    assert jit_on < 12.0, jit_on
    assert err_on < 1.05 * err_off, (err_on, err_off)


def test_a_disturbed_track_is_smoothed_more(walker: tuple[np.ndarray, np.ndarray]) -> None:
    """20 % confident outliers: the prior's part of the output follows the alpha-beta filter."""
    x, truth = walker
    leg_px = 160.0 * limb_lengths(truth)[:, RIGHT_LOWER_LEG]
    bad, conf = corrupt_2d(x, leg_px, 0.0, 0.2, 0.0, np.random.default_rng(3))
    err_on, jit_on = _errors(track(LifterOptions(), bad, conf), truth)
    _, jit_corr = _errors(track(LifterOptions(disturbed_smoothing_gain=1.0), bad, conf), truth)
    err_off, jit_off = _errors(track(LifterOptions(**OFF), bad, conf), truth)
    assert jit_on < 0.7 * jit_off, (jit_on, jit_off)  # measured 0.63 (flip-averaged prior; 0.57 without)
    assert jit_on < 0.8 * jit_corr, (jit_on, jit_corr)  # measured 0.63
    assert err_on < 1.05 * err_off, (err_on, err_off)


def test_image_limbs_read_a_persons_proportions_off_the_image(walker: tuple[np.ndarray, np.ndarray]) -> None:
    """A walker whose forearms are 25 % shorter and thighs 15 % longer: the track's estimate
    from its image limb lengths (``image_limbs``) is closer to the person's proportions than the
    bases' proportions are, and the limb constraints then take it."""
    from pose_lifter.mocap.views import scale_limbs

    _, truth = walker
    person = scale_limbs(truth, np.array([1.0, 0.75, 1.0, 0.75, 1.15, 1.0, 1.15, 1.0]))
    x = 160.0 * person[..., :2] + 320.0
    policy = TrackPolicy(Lifter(options=LifterOptions(image_limbs=True)))
    for i in range(60):
        policy.lift(0, i * 33_333_333, x[i])
    track = policy._tracks[0]
    spans = track.image_limb_proportions()
    assert spans is not None

    def shape(p: np.ndarray) -> np.ndarray:  # 8 limbs (pairs equal) -> 4 log-proportions, size removed
        g = np.log(0.5 * (np.asarray(p)[[0, 1, 4, 5]] + np.asarray(p)[[2, 3, 6, 7]]))
        return g - g.mean()

    true = shape(Lifter.limb_proportions_of(person[0]))
    bases = shape(policy.lifter.bases.limb_proportions)
    assert np.linalg.norm(shape(spans) - true) < 0.5 * np.linalg.norm(bases - true)
    blended = track.limb_proportions(image=True)
    prior_only = track.limb_proportions(image=False)
    assert blended is not None and prior_only is not None
    assert np.linalg.norm(shape(blended) - true) < np.linalg.norm(shape(prior_only) - true)


def test_the_smoothers_of_a_frames_tracks_update_together_as_the_recurrence() -> None:
    """``smooth_tracks`` (a frame's tracks as arrays) gives each track the smoother's recurrence
    (``CausalSmoother``'s docstring) written plainly per track, over frames where tracks start,
    run on and change their gains."""
    from pose_lifter.core.track.smoothing import CausalSmoother, smooth_tracks

    rng = np.random.default_rng(4)
    n = 7
    together = [CausalSmoother() for _ in range(n)]
    state: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = [None] * n  # c, level, velocity
    for frame in range(6):
        fits, priors = rng.normal(size=(2, n, 12, 3))
        b, gain = rng.uniform(0.0, 0.95, n), rng.uniform(0.2, 1.0, n)
        if frame == 3:  # two tracks start again (a cold frame)
            together[1], together[4] = CausalSmoother(), CausalSmoother()
            state[1] = state[4] = None
        got = smooth_tracks(together, fits, priors, b, gain)
        for i in range(n):
            st = state[i]
            if st is None:
                state[i], want = (fits[i] - priors[i], priors[i], np.zeros((12, 3))), fits[i]
            else:
                c = b[i] * st[0] + (1.0 - b[i]) * (fits[i] - priors[i])
                resid = priors[i] - (st[1] + st[2])
                level = st[1] + st[2] + gain[i] * resid
                velocity = st[2] + gain[i] ** 2 / (2.0 - gain[i]) * resid
                state[i], want = (c, level, velocity), level + c
            np.testing.assert_allclose(got[i], want, rtol=0, atol=1e-12)
            assert np.array_equal(got[i], together[i].level + together[i].correction) or st is None
