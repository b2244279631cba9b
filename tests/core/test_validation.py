"""core.validation: the lifters' shared input checks, and which joints a lift reads."""

from __future__ import annotations

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.core.baselines import ramakrishna as rk
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.results import LiftResult
from pose_lifter.core.validation import check_keypoint_sequence, check_keypoints, joint_weights
from tolerances import ROUND_OFF


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


def test_joint_weights_drop_unconfident_and_non_finite_joints_and_move_them_to_the_centroid() -> None:
    points = np.arange(48, dtype=np.float64).reshape(2, 12, 2)
    conf = np.full((2, 12), 0.8)
    conf[0, 1] = 0.05  # below the threshold
    conf[0, 2] = 1.7  # clipped to 1
    points[0, 3] = [np.nan, 5.0]  # confident, but not finite: missing
    conf[1] = 0.0  # a person without any joint that counts
    x, w = joint_weights(points, conf, 0.1)
    assert w[0, 1] == 0.0 and w[0, 2] == 1.0 and w[0, 3] == 0.0 and w[0, 0] == 0.8
    assert not w[1].any() and np.isfinite(x).all()
    kept = w[0] > 0
    centroid = (w[0, kept, None] * points[0, kept]).sum(axis=0) / w[0, kept].sum()
    np.testing.assert_allclose(x[0, ~kept], np.repeat(centroid[None], 2, axis=0), rtol=ROUND_OFF)
    assert np.array_equal(x[0, kept], points[0, kept])


@pytest.fixture(scope="module")
def lifters() -> dict[str, Lifter]:
    return {mode: Lifter(None, LifterOptions(mode=mode)) for mode in ("paper", "hybrid")}


def _lifts(lifter: Lifter, points: np.ndarray, joint: int, places: list[tuple[float, float]],
           confidences: list[float]) -> list[LiftResult]:
    out = []
    for place, c in zip(places, confidences, strict=True):
        x, conf = points.copy(), np.ones(12)
        x[joint], conf[joint] = place, c
        out.append(lifter.lift(x, conf))
    return out


def _assert_same_lift(a: LiftResult, b: LiftResult) -> None:
    np.testing.assert_allclose(b.pose, a.pose, rtol=0.0, atol=ROUND_OFF)
    np.testing.assert_allclose(b.objective, a.objective, rtol=ROUND_OFF)
    assert b.start_index == a.start_index


#: (frame of ``real_frames``, joint): paper-mode lifts whose winning start changed with where an
#: unseen joint was put (up to 0.11 leg lengths of pose) while the lift read its coordinates.
MISSING_JOINTS = [(9, 9), (2, 7), (9, 3), (11, 9)]


@pytest.mark.parametrize("mode", ["paper", "hybrid"])
def test_where_a_missing_joint_was_put_does_not_reach_the_lift(
        mode: str, lifters: dict[str, Lifter], real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """A joint of confidence 0 at (0, 0), elsewhere or NaN: the same lift. Its coordinates
    entered the solver steps' round-off, which the multi-start turned into another winner."""
    for frame, joint in MISSING_JOINTS:
        a, *others = _lifts(lifters[mode], real_frames[0][frame], joint,
                            [(0.0, 0.0), (123.0, -45.0), (np.nan, np.nan)], [0.0, 0.0, 0.0])
        assert a.weights[joint] == 0.0
        for b in others:
            _assert_same_lift(a, b)


@pytest.mark.parametrize("mode", ["paper", "hybrid"])
def test_a_confident_joint_without_coordinates_is_missing(
        mode: str, lifters: dict[str, Lifter], real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """NaN coordinates at confidence 0.9 weigh nothing: the lift of the same joint at confidence
    0 (a NaN joint that counted pulled the pose by a leg length, at 15 times the reprojection
    error)."""
    nan = (np.nan, np.nan)
    for frame, joint in [(0, 4), (5, 10)]:
        a, b = _lifts(lifters[mode], real_frames[0][frame], joint, [nan, nan], [0.9, 0.0])
        _assert_same_lift(a, b)
        assert a.weights[joint] == 0.0 and np.isfinite(a.pose).all()
        assert a.reprojection_error == pytest.approx(b.reprojection_error, rel=ROUND_OFF)
