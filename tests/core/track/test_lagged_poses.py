"""A track's lagged poses (core.track.lagged): without an update, the centred window over the
frames kept (checked against the offline lift's smoothing and the weights written out); the
window of frames kept, a clock that jumps back, forgetting idle tracks; with the update, the
forward pass of a frame is taken once."""

from __future__ import annotations

import numpy as np
import tolerances as tol
from pose_lifter.core.track.lagged import WINDOW, LaggedPoses
from pose_lifter.core.track.smoothing import centred_smoothing

STEP = 33_333_333


def _poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = np.cumsum(rng.normal(scale=0.01, size=(n, 12, 3)), axis=0) + rng.normal(size=(1, 12, 3))
    return p - p.mean(axis=1, keepdims=True)


def test_without_an_update_the_lagged_pose_is_the_offline_window_over_the_frames_kept() -> None:
    poses = _poses(12)
    stamps = np.arange(12, dtype=np.int64) * STEP
    stamps[9:] += 2 * 10**9  # a gap over the timeout: frames 9-11 are another segment
    kept = LaggedPoses(0.04, 1.0, 0.5, 0.3)
    for s, p in zip(stamps, poses, strict=True):
        kept.add(3, int(s), p, None)
    # the independent reference: the Gaussian weights written out for frame 5 (+-3 frames at 0.04 s)
    w = np.exp(-0.5 * ((np.arange(2, 9) - 5) * STEP * 1e-9 / 0.04) ** 2)
    expect = np.einsum("k,kjc->jc", w, poses[2:9]) / w.sum()
    np.testing.assert_allclose(kept.pose(3, int(stamps[5])), expect, rtol=0, atol=tol.ROUND_OFF)
    offline = centred_smoothing(poses, stamps, np.ones(12, dtype=bool), 0.04, 1.0)
    for k in (0, 7, 8, 9, 11):  # truncated at the ends and at the gap, as pose-lifter lift truncates
        np.testing.assert_allclose(kept.pose(3, int(stamps[k])), offline[k], rtol=0, atol=tol.ROUND_OFF)


def test_a_track_keeps_its_newest_window_forgets_when_idle_and_restarts_when_the_clock_jumps_back() -> None:
    kept = LaggedPoses(0.04, 1.0, 0.5, 0.3)
    poses = _poses(WINDOW + 5)
    for i, p in enumerate(poses):
        kept.add(7, i * STEP, p, None)
    assert kept.pose(7, 4 * STEP) is None  # left the window
    assert kept.pose(7, 5 * STEP) is not None and kept.pose(8, 5 * STEP) is None
    # the clock jumps back (a looped recording): the track starts again from that frame
    kept.add(7, 2 * STEP, poses[0], None)
    np.testing.assert_array_equal(kept.pose(7, 2 * STEP), poses[0])
    assert kept.pose(7, 10 * STEP) is None
    kept.add(9, 100 * STEP, poses[1], None)
    kept.forget(50 * STEP)
    assert len(kept) == 1 and kept.pose(9, 100 * STEP) is not None
