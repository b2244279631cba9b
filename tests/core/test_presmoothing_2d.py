"""The offline pre-smoothing of a track's 2D keypoints (core.smoothing.centred_smoothing_2d, and
offline.chains.presmoothed_inputs that applies it per track chain): noise averaged, missing
joints and gaps kept apart, the gate against outliers, off as identity."""

from __future__ import annotations

import numpy as np
import pytest
from pose_lifter.core.smoothing import centred_smoothing_2d
from pose_lifter.messages.frame import FrameSettings, SkeletonInput
from pose_lifter.offline.chains import Item, presmoothed_inputs

FRAME_NS = 33_333_333  # 30 Hz


def _still(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A person standing still: the same 12 joints (pixels) on ``n`` frames, full confidence."""
    base = np.random.default_rng(seed).uniform(100.0, 400.0, size=(12, 2))
    return np.repeat(base[None], n, axis=0), np.ones((n, 12)), np.arange(n) * FRAME_NS


def test_a_noisy_constant_track_gets_closer_to_the_constant() -> None:
    points, conf, stamps = _still(60)
    noisy = points + np.random.default_rng(1).normal(scale=3.0, size=points.shape)
    got = centred_smoothing_2d(noisy, conf, stamps, 0.05, 1.0)
    before = np.linalg.norm(noisy - points, axis=-1).mean()
    after = np.linalg.norm(got - points, axis=-1).mean()
    assert after < 0.7 * before
    # a constant stays exactly constant
    np.testing.assert_allclose(centred_smoothing_2d(points, conf, stamps, 0.05, 1.0), points, atol=1e-9)


def test_weights_follow_the_confidence() -> None:
    points, conf, stamps = _still(3)
    points[0, 0] += 10.0
    conf[0, 0] = 0.5  # the displaced frame weighs half in its neighbours' averages
    got = centred_smoothing_2d(points, conf, stamps, 0.04, 1.0)
    w = np.exp(-0.5 * (FRAME_NS * 1e-9 / 0.04) ** 2)
    expected = points[1, 0] + (0.5 * w * 10.0) / (1.0 + w + 0.5 * w)
    np.testing.assert_allclose(got[1, 0], expected, rtol=1e-12)


def test_a_missing_joint_is_not_averaged_in_and_stays_as_given() -> None:
    points, conf, stamps = _still(9)
    points[4, 3] = (0.0, 0.0)  # missing (as a checked message gives it: 0 with confidence 0)
    conf[4, 3] = 0.0
    points[6, 5] = (np.nan, np.nan)  # a non-finite point counts as missing too
    got = centred_smoothing_2d(points, conf, stamps, 0.05, 1.0)
    np.testing.assert_array_equal(got[4, 3], (0.0, 0.0))
    assert np.isnan(got[6, 5]).all()
    ok = np.ones((9, 12), bool)
    ok[4, 3] = ok[6, 5] = False
    np.testing.assert_allclose(got[ok], points[ok], atol=1e-9)  # the zeros and NaNs never leak


def test_frames_beyond_the_gap_are_not_mixed() -> None:
    points, conf, stamps = _still(10)
    points[5:] += 50.0  # the person seen elsewhere after a gap ...
    stamps[5:] += 2_000_000_000  # ... of 2 s, more than the track's timeout of 1 s
    got = centred_smoothing_2d(points, conf, stamps, 0.1, 1.0)
    np.testing.assert_allclose(got, points, atol=1e-9)
    # the same frames without the gap do mix
    stamps = np.arange(10) * FRAME_NS
    assert not np.allclose(centred_smoothing_2d(points, conf, stamps, 0.1, 1.0)[4], points[4])


def test_the_gate_keeps_an_outlier_to_its_own_frame() -> None:
    points, conf, stamps = _still(9)
    noisy = points + np.random.default_rng(2).normal(scale=1.0, size=points.shape)
    noisy[4, 2] += 300.0  # a confident outlier
    spread = centred_smoothing_2d(noisy, conf, stamps, 0.05, 1.0)
    assert np.linalg.norm(spread[3, 2] - points[3, 2]) > 20.0  # without the gate it leaks
    got = centred_smoothing_2d(noisy, conf, stamps, 0.05, 1.0, gate=0.4)
    np.testing.assert_array_equal(got[4, 2], noisy[4, 2])  # no neighbour within the gate
    assert np.linalg.norm(got[[3, 5], 2] - points[[3, 5], 2], axis=-1).max() < 5.0
    # the other joints are smoothed as without the gate
    others = np.ones((9, 12), bool)
    others[:, 2] = False
    np.testing.assert_allclose(got[others], spread[others], rtol=1e-12)


def test_off_is_the_identity_and_refusals() -> None:
    points, conf, stamps = _still(5)
    noisy = points + np.random.default_rng(3).normal(size=points.shape)
    np.testing.assert_array_equal(centred_smoothing_2d(noisy, conf, stamps, 0.0, 1.0), noisy)
    with pytest.raises(ValueError, match="non-decreasing"):
        centred_smoothing_2d(noisy, conf, stamps[::-1].copy(), 0.04, 1.0)
    with pytest.raises(ValueError, match="expected"):
        centred_smoothing_2d(noisy, conf[:, :5], stamps, 0.04, 1.0)


def test_a_chain_keeps_its_confidences_and_off_keeps_its_inputs() -> None:
    points, conf, stamps = _still(8)
    noisy = points + np.random.default_rng(4).normal(scale=2.0, size=points.shape)
    conf[2, 7] = 0.3
    chain = [Item(i, int(stamps[i]), SkeletonInput(5, noisy[i], conf[i]), None) for i in range(8)]
    settings = FrameSettings()
    off = presmoothed_inputs(chain, settings, 0.0)
    assert all(x is it.input for x, it in zip(off, chain, strict=True))
    on = presmoothed_inputs(chain, settings, 0.05)
    expected = centred_smoothing_2d(noisy, conf, stamps, 0.05, settings.track_timeout)
    for i, x in enumerate(on):
        assert x.track_id == 5
        np.testing.assert_array_equal(x.confidence, conf[i])
        np.testing.assert_array_equal(x.points, expected[i])
    # an untracked skeleton is never a chain of more than one frame; its input is kept anyway
    untracked = [Item(0, 0, SkeletonInput(-1, noisy[0], conf[0]), None)]
    assert presmoothed_inputs(untracked, settings, 0.05)[0] is untracked[0].input
