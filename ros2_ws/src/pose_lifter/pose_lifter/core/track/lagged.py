"""Each track's published pose a few frames late (the node's ``output_lag``).

``pose-lifter lift`` refines a track's poses with its whole recording: the measurement update
of the 2D smoothed over past and future frames, run both ways in time (:mod:`.later`), then a
centred Gaussian window over the poses (:func:`.smoothing.centred_smoothing`). A live node knows
no future, but a node that publishes each frame ``lag`` frames after it arrived knows that many.
:class:`LaggedPoses` keeps each track's last WINDOW lifted frames and gives a frame's pose as
that offline refinement over them, read at the frame: a fixed-lag smoother. With a lag of 3
frames (0.1 s at 30 Hz) the window's centred smoothing (+-3 frames) is whole and the 2D
smoother's future is mostly there; the track's earlier frames beyond the window change a
frame's pose by little (measured in docs/accuracy.md, "A node that publishes late").

The lift itself is the node's: causal, each frame lifted when it arrives; only the published
pose waits. Output-only: nothing of it feeds back into the track's next fits.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Final

import numpy as np
from numpy.typing import NDArray

from .later import LaterFrame, update_later
from .smoothing import centred_smoothing

__all__ = ["MAX_LAG", "WINDOW", "LaggedPoses", "lagged_pose"]

#: Frames of a track that a lagged pose reads at most (the newest ones): 20 (0.67 s at 30 Hz)
#: lifts within 0.2 mm of the whole past on val (docs/accuracy.md; 10 frames: 0.7 mm worse).
WINDOW: Final[int] = 20
#: The largest lag (frames): the lagged frame must be inside the window, with past frames to read.
MAX_LAG: Final[int] = 10


def lagged_pose(stamps_ns: NDArray[np.int64], poses: NDArray[np.float64], later: list[LaterFrame | None],
                at: int, smoothing_s: float, gap_s: float, depth: float, gate: float) -> NDArray[np.float64]:
    """The pose of frame ``at`` of a track's frames refined as ``pose-lifter lift`` refines a whole
    track: the offline measurement update (:func:`~.later.update_later`: the 2D smoothed over the
    frames given, the update at every noise level, forward and backward in time) of the frames
    that have one, then the centred Gaussian window (:func:`~.smoothing.centred_smoothing`) over
    the poses. Nothing here minimises beyond what those two do (each states its objective).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (T,)
        The frames' stamps, in the order they came.
    poses : ndarray, shape (T, 12, 3)
        Each frame's published pose without the update (camera frame, centred, model units).
    later : list of LaterFrame or None, length T
        What the offline update reads of each frame (None: the frame has no update; e.g. a
        learned-mode track, or ``measurement_update`` off).
    at : int
        The frame whose pose is wanted (0 <= at < T).
    smoothing_s : float
        The window's standard deviation (seconds); 0: no window.
    gap_s : float
        A gap over this (seconds) splits the window (the track was forgotten there).
    depth, gate : float
        The update's ``measurement_depth`` and ``measurement_gate``.

    Returns
    -------
    ndarray, shape (12, 3)
        Finite (a non-finite update or window leaves frame ``at``'s pose as given).
    """
    out = np.array(poses, dtype=np.float64)
    rows = [k for k, f in enumerate(later) if f is not None]
    if rows:
        updated = update_later([later[k] for k in rows], depth, gate)  # type: ignore[misc]
        for k, pose in zip(rows, updated, strict=True):
            if pose is not None and np.isfinite(pose).all():
                out[k] = pose
    smooth: NDArray[np.float64] = centred_smoothing(out, np.asarray(stamps_ns, dtype=np.int64),
                                                    np.ones(len(out), dtype=bool), smoothing_s, gap_s)[at]
    if not np.isfinite(smooth).all():
        return np.array(poses[at], dtype=np.float64)
    return smooth


@dataclass
class _Track:
    """One track's kept frames (the newest WINDOW)."""

    stamps: deque[int] = field(default_factory=lambda: deque(maxlen=WINDOW))
    poses: deque[NDArray[np.float64]] = field(default_factory=lambda: deque(maxlen=WINDOW))
    later: deque[LaterFrame | None] = field(default_factory=lambda: deque(maxlen=WINDOW))


class LaggedPoses:
    """The tracks' kept frames and their lagged poses (:func:`lagged_pose`).

    Parameters
    ----------
    smoothing_s, gap_s, depth, gate : float
        As :func:`lagged_pose` (the offline lift's window, the track timeout, the lifter's
        ``measurement_depth`` and ``measurement_gate``).
    """

    def __init__(self, smoothing_s: float, gap_s: float, depth: float, gate: float) -> None:
        self.smoothing_s, self.gap_s, self.depth, self.gate = smoothing_s, gap_s, depth, gate
        self._tracks: dict[int, _Track] = {}

    def __len__(self) -> int:
        return len(self._tracks)

    def add(self, track_id: int, stamp_ns: int, pose: NDArray[np.float64], later: LaterFrame | None) -> None:
        """Keep a track's newest frame: its published pose (12, 3) and what the offline update
        reads of it (None: none). A stamp before the track's last one (the input clock jumped
        back) starts the track again."""
        t = self._tracks.get(track_id)
        if t is None or (t.stamps and stamp_ns < t.stamps[-1]):
            t = self._tracks[track_id] = _Track()
        t.stamps.append(int(stamp_ns))
        t.poses.append(np.array(pose, dtype=np.float64))
        t.later.append(later)

    def pose(self, track_id: int, stamp_ns: int) -> NDArray[np.float64] | None:
        """The lagged pose (12, 3) of the track's kept frame at ``stamp_ns`` (the latest kept frame
        with that stamp), read over the frames kept now; None when it is no longer kept."""
        t = self._tracks.get(track_id)
        if t is None:
            return None
        at = [k for k, s in enumerate(t.stamps) if s == stamp_ns]
        if not at:
            return None
        return lagged_pose(np.array(t.stamps, dtype=np.int64), np.array(t.poses), list(t.later), at[-1],
                           self.smoothing_s, self.gap_s, self.depth, self.gate)

    def forget(self, before_ns: int) -> None:
        """Forget the tracks whose newest frame is older than ``before_ns``."""
        for track_id in [k for k, t in self._tracks.items() if t.stamps[-1] < before_ns]:
            del self._tracks[track_id]

    def clear(self) -> None:
        self._tracks.clear()
