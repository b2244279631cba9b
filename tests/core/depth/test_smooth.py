"""A track's fused joints smoothed over its frames (core/depth/smooth.py)."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.depth.smooth import smooth_fused, smooth_fused_at
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
    whole_j, whole_s = smooth_fused(joints, std, stamps, np.ones(n, dtype=bool), 0.04, 1.0)
    frames = [(int(stamps[k]), joints[k], std[k]) for k in range(n)]
    for i in (0, 7, 19):
        j, s = smooth_fused_at(frames[max(0, i - 4):i], frames[i], frames[i + 1:i + 5], 0.04, 1.0)
        np.testing.assert_allclose(j, whole_j[i], atol=ROUND_OFF)
        np.testing.assert_allclose(s, whole_s[i], atol=ROUND_OFF)
