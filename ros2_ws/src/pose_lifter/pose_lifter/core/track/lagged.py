"""Each track's published pose a few frames late (the node's ``output_lag``).

``pose-lifter lift`` refines a track's poses with its whole recording (:mod:`.later`): the
measurement update of the 2D smoothed over past and future frames, run forward and backward in
time (each frame the mean of the two passes), then a centred Gaussian window over the poses
(:func:`.smoothing.centred_smoothing`). A live node knows no future, but a node that publishes
each frame ``lag`` frames after it arrived knows that many. :class:`LaggedPoses` gives a frame's
pose as that refinement over the frames known then, a fixed-lag smoother:

* the track's 2D smoothed over its newest WINDOW frames (:func:`.later.smooth_track_2d`);
* the forward pass of the update carried over the whole track, each frame taken once, when its
  pose is asked for (its 2D then smoothed with ``lag`` frames of future), and continued over
  the frames after it on a copy;
* the backward pass started at the newest frame, as the offline one starts at a track's last;
* the centred window over the mean of the two passes.

With a lag of 3 frames (0.1 s at 30 Hz) the window (+-3 frames) is whole. The lift itself is the
node's (causal, each frame lifted when it arrives); only the published pose waits, and nothing
of it feeds back into the track's fits. Measured in docs/accuracy.md (the table's hybrid-lag columns).
"""

from __future__ import annotations

import itertools
from collections import deque
from dataclasses import dataclass, field
from typing import Final

import numpy as np
from numpy.typing import NDArray

from .defaults import MAX_LAG
from .later import LaterFrame, RunArrays, mean_of_passes
from .measurement import MeasurementUpdate

__all__ = ["MAX_LAG", "WINDOW", "LaggedPoses"]

#: The newest frames of a track whose 2D is smoothed for a lagged pose: 20 (0.67 s at 30 Hz);
#: its backward pass and window read at most these.
WINDOW: Final[int] = 20


@dataclass
class _Frame:
    """One kept frame of a track."""

    stamp_ns: int
    pose: NDArray[np.float64]  #: (12, 3) the published pose without the update
    later: LaterFrame | None  #: what the update reads of it (None: no update)
    forward: NDArray[np.float64] | None = None  #: the forward pass's pose, once taken
    taken: bool = False  #: the forward pass has taken it


def _later(f: _Frame) -> LaterFrame:
    """What the update reads of a frame that has one."""
    assert f.later is not None
    return f.later


@dataclass
class _Track:
    """One track's newest WINDOW frames and its forward pass."""

    frames: deque[_Frame] = field(default_factory=lambda: deque(maxlen=WINDOW))
    forward: MeasurementUpdate | None = None  #: the forward pass's state (None: starts again)


class LaggedPoses:
    """The tracks' kept frames and their lagged poses (module docstring).

    Parameters
    ----------
    smoothing_s : float
        The centred window's standard deviation (seconds; ``pose-lifter lift``'s).
    gap_s : float
        A gap over this (seconds) splits the window (the track's timeout: it was forgotten).
    depth, gate : float
        The update's ``measurement_depth`` and ``measurement_gate`` (the lifter's options).
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
        if t is None or (t.frames and stamp_ns < t.frames[-1].stamp_ns):
            t = self._tracks[track_id] = _Track()
        t.frames.append(_Frame(int(stamp_ns), np.array(pose, dtype=np.float64), later))

    def pose(self, track_id: int, stamp_ns: int) -> NDArray[np.float64] | None:
        """The lagged pose (12, 3; finite) of the track's kept frame at ``stamp_ns`` (the latest
        with that stamp), refined over the frames kept now; None when it is no longer kept. Ask
        for a track's frames in time order: each is taken by the forward pass when first asked."""
        t = self._tracks.get(track_id)
        if t is None:
            return None
        frames = list(t.frames)
        at = next((k for k in range(len(frames) - 1, -1, -1) if frames[k].stamp_ns == stamp_ns), None)
        if at is None:
            return None
        # the update's run holding the frame (a frame that does not follow its track's last starts one)
        rows = [k for k, f in enumerate(frames) if f.later is not None]
        starts = [k for k in rows if not _later(frames[k]).follows]
        first = max([k for k in starts if k <= at], default=0)
        end = min([k for k in starts if k > at], default=len(frames))
        run = [k for k in rows if first <= k < end]
        refined = [f.pose for f in frames[first:end]]
        if run:
            self._update(t, frames, run, at, first, refined)
        out = self._window(np.array([f.stamp_ns for f in frames[first:end]], dtype=np.int64), refined,
                           at - first)
        return out if np.isfinite(out).all() else np.array(frames[at].pose, dtype=np.float64)

    def _window(self, stamps_ns: NDArray[np.int64], poses: list[NDArray[np.float64]], at: int
                ) -> NDArray[np.float64]:
        """Row ``at`` of :func:`.smoothing.centred_smoothing` of ``poses`` (the frames' stamps
        increasing): the Gaussian-weighted mean of the frames within 3 standard deviations of it
        and no gap over ``gap_s`` away."""
        if self.smoothing_s <= 0:
            return np.array(poses[at], dtype=np.float64)
        t = (stamps_ns - stamps_ns[at]) * 1e-9
        gaps = np.diff(t) > self.gap_s
        segment = np.concatenate([[0], np.cumsum(gaps)])
        near = (segment == segment[at]) & (np.abs(t) <= 3.0 * self.smoothing_s)
        w = np.exp(-0.5 * (t[near] / self.smoothing_s) ** 2)
        rows = np.flatnonzero(near)
        return np.asarray(np.einsum("k,kjc->jc", w, np.array([poses[k] for k in rows])) / w.sum(),
                          dtype=np.float64)

    def _update(self, t: _Track, frames: list[_Frame], run: list[int], at: int, first: int,
                refined: list[NDArray[np.float64]]) -> None:
        """The update's two passes over the ``run`` (indices into ``frames`` of the frames with an
        update) around frame ``at``, into ``refined`` (the poses of ``frames[first:]``)."""
        later = [_later(frames[k]) for k in run]
        arrays = RunArrays.of(later)
        restart = np.array([not f.follows for f in later])  # a new run starts the pass again
        upto = sum(k <= at for k in run)  # run[:upto] are at or before the frame
        # forward: the track's state takes each frame up to this one once; the later ones on a copy
        new = [j for j in range(upto) if not frames[run[j]].taken]
        if t.forward is None:
            t.forward = MeasurementUpdate()
        if new:
            out, done = arrays.update(t.forward, np.array(new), self.depth, self.gate, restart)
            for j in new:
                f = frames[run[j]]
                f.forward, f.taken = (out[j] if done[j] else None), True
        fwd: dict[int, NDArray[np.float64] | None] = {run[j]: frames[run[j]].forward for j in range(upto)}
        if upto < len(run):
            after = np.arange(upto, len(run))
            out, done = arrays.update(t.forward.copy(), after, self.depth, self.gate, restart)
            fwd.update({run[j]: out[j] if done[j] else None for j in range(upto, len(run))})
        # backward: from the newest frame down to the first the window around this one reads
        noise = arrays.backward_noise()
        if noise is None:  # no frame of the run has a noise: neither pass updated one
            return
        reach = frames[at].stamp_ns - self.smoothing_s * 3e9
        back = list(itertools.takewhile(lambda j: frames[run[j]].stamp_ns >= reach,
                                        range(len(run) - 1, -1, -1)))
        bwd, bdone = arrays.update(MeasurementUpdate(), np.array(back, dtype=np.int64), self.depth, self.gate,
                                   noise=noise)
        for j in back:
            pose = mean_of_passes(fwd.get(run[j]), bwd[j] if bdone[j] else None)
            if pose is not None:
                refined[run[j] - first] = pose

    def forget(self, before_ns: int) -> None:
        """Forget the tracks whose newest frame is older than ``before_ns``."""
        for track_id in [k for k, t in self._tracks.items() if t.frames[-1].stamp_ns < before_ns]:
            del self._tracks[track_id]

    def clear(self) -> None:
        self._tracks.clear()
