"""Checks of the lifters' inputs: the model joints' 2D points and confidences, once, at the entry.

Both lifters (:class:`pose_lifter.core.lift.lifter.Lifter` and the Ramakrishna et al. baseline) take
one skeleton as ``points_2d`` (12, 2) and an optional ``confidence`` (12,), or a sequence as
(T, 12, 2) and (T, 12). The shapes and the finiteness of the confidences are checked here.
:func:`joint_weights` is the paper lifter's reading of the checked input: which joints count,
with what weight, and a missing joint's coordinates replaced, so that nothing downstream reads
what a detector put there.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InvalidInputError
from .model.skeleton import N_JOINTS

__all__ = ["check_keypoint_sequence", "check_keypoints", "joint_weights", "weighted_centroids"]


def check_keypoints(points_2d: ArrayLike, confidence: ArrayLike | None
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One skeleton's points and confidences as float64 arrays.

    Parameters
    ----------
    points_2d : array_like, shape (12, 2)
        May hold non-finite values (the caller decides what they mean).
    confidence : array_like, shape (12,), optional
        None: every joint fully confident.

    Returns
    -------
    points : ndarray, shape (12, 2)
    confidence : ndarray, shape (12,)
        Finite.

    Raises
    ------
    InvalidInputError
        A shape is wrong or a confidence is not finite.
    """
    x = np.asarray(points_2d, dtype=np.float64)
    if x.shape != (N_JOINTS, 2):
        raise InvalidInputError(f"points_2d must have shape ({N_JOINTS}, 2), got {x.shape}")
    if confidence is None:
        return x, np.ones(N_JOINTS)
    conf = np.asarray(confidence, dtype=np.float64)
    if conf.shape != (N_JOINTS,):
        raise InvalidInputError(f"confidence must have shape ({N_JOINTS},), got {conf.shape}")
    if not np.isfinite(conf).all():
        raise InvalidInputError("confidence has non-finite values")
    return x, conf


def check_keypoint_sequence(points_2d: ArrayLike, confidence: ArrayLike | None
                            ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """A sequence's points (T, 12, 2) and confidences (T, 12) (None stays None) as float64
    arrays; each frame is checked further by :func:`check_keypoints` when it is lifted.

    Raises
    ------
    InvalidInputError
        A shape is wrong.
    """
    pts = np.asarray(points_2d, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[1:] != (N_JOINTS, 2):
        raise InvalidInputError(f"points_2d must have shape (T, {N_JOINTS}, 2), got {pts.shape}")
    conf = None if confidence is None else np.asarray(confidence, dtype=np.float64)
    if conf is not None and conf.shape != pts.shape[:2]:
        raise InvalidInputError(f"confidence must have shape {pts.shape[:2]}, got {conf.shape}")
    return pts, conf


def joint_weights(points: NDArray[np.float64], confidence: NDArray[np.float64], threshold: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The weights the lift gives n people's joints, and their points with every missing joint
    at one canonical place.

    A joint is missing (weight 0) when its confidence is below ``threshold`` or a coordinate is
    not finite, whatever its confidence; the others weigh their confidence clipped to [0, 1].
    A missing joint is moved to the weighted centroid of its person's joints with weight (0 when
    there is none), so the lift is a function of the joints that count: where a detector put a
    joint it did not see (0, 0, NaN or anywhere) cannot reach the fit, not even through the
    round-off of its solver steps, which a multi-start would turn into another winning start.

    Parameters
    ----------
    points : ndarray, shape (n, 12, 2)
        Checked by :func:`check_keypoints`; may hold non-finite values.
    confidence : ndarray, shape (n, 12)
        Finite.
    threshold : float
        The lowest confidence of a joint that counts.

    Returns
    -------
    points : ndarray, shape (n, 12, 2)
        Finite.
    weights : ndarray, shape (n, 12)
        In [0, 1].
    """
    weights = np.where(confidence >= threshold, confidence.clip(0.0, 1.0), 0.0)
    bad = np.asarray(~np.isfinite(points).all(axis=2))
    weights[bad] = 0.0
    held = np.where(bad[:, :, None], 0.0, points)
    centroid = weighted_centroids(held, weights)
    return np.where((weights > 0.0)[:, :, None], held, centroid[:, None, :]), weights


def weighted_centroids(points: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """The weighted centroid (n, 2) of each of n people's finite points (n, 12, 2) with weights
    (n, 12) >= 0: ``sum_j w_j x_j / sum_j w_j``, 0 for a person without weight."""
    total = weights.sum(axis=1)  # (n,)
    return np.asarray((weights[:, None, :] @ points)[:, 0, :] / np.where(total > 0.0, total, 1.0)[:, None])
