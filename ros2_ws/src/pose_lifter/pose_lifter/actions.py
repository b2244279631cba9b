"""Action recognition from short windows of poses: the downstream example's model (no rclpy).

A window is ``W`` poses ``step_s`` seconds apart, newest last. Features:

* 3D: every pose view-normalised (:func:`pose_lifter.core.normalise_pose`: centred, body frame,
  right lower leg = 1), so the camera's viewpoint and the person's size and heading drop out;
  the body frame's forward coordinate can be down-weighted (``depth_weight``): a lifted pose's
  errors are mostly in depth, which for a person facing the camera is the body's forward axis.
* 2D (the baseline without the lifter): every pose's 2D keypoints centred on their centroid and
  divided by their RMS spread; the viewpoint stays in the features.

The classifier is a nearest-neighbour vote over training windows (scikit-learn).
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.skeleton import N_JOINTS, normalise_pose

__all__ = [
    "DEFAULT_MODEL_PATH",
    "ActionClassifier",
    "PoseHistory",
    "keypoint_window_features",
    "pose_window_features",
]

#: The model shipped with the package (tools/action_recognition_eval.py writes it).
DEFAULT_MODEL_PATH: Final[Path] = Path(__file__).resolve().parent / "data" / "actions_knn.npz"

FeatureKind = Literal["3d", "2d"]


def _windows(x: Any, dims: int, what: str) -> NDArray[np.float64]:
    """``x`` as float64 windows of shape (..., W, 12, ``dims``); ``what`` names them in the error."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim < 3 or arr.shape[-2:] != (N_JOINTS, dims):
        raise InvalidInputError(f"{what} windows must be (..., W, {N_JOINTS}, {dims}), got {arr.shape}")
    return arr


def pose_window_features(poses: NDArray[np.float64], depth_weight: float = 1.0) -> NDArray[np.float64]:
    """View-normalised 3D features of pose windows.

    Parameters
    ----------
    poses : ndarray, shape (..., W, 12, 3)
        Any unit and frame (metres in the camera frame, mocap world frame, ...).
    depth_weight : float
        Factor on the body frame's forward (z) coordinate, in [0, 1] (1: all axes alike).

    Returns
    -------
    ndarray, shape (..., W * 36)
    """
    arr = _windows(poses, 3, "pose")
    if not 0.0 <= depth_weight <= 1.0:
        raise InvalidInputError(f"depth_weight must be in [0, 1], got {depth_weight}")
    norm = normalise_pose(arr) * np.array([1.0, 1.0, depth_weight])
    return np.asarray(norm.reshape(*arr.shape[:-3], -1))


def keypoint_window_features(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """2D features of keypoint windows (centred, unit RMS spread per frame).

    Parameters
    ----------
    points : ndarray, shape (..., W, 12, 2)

    Returns
    -------
    ndarray, shape (..., W * 24)
    """
    arr = _windows(points, 2, "keypoint")
    centred = arr - arr.mean(axis=-2, keepdims=True)
    spread = np.sqrt(np.mean(np.sum(centred**2, axis=-1), axis=-1))[..., None, None]
    if np.any(spread <= 0) or not np.all(np.isfinite(spread)):
        raise InvalidInputError("a keypoint frame has zero spread")
    return np.asarray((centred / spread).reshape(*arr.shape[:-3], -1))


@dataclass
class ActionClassifier:
    """k-nearest-neighbour action classifier over pose windows.

    Parameters
    ----------
    kind : {"3d", "2d"}
        Which features the windows are turned into.
    window : int
        Poses per window.
    step_s : float
        Seconds between the poses of a window.
    n_neighbors : int
    depth_weight : float
        "3d" only: see :func:`pose_window_features`.
    metadata : dict
        Saved with the model (provenance: the command, what it was trained on).

    Attributes
    ----------
    features_ : ndarray, shape (n, d)
    labels_ : ndarray of str, shape (n,)
    classes_ : list of str
    """

    kind: FeatureKind = "3d"
    window: int = 4
    step_s: float = 0.1
    n_neighbors: int = 5
    depth_weight: float = 1.0
    metadata: dict[str, Any] = field(default_factory=dict)
    features_: NDArray[np.float64] | None = None
    labels_: NDArray[np.str_] | None = None
    _knn: Any = None

    @property
    def classes_(self) -> list[str]:
        return sorted(set(self.labels_.tolist())) if self.labels_ is not None else []

    def features(self, windows: NDArray[np.float64]) -> NDArray[np.float64]:
        """Features of windows (..., W, 12, 3) for "3d" or (..., W, 12, 2) for "2d"."""
        arr = np.asarray(windows, dtype=np.float64)
        if arr.ndim < 3 or arr.shape[-3] != self.window:
            raise InvalidInputError(f"windows must hold {self.window} poses, got shape {arr.shape}")
        if self.kind == "3d":
            return pose_window_features(arr, self.depth_weight)
        return keypoint_window_features(arr)

    def fit(self, windows: NDArray[np.float64], labels: NDArray[Any]) -> ActionClassifier:
        """Store the training windows' features (n, W, 12, 3|2) and labels (n,)."""
        feats = self.features(windows).reshape(len(labels), -1)
        return self.fit_features(feats, np.asarray(labels))

    def fit_features(self, features: NDArray[np.float64], labels: NDArray[Any]) -> ActionClassifier:
        from sklearn.neighbors import KNeighborsClassifier

        feats = np.asarray(features, dtype=np.float64)
        labs = np.asarray(labels).astype(str)
        if feats.ndim != 2 or labs.shape != (feats.shape[0],) or feats.shape[0] == 0:
            raise InvalidInputError("need (n, d) features and n labels, n > 0")
        self.features_, self.labels_ = feats, labs
        self._knn = KNeighborsClassifier(n_neighbors=min(self.n_neighbors, len(labs))).fit(feats, labs)
        return self

    def predict(self, windows: NDArray[np.float64]) -> NDArray[np.str_]:
        """Labels of windows, shape (n,) for (n, W, 12, 3|2)."""
        arr = np.asarray(windows, dtype=np.float64)
        return self.predict_features(self.features(arr).reshape(-1, self.features_dim))

    def predict_features(self, features: NDArray[np.float64]) -> NDArray[np.str_]:
        if self._knn is None:
            raise InvalidInputError("the classifier is not fitted")
        return np.asarray(self._knn.predict(np.atleast_2d(features)))

    @property
    def features_dim(self) -> int:
        return self.window * N_JOINTS * (3 if self.kind == "3d" else 2)

    def save(self, path: str | Path) -> None:
        """Write an ``.npz``: the features quantised to int8 (``features * feature_scale``; unit-scale
        features: a step of max|feature| / 127, ~2 % of a lower leg; a small file), labels and settings."""
        if self.features_ is None or self.labels_ is None:
            raise InvalidInputError("the classifier is not fitted")
        scale = max(float(np.abs(self.features_).max()), 1e-12) / 127.0
        settings = {"kind": self.kind, "window": self.window, "step_s": self.step_s,
                    "n_neighbors": self.n_neighbors, "depth_weight": self.depth_weight,
                    "metadata": self.metadata}
        quantised = np.round(self.features_ / scale).astype(np.int8)
        np.savez_compressed(Path(path), features=quantised, feature_scale=np.float64(scale),
                            labels=self.labels_, settings=json.dumps(settings))

    @classmethod
    def load(cls, path: str | Path | None = None) -> ActionClassifier:
        """Read a model written by :meth:`save` (default: the packaged one).

        Raises
        ------
        InvalidInputError
            A missing file, or one that is not such a model (missing arrays or settings, an
            unknown kind, features that do not match the settings' window).
        """
        p = Path(path) if path is not None else DEFAULT_MODEL_PATH
        if not p.is_file():
            raise InvalidInputError(f"action model not found: {p} (tools/action_recognition_eval.py "
                                    "writes one)")
        try:
            with np.load(p, allow_pickle=False) as z:
                settings = json.loads(str(z["settings"]))
                features, labels = z["features"], z["labels"]
                if features.dtype == np.int8:  # quantised (older files: float16)
                    features = features * float(z["feature_scale"])
                features = features.astype(np.float64)
            kind = settings["kind"]
            if kind not in ("3d", "2d"):
                raise InvalidInputError(f"{p}: unknown feature kind {kind!r}")
            clf = cls(kind=kind, window=int(settings["window"]), step_s=float(settings["step_s"]),
                      n_neighbors=int(settings["n_neighbors"]),
                      depth_weight=float(settings.get("depth_weight", 1.0)),
                      metadata=dict(settings.get("metadata", {})))
        except (KeyError, TypeError, ValueError, OSError) as exc:
            raise InvalidInputError(f"{p}: not an action model ({exc})") from exc
        if not (clf.window > 0 and clf.step_s > 0 and clf.n_neighbors > 0 and 0.0 <= clf.depth_weight <= 1.0):
            raise InvalidInputError(f"{p}: invalid settings {settings}")
        if features.ndim != 2 or features.shape[1] != clf.features_dim or not np.all(np.isfinite(features)):
            raise InvalidInputError(f"{p}: features of shape {features.shape}, "
                                    f"expected finite (n, {clf.features_dim})")
        return clf.fit_features(features, labels)


@dataclass
class PoseHistory:
    """Recent poses of one track, to assemble windows at a fixed time step from any input rate.

    Parameters
    ----------
    window : int
    step_s : float
    """

    window: int
    step_s: float
    _stamps: deque[int] = field(default_factory=deque)
    _poses: deque[NDArray[np.float64]] = field(default_factory=deque)

    def add(self, stamp_ns: int, pose: NDArray[np.float64]) -> None:
        """Append a pose (12, 3); older stamps than the newest are ignored."""
        if self._stamps and stamp_ns <= self._stamps[-1]:
            return
        self._stamps.append(int(stamp_ns))
        self._poses.append(np.asarray(pose, dtype=np.float64))
        horizon = int((self.window + 1) * self.step_s * 1e9)
        while self._stamps and self._stamps[0] < stamp_ns - horizon:
            self._stamps.popleft()
            self._poses.popleft()

    @property
    def last_stamp_ns(self) -> int | None:
        return self._stamps[-1] if self._stamps else None

    def window_at(self, stamp_ns: int) -> NDArray[np.float64] | None:
        """Poses nearest to ``stamp - k step`` (k = W-1..0, oldest first), shape (W, 12, 3);
        None when one of them is farther than half a step from its target time."""
        if not self._stamps:
            return None
        stamps = np.asarray(self._stamps, dtype=np.int64)
        step = int(self.step_s * 1e9)
        out = []
        for k in range(self.window - 1, -1, -1):
            target = stamp_ns - k * step
            i = int(np.argmin(np.abs(stamps - target)))
            if abs(int(stamps[i]) - target) > step // 2:
                return None
            out.append(self._poses[i])
        return np.stack(out)
