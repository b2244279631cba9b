"""The realistic detector (pose_lifter.mocap.detector_model): each fault does what it says, measured
on long synthetic tracks (statistical bounds are several standard errors wide)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pose_lifter.mocap.detector_model import (
    COCO_SIGMAS,
    CONFIDENCE_LOST,
    REALISTIC,
    DetectorModel,
    detect,
    joint_spreads,
)

T = 4000
LEG_PX = 50.0
QUIET = DetectorModel(noise=0.05, correlation=0.0, outliers=0.0, missing=0.0, limb_drop=0.0, swap=0.0,
                      lower_cut=0.0)


def _track(n: int = T) -> np.ndarray:
    """A person walking across the middle of a 640x480 image (pixels), distinct joints."""
    rng = np.random.default_rng(3)
    base = rng.uniform(-40.0, 40.0, (12, 2)) + np.array([320.0, 240.0])
    drift = np.stack([20.0 * np.sin(np.arange(n) / 30.0), np.zeros(n)], axis=1)
    return base[None] + drift[:, None]


def test_noise_is_scaled_per_joint_like_the_coco_sigmas() -> None:
    clean = _track()
    px, conf = detect(clean, np.full(T, LEG_PX), QUIET, np.random.default_rng(0))
    std = (px - clean).std(axis=(0, 2)) / LEG_PX  # per joint, per axis, leg lengths
    np.testing.assert_allclose(std, joint_spreads(0.05), rtol=0.05)
    assert std.mean() == pytest.approx(0.05, rel=0.03)
    # hips and ankles worse than shoulders and wrists
    assert std[[6, 9, 8, 11]].min() > std[[0, 3, 2, 5]].max()
    assert np.all(conf >= CONFIDENCE_LOST)


def test_errors_are_correlated_over_frames_as_set() -> None:
    clean = _track()
    for rho in (0.0, 0.7):
        px, _ = detect(clean, np.full(T, LEG_PX), replace(QUIET, correlation=rho), np.random.default_rng(1))
        e = (px - clean)[..., 0]
        lag1 = np.mean([np.corrcoef(e[1:, j], e[:-1, j])[0, 1] for j in range(12)])
        assert lag1 == pytest.approx(rho, abs=0.05)
        # the stationary variance does not depend on the correlation
        assert e.std() / LEG_PX == pytest.approx(0.05, rel=0.05)


def test_confidence_falls_with_the_error() -> None:
    clean = _track()
    px, conf = detect(clean, np.full(T, LEG_PX), QUIET, np.random.default_rng(2))
    err = np.linalg.norm(px - clean, axis=-1) / (LEG_PX * joint_spreads(0.05))
    small, large = conf[err < 1.0], conf[err > 2.5]
    assert small.mean() > large.mean() + 0.1
    assert np.corrcoef(err.ravel(), conf.ravel())[0, 1] < -0.3


def test_confident_outliers_misses_and_swaps_at_their_rates() -> None:
    clean = _track()
    model = replace(QUIET, noise=0.0, outliers=0.05, missing=0.1, swap=0.0)
    px, conf = detect(clean, np.full(T, LEG_PX), model, np.random.default_rng(3))
    off = np.linalg.norm(px - clean, axis=-1) / LEG_PX
    lost = conf < CONFIDENCE_LOST
    outlier = (off >= 1.0 - 1e-9) & ~lost
    assert outlier.mean() == pytest.approx(0.05 * 0.9, abs=0.01)  # those not lost too
    assert conf[outlier].min() >= 0.5  # confident
    assert off[outlier].max() <= 3.0 + 1e-9
    assert lost.mean() == pytest.approx(0.1, abs=0.01)
    # a swap exchanges whole arms (or legs) with their confidences
    swapped = replace(QUIET, noise=0.0, swap=0.2)
    px, conf = detect(clean, np.full(T, LEG_PX), swapped, np.random.default_rng(4))
    arms = np.all(px[:, [0, 1, 2]] == clean[:, [3, 4, 5]], axis=(1, 2))
    legs = np.all(px[:, [6, 7, 8]] == clean[:, [9, 10, 11]], axis=(1, 2))
    assert arms.mean() == pytest.approx(0.2, abs=0.03) and legs.mean() == pytest.approx(0.2, abs=0.03)
    assert np.any(arms & ~legs)


def test_limbs_drop_in_bursts_and_the_border_loses_joints() -> None:
    clean = _track()
    model = replace(QUIET, noise=0.0, limb_drop=0.04, lower_cut=0.02)
    _, conf = detect(clean, np.full(T, LEG_PX), model, np.random.default_rng(5))
    lost = conf < CONFIDENCE_LOST
    # an elbow and its wrist go together, for several frames in a row
    assert lost[:, 1].any() and np.array_equal(lost[:, 1], lost[:, 2])
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, lost[:, 1].astype(int), 0])))[::2]
    assert runs.min() >= 3
    # the lower cut takes knees and ankles, never the upper body
    assert lost[:, [7, 8, 10, 11]].mean() > lost[:, [0, 3]].mean()
    assert not lost[:, [0, 3, 6, 9]].any()
    # a person partly outside the image: the joints outside are lost, clamped to the border
    shifted = clean + np.array([300.0, 0.0])
    px, conf = detect(shifted, np.full(T, LEG_PX), QUIET, np.random.default_rng(6), (640.0, 480.0))
    outside = shifted[..., 0] > 640.0
    assert outside.any() and np.all(conf[outside] < CONFIDENCE_LOST)
    assert np.all(conf[~outside] >= CONFIDENCE_LOST)
    assert px[..., 0].max() <= 640.0


def test_the_realistic_model_is_deterministic_for_a_seed_and_finite() -> None:
    clean = _track(300)
    a = detect(clean, np.full(300, LEG_PX), REALISTIC, np.random.default_rng(7), (640.0, 480.0))
    b = detect(clean, np.full(300, LEG_PX), REALISTIC, np.random.default_rng(7), (640.0, 480.0))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.isfinite(a[0]).all() and ((a[1] >= 0) & (a[1] <= 1)).all()
    assert COCO_SIGMAS.shape == (12,)
    with pytest.raises(ValueError, match="correlation"):
        DetectorModel(correlation=1.0)
    with pytest.raises(ValueError, match=r"\(T, 12, 2\)"):
        detect(clean[:, :5], np.full(300, LEG_PX), REALISTIC, np.random.default_rng(0))
