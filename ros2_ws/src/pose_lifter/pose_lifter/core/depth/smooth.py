"""A track's fused joints smoothed over its frames, and their standard deviations with them.

A fused joint (:mod:`.fuse`) moves along its ray to its frame's depth reading, so it carries that
frame's reading error: the sensor's noise, the patch it read, a reading that was the occluder's.
These change from frame to frame while the body moves smoothly, so a window over the track's
fused joints averages them out where a window over the lifted poses before the fusion cannot (it
smooths the shape, and each frame's reading then moves the joint again). On the evaluation split
(``make rgbd-accuracy``, 3 m, level; docs/depth.md) the lagged node's answers went from 41.6 to
39.4 mm P-MPJPE with this window, their jitter from 43.8 to 10.6 mm/frame^2.

Two windows, one arithmetic: :func:`smooth_fused` over a whole track (``pose-lifter lift``), and
:class:`LagWindow` a frame at a time over the frames a lag holds (the lagged node and its
evaluation, :func:`smooth_fused_at`).

The window averages correlated errors (a limb's shape, the body's distance) as well as
independent ones, so the averaged standard deviations are scaled by a factor
(:data:`~pose_lifter.core.depth.uncertainty.SMOOTHED_STD_FACTOR` over a whole track,
:data:`~pose_lifter.core.depth.uncertainty.LAGGED_STD_FACTOR` over the lagged node's window),
measured as what keeps the smoothed joints' coverage that of the frames' own (``make
depth-calibration``), on the joints read from depth and every joint of a body the 2D shows whole
(:func:`window_std_factor`): a body the image cuts errs most in the joints the lift guesses, and
those errors last over the frames.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.uncertainty import LAGGED_STD_FACTOR, SMOOTHED_STD_FACTOR
from pose_lifter.core.model.skeleton import N_JOINTS
from pose_lifter.core.track.smoothing import centred_smoothing

__all__ = ["Fused", "LagWindow", "scaled_joints", "smooth_fused", "smooth_fused_at", "window_std_factor"]

#: One frame of a track's fused joints: (stamp_ns, joints (12, 3) metres, std (12, 3) metres).
Fused: TypeAlias = tuple[int, NDArray[np.float64], NDArray[np.float64]]


def smooth_fused(joints_m: NDArray[np.float64], std_m: NDArray[np.float64], stamps_ns: NDArray[np.int64],
                 valid: NDArray[np.bool_], sigma_s: float, gap_s: float,
                 std_factor: float | NDArray[np.float64] = SMOOTHED_STD_FACTOR
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One track's fused joints and standard deviations averaged over a centred Gaussian window
    (:func:`~pose_lifter.core.track.smoothing.centred_smoothing`: the same weights for both).

    Parameters
    ----------
    joints_m : ndarray, shape (T, 12, 3)
        The track's fused joints, metres, camera frame, in time order.
    std_m : ndarray, shape (T, 12, 3)
        Their standard deviations per axis, metres.
    stamps_ns : ndarray of int, shape (T,)
    valid : ndarray of bool, shape (T,)
        The frames placed on a depth image: only these are averaged, and only these change.
    sigma_s : float
        The window's standard deviation, seconds (<= 0: nothing changes).
    gap_s : float
        A larger gap between valid frames (or a step back in time) starts a new segment, which no
        window crosses.
    std_factor : float or ndarray, shape (T,) or (T, 12)
        The averaged standard deviations' scale (per frame, or per joint: :func:`window_std_factor`).

    Returns
    -------
    joints : ndarray, shape (T, 12, 3)
    std : ndarray, shape (T, 12, 3)
        Invalid frames as given.
    """
    ok = np.asarray(valid, dtype=bool)
    joints = np.asarray(joints_m, dtype=np.float64)
    std = np.asarray(std_m, dtype=np.float64)
    # one window for both: the joints and their deviations side by side, (T, 24, 3)
    both = centred_smoothing(np.concatenate([joints, std], axis=1), stamps_ns, ok, sigma_s, gap_s)
    out_std = std.copy()
    if sigma_s > 0 and ok.sum() >= 2:
        factor = np.asarray(std_factor, dtype=np.float64)
        factor = np.broadcast_to(factor[:, None] if factor.ndim == 1 else factor, joints.shape[:2])
        out_std[ok] = both[ok, joints.shape[1]:] * factor[ok][:, :, None]
    return both[:, :joints.shape[1]], out_std


def smooth_fused_at(before: Sequence[Fused], frame: Fused, after: Sequence[Fused], sigma_s: float,
                    gap_s: float, std_factor: float | NDArray[np.float64] = LAGGED_STD_FACTOR
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One frame's fused joints and standard deviations averaged with its track's frames around
    it, as :func:`smooth_fused` averages them over the whole track (the same where ``before`` and
    ``after`` hold the frames within three ``sigma_s`` of it): the lagged node's, whose later frames
    are those its lag holds.

    Parameters
    ----------
    before, frame, after : (stamp_ns, joints (12, 3), std (12, 3))
        The track's fused frames before it and after it, each in time order, and the frame.
    sigma_s, gap_s : as :func:`smooth_fused`
    std_factor : float or ndarray, shape (12,)
        The frame's scale (:func:`window_std_factor`).

    Returns
    -------
    joints, std : ndarray, shape (12, 3)
    """
    frames = [*before, frame, *after]
    factor = np.broadcast_to(np.asarray(std_factor, dtype=np.float64), (len(frames), N_JOINTS))
    joints, std = smooth_fused(np.array([f[1] for f in frames]), np.array([f[2] for f in frames]),
                               np.array([f[0] for f in frames], dtype=np.int64),
                               np.ones(len(frames), dtype=bool), sigma_s, gap_s, factor)
    return joints[len(before)], std[len(before)]


class LagWindow:
    """Per track, the window a lagged answer's fused joints are averaged over
    (:func:`smooth_fused_at`): the track's frames before it as they were answered (refined, fused,
    before their own average: kept here as each is averaged) and the frames the lag holds after it
    (fused as lifted, their refinement to come), those within three ``sigma_s`` of it. The lagged
    node's (:class:`pose_lifter.messages.lagged.LaggedFrames`) and the RGB-D evaluation's
    (:mod:`pose_lifter.mocap.rgbd_evaluation`), so the figures are the node's.

    Parameters
    ----------
    sigma_s, gap_s : float
        As :func:`smooth_fused` (``gap_s`` may be changed between frames: the node's track
        timeout).
    """

    def __init__(self, sigma_s: float, gap_s: float) -> None:
        self.sigma_s, self.gap_s = sigma_s, gap_s
        self._past: dict[int, deque[Fused]] = {}

    def average(self, track_id: int, frame: Fused, after: Sequence[Fused],
                std_factor: float | NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``frame``'s fused joints and standard deviations (12, 3) averaged with its track's
        answered frames before it and the frames ``after`` it (in time order; those outside the
        window are passed over); ``frame`` is then kept as its track's newest answered frame. A
        frame stamped before the track's newest starts its window again (the input clock stepped
        back)."""
        stamp, reach = frame[0], round(3 * self.sigma_s * 1e9)
        past = self._past.setdefault(track_id, deque())
        if past and past[-1][0] > stamp:  # the input clock stepped back
            past.clear()
        while past and past[0][0] < stamp - reach:
            past.popleft()
        later = [f for f in after if stamp < f[0] <= stamp + reach]
        joints, std = smooth_fused_at(list(past), frame, later, self.sigma_s, self.gap_s, std_factor)
        past.append(frame)
        return joints, std

    def forget(self, before_ns: int) -> None:
        """Forget the tracks whose newest answered frame is older than ``before_ns``."""
        for track in [t for t, past in self._past.items() if not past or past[-1][0] < before_ns]:
            del self._past[track]

    def clear(self) -> None:
        self._past.clear()


def scaled_joints(observed: NDArray[np.bool_], read: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The joints (..., 12) a window's scale applies to: those ``read`` from depth, and every joint
    of a body the 2D shows whole (every joint ``observed``); the others are the lift's guesses of a
    body the image cuts, whose errors last over the frames (module docstring)."""
    whole = np.asarray(observed, dtype=bool).all(axis=-1, keepdims=True)
    return np.asarray(whole | np.asarray(read, dtype=bool))


def window_std_factor(observed: NDArray[np.bool_], read: NDArray[np.bool_], factor: float
                      ) -> NDArray[np.float64]:
    """Per joint, the scale of its averaged standard deviation: ``factor`` on the
    :func:`scaled_joints` of ``observed`` and ``read`` (..., 12), 1 elsewhere; their shape."""
    return np.where(scaled_joints(observed, read), factor, 1.0)
