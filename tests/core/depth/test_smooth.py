"""A track's fused joints smoothed over its frames (core/depth/smooth.py)."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.depth.smooth import LagWindow, smooth_fused, smooth_fused_at, window_std_factor
from tolerances import ROUND_OFF

FRAME_NS = 33_333_333


def _reference(x: np.ndarray, stamps: np.ndarray, valid: np.ndarray, sigma: float, gap: float
               ) -> np.ndarray:
    """The window written out frame by frame: Gaussian weights of the valid frames within 3 sigma
    and in the same segment (no gap over ``gap`` seconds between consecutive valid frames)."""
    idx = np.flatnonzero(valid)
    t = stamps[idx] * 1e-9
    segment = np.concatenate([[0], np.cumsum(np.diff(t) > gap)])
    out = x.copy()
    for a, i in enumerate(idx):
        w = np.array([np.exp(-0.5 * ((t[b] - t[a]) / sigma) ** 2)
                      if segment[b] == segment[a] and abs(t[b] - t[a]) <= 3 * sigma else 0.0
                      for b in range(len(idx))])
        out[i] = np.tensordot(w, x[idx], axes=1) / w.sum()
    return out


def test_the_joints_and_their_deviations_take_the_window_s_weights() -> None:
    rng = np.random.default_rng(0)
    n = 40
    joints = rng.normal(size=(n, 12, 3)) + np.array([0.0, 0.0, 3.0])
    std = rng.uniform(0.01, 0.1, size=(n, 12, 3))
    stamps = np.arange(n, dtype=np.int64) * FRAME_NS
    stamps[25:] += 100_000_000  # a gap over gap_s and within the window: two segments
    valid = np.ones(n, dtype=bool)
    valid[[3, 10, 11]] = False  # frames not placed on a depth image
    j, s = smooth_fused(joints, std, stamps, valid, 0.05, 0.05, std_factor=0.8)
    np.testing.assert_allclose(j, _reference(joints, stamps, valid, 0.05, 0.05), atol=ROUND_OFF)
    np.testing.assert_allclose(s[valid], 0.8 * _reference(std, stamps, valid, 0.05, 0.05)[valid],
                               atol=ROUND_OFF)
    assert np.array_equal(j[~valid], joints[~valid]) and np.array_equal(s[~valid], std[~valid])
    # no window crosses the gap: the first segment's last frame ignores the second's first
    assert not np.allclose(j[24], _reference(joints, stamps, valid, 0.05, 10.0)[24])


def test_frame_by_frame_noise_is_averaged_out() -> None:
    """Each frame's own reading error (independent between frames) shrinks under the window; a
    body moving smoothly is kept."""
    rng = np.random.default_rng(1)
    n = 300
    t = np.arange(n) / 30.0
    truth = np.zeros((n, 12, 3))
    truth[..., 2] = 3.0 + 0.3 * np.sin(2 * np.pi * 0.5 * t)[:, None]  # walking to and fro
    noisy = truth + rng.normal(scale=0.03, size=truth.shape)
    std = np.full(truth.shape, 0.03)
    j, _ = smooth_fused(noisy, std, (t * 1e9).astype(np.int64), np.ones(n, dtype=bool), 0.04, 1.0)
    before = np.sqrt(((noisy - truth) ** 2).mean())
    after = np.sqrt(((j - truth) ** 2).mean())
    assert after < 0.6 * before
    assert np.array_equal(smooth_fused(noisy, std, (t * 1e9).astype(np.int64), np.ones(n, dtype=bool),
                                       0.0, 1.0)[0], noisy)


def test_one_frame_s_window_is_the_track_s() -> None:
    """The lagged node's average of one frame over the frames it holds around it is the whole
    track's average at that frame, once those frames cover the window (+-3 sigma)."""
    rng = np.random.default_rng(2)
    n = 20
    joints = rng.normal(size=(n, 12, 3))
    std = rng.uniform(0.01, 0.1, size=(n, 12, 3))
    stamps = np.arange(n, dtype=np.int64) * FRAME_NS
    whole_j, whole_s = smooth_fused(joints, std, stamps, np.ones(n, dtype=bool), 0.04, 1.0, std_factor=0.9)
    frames = [(int(stamps[k]), joints[k], std[k]) for k in range(n)]
    for i in (0, 7, 19):
        j, s = smooth_fused_at(frames[max(0, i - 4):i], frames[i], frames[i + 1:i + 5], 0.04, 1.0,
                               std_factor=0.9)
        np.testing.assert_allclose(j, whole_j[i], atol=ROUND_OFF)
        np.testing.assert_allclose(s, whole_s[i], atol=ROUND_OFF)


def test_the_lag_window_reads_the_answered_frames_before_and_the_held_after() -> None:
    """Frame by frame, the lag's window averages each frame with the frames it answered before (as
    given to it, before their own average) and those held after it, those within 3 sigma: the
    whole track's window where the frames held cover it; a step back in time starts it again, and
    a forgotten track has no past."""
    rng = np.random.default_rng(3)
    n = 16
    joints = rng.normal(size=(n, 12, 3))
    std = rng.uniform(0.01, 0.1, size=(n, 12, 3))
    stamps = np.arange(n, dtype=np.int64) * FRAME_NS
    frames = [(int(stamps[k]), joints[k], std[k]) for k in range(n)]
    whole_j, whole_s = smooth_fused(joints, std, stamps, np.ones(n, dtype=bool), 0.04, 1.0, std_factor=0.9)
    window = LagWindow(0.04, 1.0)
    for i in range(n):  # the frames held after it: its lag's 5, past the window's 3.6 frames
        j, s = window.average(7, frames[i], frames[i + 1:i + 6], 0.9)
        np.testing.assert_allclose(j, whole_j[i], atol=ROUND_OFF)
        np.testing.assert_allclose(s, whole_s[i], atol=ROUND_OFF)
    # the input clock steps back: the frame is averaged with those after it alone
    j, _ = window.average(7, frames[2], frames[3:5], 1.0)
    np.testing.assert_allclose(j, smooth_fused_at([], frames[2], frames[3:5], 0.04, 1.0, 1.0)[0],
                               atol=ROUND_OFF)
    # another track has a past of its own; a forgotten one none
    window.average(8, frames[10], [], 1.0)
    window.forget(int(stamps[5]))  # track 7's newest answer is frame 2's
    j, _ = window.average(7, frames[3], [], 1.0)
    np.testing.assert_allclose(j, joints[3], atol=ROUND_OFF)
    j, _ = window.average(8, frames[11], [], 1.0)
    np.testing.assert_allclose(j, smooth_fused_at(frames[10:11], frames[11], [], 0.04, 1.0, 1.0)[0],
                               atol=ROUND_OFF)
    assert not np.allclose(j, joints[11])


def test_the_window_s_scale_is_for_read_joints_and_bodies_shown_whole() -> None:
    """``window_std_factor``: the factor on every joint of a body the 2D shows whole and on the
    read joints of a body it cuts, 1 on the others; ``smooth_fused`` scales each joint's averaged
    deviation by its own factor."""
    observed = np.ones((3, 12), dtype=bool)
    observed[1, [0, 3]] = False  # cut at the shoulders
    observed[2, 8] = False
    read = np.zeros((3, 12), dtype=bool)
    read[1, [6, 7, 9]] = True
    got = window_std_factor(observed, read, 0.8)
    want = np.ones((3, 12))
    want[0] = 0.8
    want[1, [6, 7, 9]] = 0.8  # row 2: cut, nothing read
    np.testing.assert_array_equal(got, want)
    rng = np.random.default_rng(4)
    n = 12
    joints = rng.normal(size=(n, 12, 3))
    std = rng.uniform(0.01, 0.1, size=(n, 12, 3))
    stamps = np.arange(n, dtype=np.int64) * FRAME_NS
    factor = rng.uniform(0.5, 1.0, size=(n, 12))
    valid = np.ones(n, dtype=bool)
    _, s = smooth_fused(joints, std, stamps, valid, 0.04, 1.0, std_factor=factor)
    _, s1 = smooth_fused(joints, std, stamps, valid, 0.04, 1.0, std_factor=1.0)
    np.testing.assert_allclose(s, s1 * factor[:, :, None], atol=ROUND_OFF)
