"""Checks of the lifters' inputs: the model joints' 2D points and confidences, once, at the entry.

Both lifters (:class:`pose_lifter.core.lift.lifter.Lifter` and the Ramakrishna et al. baseline) take
one skeleton as ``points_2d`` (12, 2) and an optional ``confidence`` (12,), or a sequence as
(T, 12, 2) and (T, 12). What a missing joint or a non-finite coordinate means is each lifter's
own policy; the shapes and the finiteness of the confidences are checked here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InvalidInputError
from .model.skeleton import N_JOINTS

__all__ = ["check_keypoint_sequence", "check_keypoints"]


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
