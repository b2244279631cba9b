"""The downstream example's model (pose_lifter.actions): features, k-NN, pose history."""

from __future__ import annotations

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.actions import (
    ActionClassifier,
    PoseHistory,
    keypoint_window_features,
    pose_window_features,
)
from pose_lifter.core.errors import InvalidInputError
from scipy.spatial.transform import Rotation

#: A standing person (metres, y up), paper joint order.
STANDING = np.array([
    [0.19, 1.42, 0.0], [0.24, 1.13, 0.05], [0.26, 0.88, 0.12],
    [-0.19, 1.42, 0.0], [-0.24, 1.13, 0.05], [-0.26, 0.88, 0.12],
    [0.10, 0.92, 0.0], [0.11, 0.50, 0.03], [0.11, 0.08, 0.0],
    [-0.10, 0.92, 0.0], [-0.11, 0.50, 0.03], [-0.11, 0.08, 0.0],
])


def windows(n: int, seed: int, raise_arm: bool) -> np.ndarray:
    """n windows of 4 noisy standing poses; with ``raise_arm`` the left wrist goes up."""
    rng = np.random.default_rng(seed)
    base = STANDING.copy()
    if raise_arm:
        base[1] = [0.30, 1.65, 0.05]
        base[2] = [0.32, 1.90, 0.05]
    return base + 0.02 * rng.normal(size=(n, 4, 12, 3))


def test_3d_features_ignore_viewpoint_size_and_position_2d_features_do_not() -> None:
    w = windows(1, 0, False)[0]
    rot = Rotation.from_euler("yx", [70.0, 20.0], degrees=True).as_matrix()
    moved = 1.7 * w @ rot.T + np.array([3.0, -1.0, 8.0])
    np.testing.assert_allclose(pose_window_features(moved), pose_window_features(w),
                               atol=tol.ROUND_OFF_ACCUMULATED)
    f2 = keypoint_window_features(w[..., :2])
    np.testing.assert_allclose(keypoint_window_features(2.0 * w[..., :2] + 5.0), f2, atol=tol.ROUND_OFF)
    assert not np.allclose(keypoint_window_features(moved[..., :2]), f2, atol=1e-3)


def test_classifier_separates_actions_from_any_view_and_round_trips(tmp_path: object) -> None:
    from pathlib import Path

    train = np.concatenate([windows(30, 1, False), windows(30, 2, True)])
    labels = np.array(["stand"] * 30 + ["wave"] * 30)
    clf = ActionClassifier("3d", window=4, step_s=0.1, n_neighbors=3).fit(train, labels)
    assert clf.classes_ == ["stand", "wave"]
    rot = Rotation.from_euler("y", 135.0, degrees=True).as_matrix()
    test = np.concatenate([windows(10, 3, False), windows(10, 4, True)]) @ rot.T
    truth = np.array(["stand"] * 10 + ["wave"] * 10)
    assert (clf.predict(test) == truth).all()
    path = Path(str(tmp_path)) / "model.npz"
    clf.save(path)
    back = ActionClassifier.load(path)
    assert (back.kind, back.window, back.step_s) == ("3d", 4, 0.1)
    assert (back.predict(test) == truth).all()
    with pytest.raises(InvalidInputError):
        clf.predict(test[:, :3])  # 3 poses for a 4-pose model
    with pytest.raises(InvalidInputError):
        ActionClassifier.load(Path(str(tmp_path)) / "missing.npz")


def test_pose_history_assembles_windows_at_the_model_step_from_any_rate() -> None:
    hist = PoseHistory(window=4, step_s=0.1)
    poses = [np.full((12, 3), float(i)) for i in range(40)]
    for i, p in enumerate(poses):  # 50 Hz input
        hist.add(i * 20_000_000, p)
    w = hist.window_at(39 * 20_000_000)
    assert w is not None and w.shape == (4, 12, 3)
    np.testing.assert_allclose(w[:, 0, 0], [24.0, 29.0, 34.0, 39.0])  # 0.1 s = 5 frames apart
    hist.add(10 * 20_000_000, poses[0])  # older than the newest: ignored
    assert hist.last_stamp_ns == 39 * 20_000_000
    sparse = PoseHistory(window=4, step_s=0.1)
    for i in (0, 1, 3):  # a gap: no pose near t - 0.2 s
        sparse.add(i * 100_000_000, poses[i])
    assert sparse.window_at(3 * 100_000_000) is None


def test_depth_weight_scales_the_body_forward_axis_and_round_trips(tmp_path: object) -> None:
    from pathlib import Path

    w = windows(2, 5, True)
    full = pose_window_features(w).reshape(2, 4, 12, 3)
    part = pose_window_features(w, depth_weight=0.25).reshape(2, 4, 12, 3)
    np.testing.assert_allclose(part[..., :2], full[..., :2], atol=tol.ROUND_OFF)
    np.testing.assert_allclose(part[..., 2], 0.25 * full[..., 2], atol=tol.ROUND_OFF)
    assert np.abs(full[..., 2]).max() > 0.05  # the test poses do have depth
    with pytest.raises(InvalidInputError):
        pose_window_features(w, depth_weight=1.5)
    train = np.concatenate([windows(20, 1, False), windows(20, 2, True)])
    labels = np.array(["stand"] * 20 + ["wave"] * 20)
    clf = ActionClassifier("3d", window=4, step_s=0.1, n_neighbors=3, depth_weight=0.25).fit(train, labels)
    np.testing.assert_allclose(clf.features(w), pose_window_features(w, 0.25).reshape(2, -1))
    path = Path(str(tmp_path)) / "model.npz"
    clf.save(path)
    back = ActionClassifier.load(path)
    assert back.depth_weight == 0.25
    np.testing.assert_allclose(back.features(w), clf.features(w))
    assert clf.features_ is not None and back.features_ is not None
    with np.load(path) as z:
        assert z["features"].dtype == np.int8
        step = float(z["feature_scale"])
    assert step < 0.03 and np.abs(back.features_ - clf.features_).max() <= 0.5 * step + tol.ROUND_OFF


def test_load_rejects_files_that_are_not_action_models(tmp_path: object) -> None:
    import json
    from pathlib import Path

    d = Path(str(tmp_path))
    settings = {"kind": "3d", "window": 4, "step_s": 0.1, "n_neighbors": 3}
    ok = np.zeros((5, 4 * 36), np.float16)
    np.savez(d / "good.npz", features=ok, labels=np.array(["a"] * 5), settings=json.dumps(settings))
    assert ActionClassifier.load(d / "good.npz").depth_weight == 1.0  # files without it: all axes alike
    labels = np.array(["a"] * 5)
    bad = {
        "no_labels": {"features": ok, "settings": json.dumps(settings)},
        "wrong_dim": {"features": ok[:, :100], "labels": labels, "settings": json.dumps(settings)},
        "kind": {"features": ok, "labels": labels, "settings": json.dumps({**settings, "kind": "x"})},
        "weight": {"features": ok, "labels": labels,
                   "settings": json.dumps({**settings, "depth_weight": 2.0})},
        "int8_no_scale": {"features": ok.astype(np.int8), "labels": labels, "settings": json.dumps(settings)},
        "pickled": {"features": ok, "labels": labels, "settings": np.array([settings], dtype=object)},
    }
    for name, arrays in bad.items():
        np.savez(d / f"{name}.npz", **arrays)  # type: ignore[arg-type]
        with pytest.raises(InvalidInputError):
            ActionClassifier.load(d / f"{name}.npz")
