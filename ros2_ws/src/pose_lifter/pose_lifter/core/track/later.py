"""Poses refined over the frames after them: one refiner (:class:`Refiner`) with a horizon, the
node's ``output_lag`` N (each frame published N frames late, refined over those) and ``pose-lifter
lift`` (the whole track, :attr:`~pose_lifter.core.track.policy.TrackPolicy.smoothed_later`).

A track's frames are kept as it is lifted; its 2D is smoothed over past and future frames and the
measurement update (:mod:`.measurement`) runs over them from the smoothed 2D, at every noise
level, forward and backward in time (each frame publishes the mean of the two passes), then each
pose is placed where its frame's lift put the person (:class:`Placement`) and a centred Gaussian
window (:func:`.smoothing.centred_smoothing`) averages the metric joints, the person's depth with
them. With a lag of 3 frames (0.1 s at 30 Hz) the window (+-3 frames) is whole. Output-only: the
track's fits never see it.

Live, the update stops above ``MAX_NOISE`` (:mod:`.measurement`: its causal gain would follow a
detector's noise, and its frame-correlated error most). Here each joint's 2D (the joints the
lift used) is first smoothed by a Rauch-Tung-Striebel smoother of a constant-velocity model,
which halves white 2D noise of 0.05 leg lengths, and the update's gain and depth step follow the
smoothed 2D's noise
(the track's noise times the smoother's ratio of posterior to measurement standard deviation).
A detector's frame-correlated error is not halved; the smoother's ratio, estimated for white
noise, then leaves the gain where the track's noise puts it. The update's filters (its offsets'
gain, its depths' alpha-beta filter) lag the motion; run backward in time they lag the other
way, and the mean of the two passes does not. Measured in docs/accuracy.md (the hybrid-lag and
hybrid-offline columns) and docs/cross_action.md (their decisions).
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..model.skeleton import N_JOINTS
from .defaults import MAX_LAG
from .measurement import MeasurementUpdate
from .placement import CameraIntrinsics, place_at, ray_rotations, result_centroids
from .smooth2d import smooth_track_2d
from .smoothing import centred_smoothing

if TYPE_CHECKING:
    from ..results import LiftResult
    from .state import Track

__all__ = ["MAX_LAG", "WINDOW", "LaterFrame", "Placement", "Refiner", "RunArrays", "compile_kernels",
           "mean_of_passes", "placements", "smooth_track_2d", "update_later"]


class LaterFrame(NamedTuple):
    """What the offline update (:func:`update_later`) reads of one lifted frame of a track."""

    stamp_ns: int
    pose: NDArray[np.float64]  #: (12, 3) the pose the track would publish
    points: NDArray[np.float64]  #: (12, 2) the 2D the lift read
    used: NDArray[np.bool_]  #: (12,) the joints the lift used
    noise: float | None  #: the track's 2D noise then (None: not known yet, no update)
    follows: bool  #: the frame follows the track's last one (False: the update starts again)

    @classmethod
    def of(cls, track: Track, result: LiftResult, points: NDArray[np.float64], follows: bool,
           stamp_ns: int) -> LaterFrame:
        """The frame a hybrid track just lifted (``result``: the fit, smoothed; ``points`` (12, 2)
        the 2D the lift read), copied."""
        noise = track.noise_median() if track.noise else None
        return cls(stamp_ns, np.array(result.pose_camera, dtype=np.float64),
                   np.array(points, dtype=np.float64), result.weights > 0, noise, follows)


def mean_of_passes(forward: NDArray[np.float64] | None, backward: NDArray[np.float64] | None
                   ) -> NDArray[np.float64] | None:
    """A frame's published pose (12, 3) from the update's two passes: their mean, the one that
    updated it, or None when neither did."""
    if forward is None or backward is None:
        return backward if forward is None else forward
    return 0.5 * (forward + backward)


class RunArrays(NamedTuple):
    """A run of a track's frames that follow one another, as the update reads them."""

    poses: NDArray[np.float64]  #: (T, 12, 3) the poses the track would publish
    points: NDArray[np.float64]  #: (T, 12, 2) the 2D smoothed (:func:`smooth_track_2d`), as read where not
    used: NDArray[np.bool_]  #: (T, 12) the joints the lifts used
    #: (T,) each frame's noise times the smoother's ratio (NaN: not known then)
    noise: NDArray[np.float64]

    @classmethod
    def of(cls, run: list[LaterFrame]) -> RunArrays:
        """The arrays of ``run`` (at least one frame, in time order), its 2D smoothed."""
        raw = np.array([f.points for f in run], dtype=np.float64)
        used = np.array([f.used for f in run], dtype=bool)
        smoothed, ratio = smooth_track_2d(raw, used, np.array([f.stamp_ns for f in run], dtype=np.int64))
        noise = np.array([np.nan if f.noise is None else f.noise * ratio for f in run])
        return cls(np.array([f.pose for f in run], dtype=np.float64),
                   np.where(np.isfinite(smoothed), smoothed, raw), used, noise)

    def backward_noise(self) -> NDArray[np.float64] | None:
        """The noise (T,) of the backward pass: each frame's, the run's first known one for its
        first frames (the track did not know it yet then); None when no frame has one."""
        known = self.noise[np.isfinite(self.noise)]
        return np.where(np.isfinite(self.noise), self.noise, known[0]) if known.size else None

    def update(self, state: MeasurementUpdate, order: NDArray[np.int64], depth: float, gate: float,
               restart: NDArray[np.bool_] | None = None, noise: NDArray[np.float64] | None = None
               ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """:meth:`MeasurementUpdate.run` of ``state`` over this run's frames in ``order`` (at
        ``noise``, default the frames' own): each frame's pose (T, 12, 3) and whether it was
        updated (T,)."""
        return state.run(self.poses, self.points, self.used, self.noise if noise is None else noise, order,
                         depth, gate, restart)


#: The newest frames of a track a refiner with a horizon keeps (:class:`Refiner`): 20 (0.67 s at
#: 30 Hz); its 2D is smoothed over these, its backward pass and window read at most these.
WINDOW: Final[int] = 20


class Placement(NamedTuple):
    """Where a lifted frame's pose goes in metres (:func:`.placement.place_at`): ``joints =
    leg_m * pose @ rotation.T + centroid``; the centroid and the ray's rotation follow from the
    lift's camera (scale, translation) and the intrinsics, not from the pose, so a refined pose is
    placed as the lift's."""

    rotation: NDArray[np.float64] | None  #: (3, 3) the ray's rotation (None: no intrinsics, none)
    centroid: NDArray[np.float64]  #: (3,) metres
    leg_m: float  #: the right lower leg, metres

    def place(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """The pose's joints (12, 3; ``pose`` (12, 3) camera frame, centred, leg units) in metres."""
        placed = place_at(pose[None], self.leg_m, self.centroid[None],
                          None if self.rotation is None else self.rotation[None])
        return np.asarray(placed[0], dtype=np.float64)


def placements(results: Sequence[LiftResult], leg_m: float, intrinsics: CameraIntrinsics | None,
               default_distance_m: float) -> list[Placement]:
    """The :class:`Placement` of each of ``results`` (one camera's; :func:`.placement.place_results`'s,
    which raises what it raises)."""
    centroids = result_centroids(results, leg_m, intrinsics, default_distance_m)
    rotations = ray_rotations(centroids) if intrinsics is not None else [None] * len(results)
    return [Placement(r, c, float(leg_m)) for r, c in zip(rotations, centroids, strict=True)]


@dataclass
class _Frame:
    """One kept frame of a track."""

    stamp_ns: int
    pose: NDArray[np.float64]  #: (12, 3) the published pose without the update
    later: LaterFrame | None  #: what the update reads of it (None: no update)
    placement: Placement | None  #: where its pose goes in metres (None: the model frame)
    forward: NDArray[np.float64] | None = None  #: the forward pass's pose, once taken
    taken: bool = False  #: the forward pass has taken it

    def placed(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """``pose`` (a refinement of this frame's) placed as this frame (12, 3)."""
        return pose if self.placement is None else self.placement.place(pose)


def _placed(frames: list[_Frame], poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """``poses`` (K, 12, 3; refinements of ``frames``' poses) each placed as its frame
    (:meth:`_Frame.placed`), in one pass."""
    found = [f.placement for f in frames]
    if not any(found):
        return poses
    if not all(found):
        return np.array([f.placed(p) for f, p in zip(frames, poses, strict=True)])
    places = [p for p in found if p is not None]
    rotations = (None if all(p.rotation is None for p in places)
                 else np.array([np.eye(3) if p.rotation is None else p.rotation for p in places]))
    return place_at(poses, np.array([p.leg_m for p in places]), np.array([p.centroid for p in places]),
                    rotations)


def _later(f: _Frame) -> LaterFrame:
    """What the update reads of a frame that has one."""
    assert f.later is not None
    return f.later


@dataclass
class _Track:
    """One track's kept frames and its forward pass."""

    frames: deque[_Frame]
    forward: MeasurementUpdate | None = None  #: the forward pass's state (None: starts again)
    #: the whole track's updated poses by run (its first and end index into ``frames``), by frame
    #: index; valid until a frame is added
    measured: dict[tuple[int, int], dict[int, NDArray[np.float64]]] = field(default_factory=dict)


class Refiner:
    """Tracks' poses refined over the frames after them: the node's ``output_lag`` N and ``pose-lifter
    lift`` (module docstring), one code with a horizon.

    Per track, its frames in time order, each with the pose it was lifted with, what the update
    reads of it and where it is placed. A frame's pose is refined over the frames known when it is
    asked for:

    * the update's runs (frames that follow one another) have their 2D smoothed
      (:func:`smooth_track_2d`) over the frames kept;
    * the forward pass of the update (:meth:`MeasurementUpdate.run`) takes each frame once, when its
      2D is final: with a horizon, when its pose is asked for (its 2D then smoothed with the horizon's
      frames of future), the frames after it continued on a copy; over the whole track, every frame
      at once;
    * the backward pass starts at the newest frame (with the run's first known noise for its first
      frames, whose noise the track did not know yet); each frame's updated pose is the mean of the
      two passes (:func:`mean_of_passes`);
    * each updated pose is placed as its frame (:class:`Placement`: in metres, so the window also
      smooths the placement's depth; without one, the model frame), and the centred Gaussian window
      (:func:`.smoothing.centred_smoothing`; split at a gap or a step back in time, across the
      update's runs) averages them: :meth:`pose` a frame's row of it, :meth:`poses` every row.

    With a horizon, a track keeps its newest WINDOW frames, so a frame costs the same at any point
    of a long track; over the whole track every frame is kept and each run is refined once.

    Parameters
    ----------
    horizon : int or None
        Frames of future a pose is refined with (the node's ``output_lag``, 1 to :data:`MAX_LAG`),
        or None: the whole track (every frame added before any pose is asked for).
    smoothing_s : float
        The centred window's standard deviation (seconds; ``pose-lifter lift``'s).
    gap_s : float
        A gap over this (seconds) splits the window (the track's timeout: it was forgotten).
    depth, gate : float
        The update's ``measurement_depth`` and ``measurement_gate`` (the lifter's options).
    """

    def __init__(self, horizon: int | None, smoothing_s: float, gap_s: float, depth: float, gate: float
                 ) -> None:
        if horizon is not None and not 1 <= horizon <= MAX_LAG:
            raise ValueError(f"horizon must be 1 to {MAX_LAG} frames or None, got {horizon}")
        self.horizon = horizon
        self.smoothing_s, self.gap_s, self.depth, self.gate = smoothing_s, gap_s, depth, gate
        self._tracks: dict[int, _Track] = {}

    def __len__(self) -> int:
        return len(self._tracks)

    def add(self, track_id: int, stamp_ns: int, pose: NDArray[np.float64], later: LaterFrame | None,
            placement: Placement | None = None) -> None:
        """Keep a track's newest frame: its published pose (12, 3), what the update reads of it
        (None: none) and where it is placed (None: not, the model frame; all of a track's frames
        or none). With a horizon, a stamp before the track's last one (the input clock jumped
        back) starts the track again; over the whole track the frames are kept, the update's runs
        split where a frame does not follow (:attr:`LaterFrame.follows`) and the window where the
        clock steps back."""
        t = self._tracks.get(track_id)
        if t is None or (self.horizon is not None and t.frames and stamp_ns < t.frames[-1].stamp_ns):
            t = self._tracks[track_id] = _Track(deque(maxlen=None if self.horizon is None else WINDOW))
        t.frames.append(_Frame(int(stamp_ns), np.array(pose, dtype=np.float64), later, placement))
        t.measured.clear()

    def pose(self, track_id: int, stamp_ns: int) -> NDArray[np.float64] | None:
        """The refined pose (12, 3; finite; placed) of the track's kept frame at ``stamp_ns`` (the
        latest with that stamp), over the frames kept now; None when it is no longer kept. With a
        horizon, ask for a track's frames in time order: each is taken by the forward pass when
        first asked."""
        t = self._tracks.get(track_id)
        if t is None:
            return None
        frames = list(t.frames)
        at = next((k for k in range(len(frames) - 1, -1, -1) if frames[k].stamp_ns == stamp_ns), None)
        if at is None:
            return None
        lo, hi = self._near(frames, at)
        measured: dict[int, NDArray[np.float64]] = {}
        starts = self._starts(frames)
        k = lo
        while k < hi:  # the update's runs the window reads
            first, end = self._run(starts, len(frames), k)
            measured.update(self._measured(t, frames, first, end, at))
            k = end
        near = frames[lo:hi]
        placed = _placed(near, np.array([measured.get(k, f.pose) for k, f in enumerate(near, lo)]))
        stamps = np.array([f.stamp_ns for f in frames[lo:hi]], dtype=np.int64)
        out = self._window(stamps, placed, at - lo)
        return out if np.isfinite(out).all() else frames[at].placed(frames[at].pose)

    def poses(self, track_id: int) -> NDArray[np.float64]:
        """Every kept frame's refined pose (T, 12, 3; placed), in the order added: the whole track
        (``horizon`` None), the window over every frame at once (a frame whose window is not finite
        keeps its own pose, placed)."""
        if self.horizon is not None:
            raise ValueError("poses() refines a whole track: the refiner's horizon must be None")
        t = self._tracks.get(track_id)
        if t is None:
            return np.empty((0, N_JOINTS, 3))
        frames = list(t.frames)
        measured = self.measured(track_id)
        updated = [f.pose if p is None else p for f, p in zip(frames, measured, strict=True)]
        placed = _placed(frames, np.array(updated))
        stamps = np.array([f.stamp_ns for f in frames], dtype=np.int64)
        ok: NDArray[np.bool_] = np.asarray(np.isfinite(placed).all(axis=(1, 2)), dtype=bool)
        out = centred_smoothing(np.where(ok[:, None, None], placed, 0.0), stamps, ok, self.smoothing_s,
                                self.gap_s)
        bad = ~(np.isfinite(out).all(axis=(1, 2)) & ok)
        for k in np.flatnonzero(bad):
            out[k] = frames[k].placed(frames[k].pose)
        return out

    def measured(self, track_id: int) -> list[NDArray[np.float64] | None]:
        """Each kept frame's updated pose (12, 3; not placed), in the order added, or None where
        neither pass updated it (its own pose stands); no window. Over the whole track
        (``horizon`` None)."""
        if self.horizon is not None:
            raise ValueError("measured() refines a whole track: the refiner's horizon must be None")
        t = self._tracks.get(track_id)
        if t is None:
            return []
        frames = list(t.frames)
        out: list[NDArray[np.float64] | None] = [None] * len(frames)
        for first, end in itertools.pairwise([*self._starts(frames), len(frames)]):
            for k, pose in self._measured(t, frames, first, end, first).items():
                out[k] = pose
        return out

    def _near(self, frames: list[_Frame], at: int) -> tuple[int, int]:
        """The first and end index of the frames around frame ``at`` its window may read: within
        3 standard deviations of it (and a nanosecond), no step back in time between."""
        reach = self.smoothing_s * 3e9 + 1.0 if self.smoothing_s > 0 else 0.0
        lo, hi, stamp = at, at + 1, frames[at].stamp_ns
        while lo > 0 and stamp - reach <= frames[lo - 1].stamp_ns <= frames[lo].stamp_ns:
            lo -= 1
        while hi < len(frames) and frames[hi - 1].stamp_ns <= frames[hi].stamp_ns <= stamp + reach:
            hi += 1
        return lo, hi

    @staticmethod
    def _starts(frames: list[_Frame]) -> list[int]:
        """The first index of each of the update's runs (the first frame, and each frame with an
        update that does not follow its track's last)."""
        return [k for k, f in enumerate(frames) if k == 0 or (f.later is not None and not f.later.follows)]

    @staticmethod
    def _run(starts: list[int], n: int, at: int) -> tuple[int, int]:
        """The first and end index of the run (``starts``: :meth:`_starts` of ``n`` frames) holding
        frame ``at``."""
        i = bisect.bisect_right(starts, at)
        return starts[i - 1], starts[i] if i < len(starts) else n

    def _window(self, stamps_ns: NDArray[np.int64], poses: NDArray[np.float64], at: int
                ) -> NDArray[np.float64]:
        """Row ``at`` of :func:`.smoothing.centred_smoothing` of ``poses`` (T, 12, 3; in time
        order): the Gaussian-weighted mean of the frames within 3 standard deviations of it and no
        gap over ``gap_s`` or step back in time away."""
        if self.smoothing_s <= 0:
            return np.array(poses[at], dtype=np.float64)
        t = (stamps_ns - stamps_ns[at]) * 1e-9
        dt = np.diff(t)
        segment = np.concatenate([[0], np.cumsum((dt > self.gap_s) | (dt < 0))])
        near = (segment == segment[at]) & (np.abs(t) <= 3.0 * self.smoothing_s)
        w = np.exp(-0.5 * (t[near] / self.smoothing_s) ** 2)
        return np.asarray(np.einsum("k,kjc->jc", w, poses[near]) / w.sum(), dtype=np.float64)

    def _measured(self, t: _Track, frames: list[_Frame], first: int, end: int, at: int
                  ) -> dict[int, NDArray[np.float64]]:
        """The updated poses (by index into ``frames``) of the run ``frames[first:end]`` around
        frame ``at``: over the whole track every frame of the run (computed once until a frame is
        added), with a horizon those the window around frame ``at`` reads."""
        whole = self.horizon is None
        if whole and (first, end) in t.measured:
            return t.measured[(first, end)]
        run = [k for k in range(first, end) if frames[k].later is not None]
        out: dict[int, NDArray[np.float64]] = {}
        if not run:
            return out
        later = [_later(frames[k]) for k in run]
        arrays = RunArrays.of(later)
        restart = np.array([not f.follows for f in later])  # a new run starts the pass again
        upto = len(run) if whole else sum(k <= at for k in run)  # run[:upto]: 2D final, taken
        # forward: the track's state takes each final frame once; the later ones on a copy
        new = [j for j in range(upto) if not frames[run[j]].taken]
        if t.forward is None:
            t.forward = MeasurementUpdate()
        if new:
            fout, fdone = arrays.update(t.forward, np.array(new), self.depth, self.gate, restart)
            for j in new:
                f = frames[run[j]]
                f.forward, f.taken = (fout[j] if fdone[j] else None), True
        fwd: dict[int, NDArray[np.float64] | None] = {run[j]: frames[run[j]].forward for j in range(upto)}
        if upto < len(run):
            after = np.arange(upto, len(run))
            fout, fdone = arrays.update(t.forward.copy(), after, self.depth, self.gate, restart)
            fwd.update({run[j]: fout[j] if fdone[j] else None for j in range(upto, len(run))})
        # backward: from the newest frame down to the first the window around frame ``at`` reads
        noise = arrays.backward_noise()
        if noise is not None:
            reach = -math.inf if whole else frames[at].stamp_ns - self.smoothing_s * 3e9
            back = list(itertools.takewhile(lambda j: frames[run[j]].stamp_ns >= reach,
                                            range(len(run) - 1, -1, -1)))
            bwd, bdone = arrays.update(MeasurementUpdate(), np.array(back, dtype=np.int64), self.depth,
                                       self.gate, noise=noise)
            for j in back:
                pose = mean_of_passes(fwd.get(run[j]), bwd[j] if bdone[j] else None)
                if pose is not None:
                    out[run[j]] = pose
        if whole:
            t.measured[(first, end)] = out
        return out

    def forget(self, before_ns: int) -> None:
        """Forget the tracks whose newest frame is older than ``before_ns``."""
        for track_id in [k for k, t in self._tracks.items() if t.frames[-1].stamp_ns < before_ns]:
            del self._tracks[track_id]

    def clear(self) -> None:
        self._tracks.clear()


def update_later(frames: list[LaterFrame], depth: float, gate: float) -> list[NDArray[np.float64] | None]:
    """The update of one track's frames (in time order) refined over the whole track
    (:meth:`Refiner.measured`): each frame's updated pose (12, 3), or None where neither pass
    updated it (the fit's is published)."""
    refiner = Refiner(None, 0.0, math.inf, depth, gate)
    for f in frames:
        refiner.add(0, f.stamp_ns, f.pose, f)
    return refiner.measured(0)


_COMPILED = False


def compile_kernels() -> None:
    """Compile this module's kernels (numba, ``core.numeric.jit``) or load them from their cache,
    once per process: the smoother of a short track."""
    global _COMPILED
    if _COMPILED:
        return
    points = np.arange(4 * N_JOINTS * 2, dtype=np.float64).reshape(4, N_JOINTS, 2) % 7.0
    smooth_track_2d(points, np.ones((4, N_JOINTS), dtype=bool), np.arange(4, dtype=np.int64) * 33_333_333)
    _COMPILED = True
