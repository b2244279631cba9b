"""Result and state types shared by the solver steps and the lifter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["Camera", "CameraResult", "LiftResult", "PoseResult", "WarmStart"]


@dataclass(frozen=True)
class Camera:
    """A weak-perspective (scaled orthographic) camera.

    ``x_j = M0 @ y_j + t`` with ``M0 = scale * rotation[:2]``.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Proper rotation, model (body) frame -> camera frame.
    scale : float
        > 0, image units per model unit.
    translation : ndarray, shape (2,)
    """

    rotation: NDArray[np.float64]
    scale: float
    translation: NDArray[np.float64]

    @property
    def projection(self) -> NDArray[np.float64]:
        """``M0 = [m1; m2]``, shape (2, 3)."""
        return np.asarray(self.scale * self.rotation[:2])

    def project(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Project a pose (12, 3) -> (12, 2)."""
        return np.asarray(pose @ self.projection.T + self.translation)


@dataclass(frozen=True)
class CameraResult:
    """Output of the camera step: the camera, its objective and diagnostics."""

    camera: Camera
    objective: float
    n_iter: int
    converged: bool


@dataclass(frozen=True)
class PoseResult:
    """Output of the pose step.

    Attributes
    ----------
    alpha : ndarray, shape (k,)
    pose : ndarray, shape (12, 3)
        ``mean + B alpha`` in the model frame.
    objective : float
        ``loss + theta ||alpha||_1`` at ``alpha``.
    limb_violation : float
        ``max_i | ||C_i y|| - sqrt(L_i) |`` (0 when the variant has no limb constraints).
    n_iter : int
    converged : bool
    """

    alpha: NDArray[np.float64]
    pose: NDArray[np.float64]
    objective: float
    limb_violation: float
    n_iter: int
    converged: bool


@dataclass(frozen=True)
class WarmStart:
    """A previous solution to start from (the live node keeps one per track)."""

    camera: Camera
    alpha: NDArray[np.float64]


@dataclass(frozen=True)
class LiftResult:
    """Everything one lift returns.

    Attributes
    ----------
    pose : ndarray, shape (12, 3)
        3D pose in the model frame, right lower leg = 1 (multiply by a leg length in metres
        for metric output).
    pose_camera : ndarray, shape (12, 3)
        The same pose rotated into the camera frame (x right, y down, z forward), centred,
        same units.
    camera : Camera
        In input image units (pixels): ``points_2d ~ camera.project(pose)``.
    alpha : ndarray, shape (k,)
    objective : float
        Final objective in normalised units (loss + theta ||alpha||_1).
    reprojection_error : float
        Mean 2D distance between visible input joints and the projection, input units.
    limb_violation : float
    n_iter : int
        Camera/pose alternations of the kept start.
    converged : bool
    n_starts : int
        Starts tried.
    start_index : int
        Which start won (-1 = the warm start, -2 = the depth-mirrored copy of the best run,
        -3 = the learned prior's pose (hybrid), -4 = the prior alone (learned mode); >= 0 the
        index of a multi-start pose).
    weights : ndarray, shape (12,)
        Per-joint weights used in the loss (0 = missing, or dropped as a confident outlier by
        the hybrid mode's outlier pass).
    prior_pose : ndarray, shape (12, 3), optional
        The learned prior's pose for this frame (hybrid and learned modes): image positions in
        input units and depths relative to the joints' mean depth, same units; None in paper mode.
    total_alternations : int
        Camera/pose alternations over all starts (the solve's work: a cold solve's screening
        alternation of every start plus the refined starts' further ones; a warm solve's
        warm and mirrored runs).
    """

    pose: NDArray[np.float64]
    pose_camera: NDArray[np.float64]
    camera: Camera
    alpha: NDArray[np.float64]
    objective: float
    reprojection_error: float
    limb_violation: float
    n_iter: int
    converged: bool
    n_starts: int
    start_index: int
    weights: NDArray[np.float64]
    total_alternations: int = 0
    prior_pose: NDArray[np.float64] | None = None

    def warm_start(self) -> WarmStart:
        """The state to warm-start the next frame of the same person."""
        return WarmStart(self.camera, self.alpha.copy())
