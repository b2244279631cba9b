"""core.validation: the lifters' shared input checks."""

from __future__ import annotations

import numpy as np
import pytest
from pose_lifter.core import Lifter
from pose_lifter.core.baselines import ramakrishna as rk
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.validation import check_keypoint_sequence, check_keypoints


def test_check_keypoints_returns_float64_and_full_confidence_by_default() -> None:
    pts, conf = check_keypoints(np.arange(24, dtype=np.int32).reshape(12, 2), None)
    assert pts.dtype == np.float64 and pts[11].tolist() == [22.0, 23.0]
    assert conf.dtype == np.float64 and conf.tolist() == [1.0] * 12
    nan_points = np.full((12, 2), np.nan)  # what a non-finite joint means is the lifter's policy
    assert np.isnan(check_keypoints(nan_points, np.zeros(12))[0]).all()


@pytest.mark.parametrize(("points", "confidence", "message"), [
    (np.zeros((11, 2)), None, r"points_2d must have shape \(12, 2\), got \(11, 2\)"),
    (np.zeros((12, 3)), None, r"points_2d must have shape \(12, 2\)"),
    (np.zeros((12, 2)), np.ones(17), r"confidence must have shape \(12,\), got \(17,\)"),
    (np.zeros((12, 2)), np.r_[np.ones(11), np.nan], "confidence has non-finite values"),
])
def test_both_lifters_refuse_bad_keypoints_alike(points: np.ndarray, confidence: np.ndarray | None,
                                                  message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        check_keypoints(points, confidence)
    with pytest.raises(InvalidInputError, match=message):
        Lifter().lift(points, confidence)
    with pytest.raises(InvalidInputError, match=message):
        rk.ramakrishna_lift(points, confidence, Lifter().bases)


def test_check_keypoint_sequence() -> None:
    pts, conf = check_keypoint_sequence(np.zeros((3, 12, 2)), None)
    assert pts.shape == (3, 12, 2) and conf is None
    assert check_keypoint_sequence(np.zeros((3, 12, 2)), np.ones((3, 12)))[1] is not None
    with pytest.raises(InvalidInputError, match=r"\(T, 12, 2\)"):
        check_keypoint_sequence(np.zeros((12, 2)), None)
    with pytest.raises(InvalidInputError, match=r"confidence must have shape \(3, 12\)"):
        check_keypoint_sequence(np.zeros((3, 12, 2)), np.ones((3, 11)))
