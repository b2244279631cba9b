"""The offline centred smoothing (core.track.smoothing.centred_smoothing) against a direct reading of
its definition, and what it keeps: constants, straight-line motion, segment boundaries, frames
without a pose."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pose_lifter.core.track.smoothing import centred_smoothing

#: Relative agreement with the loop reference (the same sums in another order).
REFERENCE_REL = 1e-12
FRAME_NS = 33_333_333  # 30 Hz


def _reference(poses: np.ndarray, stamps: np.ndarray, valid: np.ndarray, sigma: float,
               gap: float) -> np.ndarray:
    """The definition, one frame at a time: Gaussian weights of the valid frames within 3 sigma
    that no gap over ``gap`` separates from the frame."""
    out = poses.copy()
    t = stamps * 1e-9
    idx = np.flatnonzero(valid)
    for i in idx:
        num, den = np.zeros(poses.shape[1:]), 0.0
        for j in idx:
            lo, hi = sorted((i, j))
            between = [k for k in idx if lo <= k <= hi]
            if any(t[b] - t[a] > gap for a, b in itertools.pairwise(between)):
                continue
            if abs(t[j] - t[i]) > 3 * sigma:
                continue
            w = np.exp(-0.5 * ((t[j] - t[i]) / sigma) ** 2)
            num += w * poses[j]
            den += w
        out[i] = num / den
    return out


def test_equals_its_definition_with_gaps_and_missing_frames() -> None:
    rng = np.random.default_rng(0)
    n = 40
    poses = rng.normal(size=(n, 12, 3))
    stamps = np.cumsum(rng.integers(1, 3, size=n)) * FRAME_NS  # frames 1 or 2 apart
    stamps[25:] += 2_000_000_000  # the track was forgotten for 2 s
    valid = rng.random(n) > 0.2
    poses[~valid] = np.nan  # never read
    got = centred_smoothing(poses, stamps, valid, 0.05, 1.0)
    ref = _reference(poses, stamps, valid, 0.05, 1.0)
    np.testing.assert_allclose(got[valid], ref[valid], rtol=REFERENCE_REL, atol=REFERENCE_REL)
    assert np.isnan(got[~valid]).all()


def test_keeps_a_still_pose_and_straight_line_motion_inside_the_window() -> None:
    rng = np.random.default_rng(1)
    base = rng.normal(size=(12, 3))
    n = 30
    stamps = np.arange(n) * FRAME_NS
    still = np.repeat(base[None], n, axis=0)
    got = centred_smoothing(still, stamps, np.ones(n, bool), 0.04, 1.0)
    np.testing.assert_allclose(got, still, atol=1e-12)
    velocity = rng.normal(size=(12, 3))
    moving = base + np.arange(n)[:, None, None] * velocity
    got = centred_smoothing(moving, stamps, np.ones(n, bool), 0.04, 1.0)
    inner = slice(4, n - 4)  # a symmetric window keeps a straight line (the ends are one-sided)
    np.testing.assert_allclose(got[inner], moving[inner], atol=1e-9)
    assert not np.allclose(got[0], moving[0])


def test_a_spike_is_spread_by_the_window_and_no_window_crosses_a_gap() -> None:
    n = 20
    stamps = np.arange(n) * FRAME_NS
    stamps[10:] += 3_000_000_000
    poses = np.zeros((n, 12, 3))
    poses[8] = 1.0  # one frame off, two frames before the gap
    got = centred_smoothing(poses, stamps, np.ones(n, bool), 0.04, 1.0)
    assert 0 < got[8, 0, 0] < 1 and got[7, 0, 0] > 0 and got[9, 0, 0] > 0
    assert np.all(got[10:] == 0.0)  # the other segment never sees it
    # the spike's weight in its own frame: w(0) / sum of w over the neighbours in the segment
    w = np.exp(-0.5 * ((np.arange(-3, 2) * FRAME_NS * 1e-9) / 0.04) ** 2)  # frames 5..9
    assert got[8, 0, 0] == pytest.approx(1.0 / w.sum(), rel=1e-12)


def test_a_step_back_in_time_starts_a_new_segment() -> None:
    """A looped recording (the clock jumps back by less than the gap): each loop is smoothed as
    if it came alone, and no window crosses the jump."""
    rng = np.random.default_rng(3)
    first, second = rng.normal(size=(2, 10, 12, 3))
    stamps = np.arange(10) * FRAME_NS
    looped = centred_smoothing(np.concatenate([first, second]), np.concatenate([stamps, stamps]),
                               np.ones(20, bool), 0.04, 1.0)
    for k, alone in enumerate((first, second)):
        np.testing.assert_array_equal(looped[10 * k:10 * (k + 1)],
                                      centred_smoothing(alone, stamps, np.ones(10, bool), 0.04, 1.0))


def test_off_and_refusals() -> None:
    poses = np.random.default_rng(2).normal(size=(5, 12, 3))
    stamps = np.arange(5) * FRAME_NS
    np.testing.assert_array_equal(centred_smoothing(poses, stamps, np.ones(5, bool), 0.0, 1.0), poses)
    bad = poses.copy()
    bad[2, 0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        centred_smoothing(bad, stamps, np.ones(5, bool), 0.04, 1.0)
    with pytest.raises(ValueError, match="expected"):
        centred_smoothing(poses[:, :, :2], stamps, np.ones(5, bool), 0.04, 1.0)
