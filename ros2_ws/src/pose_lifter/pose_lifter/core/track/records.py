"""The records a track's policy (:mod:`pose_lifter.core.track.policy`) takes and gives besides a
frame: a track's next frames (what an offline lift knows of a frame's future), a lifted frame of a
track, and the refusal of a frame older than its track's last one."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import OutOfOrderFrameError
from ..results import LiftResult

__all__ = ["FramesAhead", "OutOfOrderFrameError", "TrackedLift"]


@dataclass(frozen=True)
class FramesAhead:
    """A track's next frames as its detector gave them (what an offline lift knows of a frame's
    future; :meth:`pose_lifter.core.track.policy.TrackPolicy.lift`).

    Attributes
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Increasing, after the frame lifted.
    points : ndarray, shape (n, 12, 2)
        Input units, as the frame's.
    confidence : ndarray, shape (n, 12), optional
    """

    stamps_ns: NDArray[np.int64]
    points: NDArray[np.float64]
    confidence: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class TrackedLift:
    """One lifted frame of a track.

    Attributes
    ----------
    result : LiftResult
    warm_started : bool
        Solved from the track's previous frame.
    reinitialised : bool
        The warm solve had degraded and a cold solve replaced it (its objective was lower).
    fit_pose_camera : ndarray, shape (12, 3), optional
        The fit's own ``pose_camera`` when the output smoothing replaced ``result.pose`` and
        ``result.pose_camera`` (hybrid mode; the rest of ``result`` is the fit's), else None.
    swapped : ndarray of bool, shape (2,), optional
        The arms' and the legs' left/right labels the track swapped back on this frame
        (``LifterOptions.label_swaps``): the lift read the frame's 2D and confidence with them
        exchanged (:func:`pose_lifter.core.track.state.swap_back`); None: as given.
    """

    result: LiftResult
    warm_started: bool
    reinitialised: bool
    fit_pose_camera: NDArray[np.float64] | None = None
    swapped: NDArray[np.bool_] | None = None
