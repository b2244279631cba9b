"""A frame pipeline's answers published a few frames late (the node's ``output_lag``).

:class:`LaggedFrames` takes each checked frame and gives it back lifted ``lag`` frames later,
each tracked skeleton's pose refined over the frames then known
(:class:`~pose_lifter.core.track.later.Refiner` with the horizon ``lag``, the code that refines
the offline lift's tracks: the measurement update of the smoothed 2D, each pose placed where its
frame's lift put the person, and the centred window over the metric joints, over the track's
newest frames). The pipeline's policy keeps what the update reads of each frame
(:attr:`TrackPolicy.smoothed_later`) instead of running the node's causal update.

Below AHEAD_LAG frames each frame is lifted when it arrives, by the node's causal priors. From
AHEAD_LAG on, the pipeline's lifter reads ahead (``Lifter.reads_ahead``: the offline prior) and
each frame is lifted once its prior's future frames have come, with its track's next frames
(:func:`~pose_lifter.messages.frame.with_frames_ahead`, from the frames held), as ``pose-lifter
lift`` lifts it; the rest of the lag refines it.

Frames leave in the order they came, each once; :meth:`LaggedFrames.flush` gives the ones still
held (the input stopped), lifted and refined over what is known. No rclpy: the node publishes
what this gives.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import replace
from typing import Final, Generic, NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.fuse import DepthReadings
from pose_lifter.core.depth.smooth import LagWindow, window_std_factor
from pose_lifter.core.depth.uncertainty import LAGGED_STD_FACTOR
from pose_lifter.core.results import with_camera_poses
from pose_lifter.core.track.defaults import AHEAD_LAG, MAX_LAG
from pose_lifter.core.track.later import LaterFrame, Refiner, placements
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S
from pose_lifter.messages.frame import (
    CheckedFrame,
    DepthImage,
    FramePipeline,
    Intrinsics,
    LiftedSkeleton,
    SkeletonInput,
    SkipSkeleton,
    check_output,
    place_skeletons,
    with_frames_ahead,
)

__all__ = ["AHEAD_LAG", "MAX_LAG", "LaggedFrame", "LaggedFrames", "refined_skeletons"]

T = TypeVar("T")

#: The lag's window (seconds): the offline lift's centred smoothing.
LAG_SMOOTHING_S: Final[float] = OFFLINE_SMOOTHING_S


class LaggedFrame(NamedTuple, Generic[T]):
    """A frame held for the lag: the caller's ``token`` (e.g. its header and arrival time), its
    stamp, intrinsics and, per checked skeleton in order, what lifting it gave."""

    token: T
    stamp_ns: int
    intrinsics: Intrinsics
    outcomes: list[LiftedSkeleton | SkipSkeleton]

    @property
    def lifted(self) -> list[LiftedSkeleton]:
        """The lifted skeletons, in order."""
        return [x for x in self.outcomes if isinstance(x, LiftedSkeleton)]


class LaggedFrames(Generic[T]):
    """The frames of one :class:`FramePipeline`, each given ``lag`` frames after it came.

    Parameters
    ----------
    pipeline : FramePipeline
        Its policy keeps the frames for the offline update from now on
        (:attr:`~pose_lifter.core.track.policy.TrackPolicy.smoothed_later`); its lifter reads
        ahead from a lag of AHEAD_LAG on (build it with ``reads_ahead=lag >= AHEAD_LAG``).
    lag : int
        Frames (1 to :data:`MAX_LAG`).
    """

    def __init__(self, pipeline: FramePipeline, lag: int) -> None:
        if not 1 <= lag <= MAX_LAG:
            raise ValueError(f"lag must be 1 to {MAX_LAG} frames, got {lag}")
        self.pipeline, self.lag = pipeline, lag
        pipeline.policy.smoothed_later = True
        # waiting to be lifted (with the frame's depth image: at most ``ahead`` + 1 are held)
        self._inputs: deque[tuple[T, int, Intrinsics, CheckedFrame, DepthImage]] = deque()
        self._held: deque[LaggedFrame[T]] = deque()  # lifted, waiting to be refined
        self._poses = self._new_poses()
        # per track, its answered fused frames, for the next frames' window
        self._window = LagWindow(LAG_SMOOTHING_S, pipeline.settings.track_timeout)

    @property
    def ahead(self) -> int:
        """Frames each frame waits before it is lifted (its prior's future frames; 0: none)."""
        return self.pipeline.lifter.frames_ahead if self.lag >= AHEAD_LAG else 0

    def _new_poses(self) -> Refiner:
        opts = self.pipeline.lifter.options
        return Refiner(self.lag, LAG_SMOOTHING_S, self.pipeline.settings.track_timeout,
                       opts.measurement_depth, opts.measurement_gate)

    def __len__(self) -> int:
        """Frames held."""
        return len(self._inputs) + len(self._held)

    def lift(self, token: T, stamp_ns: int, intrinsics: Intrinsics, checked: CheckedFrame,
             depth: DepthImage = None) -> list[LaggedFrame[T]]:
        """A checked, answered frame (:meth:`FramePipeline.check`), with its depth image or None:
        lifted now or, reading ahead, once its prior's future frames have come; returns the frames
        now ``lag`` frames old (at most one), their tracked skeletons refined (those placed on a
        depth image keep their fused joints)."""
        self._inputs.append((token, stamp_ns, intrinsics, checked, depth))
        out: list[LaggedFrame[T]] = []
        while len(self._inputs) > self.ahead:
            out += self._lift_oldest()
        return out

    def flush(self) -> list[LaggedFrame[T]]:
        """Every frame still held, lifted and refined over the frames known now (the input
        stopped)."""
        out: list[LaggedFrame[T]] = []
        while self._inputs:
            out += self._lift_oldest()
        held = list(self._held)
        out += [self._refined(f, held[k + 1:]) for k, f in enumerate(held)]
        self._held.clear()
        return out

    def clear(self) -> None:
        """Forget the held frames and the tracks (unpublished: e.g. a lifecycle cleanup)."""
        self._inputs.clear()
        self._held.clear()
        self._poses = self._new_poses()
        self._window.clear()
        self.pipeline.policy.kept_later()

    def _lift_oldest(self) -> list[LaggedFrame[T]]:
        """Lift the oldest waiting frame (with its tracks' next frames from the frames waiting
        after it) and keep it for the refinement; the frames then refinement-lag old, refined."""
        token, stamp_ns, intrinsics, checked, depth = self._inputs.popleft()
        if self.ahead:
            checked = _with_ahead(checked, [x[3] for x in self._inputs], [x[1] for x in self._inputs],
                                  self.ahead)
        outcomes = self.pipeline.frame(checked, stamp_ns, intrinsics, depth)
        return self._hold(LaggedFrame(token, stamp_ns, intrinsics, outcomes))

    def _hold(self, frame: LaggedFrame[T]) -> list[LaggedFrame[T]]:
        """Keep a lifted frame's tracked poses and the frame; give the frames now lifted ``lag -
        ahead`` frames before it, refined."""
        opts = self.pipeline.lifter.options  # the node may have changed them since
        self._poses.depth, self._poses.gate = opts.measurement_depth, opts.measurement_gate
        self._poses.gap_s = self.pipeline.settings.track_timeout
        kept = self.pipeline.policy.kept_later()
        tracked = [s for s in frame.lifted if s.track_id >= 0]  # untracked: no past, no future
        settings = self.pipeline.settings
        try:
            placed = placements([s.result for s in tracked], settings.lower_leg_length, frame.intrinsics,
                                settings.default_distance)
        except Exception:  # (lifted, so placed once already) e.g. a camera scale not > 0: as lifted
            placed, tracked = [], []
        for s, placement in zip(tracked, placed, strict=True):
            frames = [f for f in kept.get(s.track_id, []) if f.stamp_ns == frame.stamp_ns]
            later: LaterFrame | None = frames[-1] if frames else None
            # the published pose (without the update, the output smoothing's: offline refines the
            # fit's own, which here gave P-MPJPE 0.1-0.5 mm lower but a jitter up to 0.3 higher)
            self._poses.add(s.track_id, frame.stamp_ns, s.result.pose_camera, later, placement)
        self._held.append(frame)
        out = []
        while len(self._held) > self.lag - self.ahead:
            oldest = self._held.popleft()
            out.append(self._refined(oldest, list(self._held)))
        # tracks unseen for the timeout are forgotten, as the policy forgets them
        timeout = frame.stamp_ns - round(self.pipeline.settings.track_timeout * 1e9)
        self._poses.forget(timeout)
        self._window.forget(timeout)
        return out

    def _refined(self, frame: LaggedFrame[T], after: Sequence[LaggedFrame[T]]) -> LaggedFrame[T]:
        """``frame`` with each tracked skeleton's metric joints refined (:class:`Refiner`, placed),
        its result's pose the refined joints centred; a skeleton whose refinement is not a valid
        output keeps what it was lifted with. A skeleton placed on a depth image has its fused
        joints averaged over the window (:func:`~pose_lifter.core.depth.smooth.smooth_fused_at`,
        as ``pose-lifter lift`` averages them over the track): with its track's refined fused
        joints of the frames before it and the fused joints of the frames held ``after`` it
        (fused as lifted: their refinement is to come)."""
        rows: list[tuple[int, LiftedSkeleton]] = []
        joints = []
        for k, s in enumerate(frame.outcomes):
            if not isinstance(s, LiftedSkeleton) or s.track_id < 0:
                continue
            j = self._poses.pose(s.track_id, frame.stamp_ns)
            if j is not None:
                rows.append((k, s))
                joints.append(j)
        if not rows:
            return frame
        outcomes = list(frame.outcomes)
        leg = self.pipeline.settings.lower_leg_length
        again_of = refined_skeletons([s for _, s in rows], np.array(joints), leg,
                                     [frame.intrinsics] * len(rows), self.pipeline.settings.default_distance)
        for (k, _), again in zip(rows, again_of, strict=True):
            if again is not None:  # else what it was lifted with is kept
                outcomes[k] = self._averaged(again, frame.stamp_ns, after)
        return frame._replace(outcomes=outcomes)

    def _averaged(self, s: LiftedSkeleton, stamp_ns: int, after: Sequence[LaggedFrame[T]]) -> LiftedSkeleton:
        """A refined skeleton placed on a depth image with its fused joints averaged over its
        track's window (:class:`~pose_lifter.core.depth.smooth.LagWindow`: the frames held
        ``after`` it as lifted)."""
        if s.depth is None or s.std_m is None:
            return s
        later = [(f.stamp_ns, x.joints_m, x.std_m) for f in after for x in f.lifted
                 if x.track_id == s.track_id and x.depth is not None and x.std_m is not None]
        self._window.gap_s = self.pipeline.settings.track_timeout
        factor = window_std_factor(s.result.weights > 0, np.isfinite(s.depth.depth_m), LAGGED_STD_FACTOR)
        joints, std = self._window.average(s.track_id, (stamp_ns, s.joints_m, s.std_m), later, factor)
        return replace(s, joints_m=joints, std_m=std)


def refined_skeletons(lifted: Sequence[LiftedSkeleton], joints: NDArray[np.float64], leg_m: float,
                      intrinsics: Sequence[Intrinsics], distance_m: float) -> list[LiftedSkeleton | None]:
    """Lifted skeletons with refined metric joints (``joints`` (n, 12, 3), metres, camera frame:
    :meth:`Refiner.pose`): each result's camera-frame pose the joints centred, in leg units
    (:func:`~pose_lifter.core.results.with_camera_poses`); a skeleton placed on a depth image is
    placed again, the refined pose with its frame's readings (:func:`place_skeletons`, with its
    camera's ``intrinsics``), the others keep the refined joints with their monocular standard
    deviations. None for a skeleton that is then no valid output (:func:`check_output`)."""
    from pose_lifter.core.depth.uncertainty import fit_residual, monocular_std

    centred = (joints - joints.mean(axis=1, keepdims=True)) / leg_m
    results = with_camera_poses([s.result for s in lifted], centred)
    groups: dict[tuple[Intrinsics, bool], list[int]] = {}
    for i, (s, intr) in enumerate(zip(lifted, intrinsics, strict=True)):
        groups.setdefault((intr, s.depth is not None and intr is not None), []).append(i)
    by_row: dict[int, tuple[NDArray[np.float64], NDArray[np.float64], DepthReadings | None]] = {}
    for (intr, with_depth), members in groups.items():
        again = None
        if with_depth:
            points = np.array([lifted[i].labelled_2d()[0] for i in members])
            try:
                again = place_skeletons(points, [results[i] for i in members], leg_m, distance_m, intr, None,
                                        centred[members], [lifted[i].depth for i in members])
            except Exception:  # placed as without depth
                again = None
        if again is None:
            weights = np.array([(results[i].weights > 0) for i in members], dtype=np.float64)
            residual = fit_residual([results[i] for i in members])
            sds = monocular_std(joints[members], weights, intr, residual=residual)
            again = [(joints[i], sd, None) for i, sd in zip(members, sds, strict=True)]
        by_row.update(zip(members, again, strict=True))
    placed = [by_row[i] for i in range(len(lifted))]
    out: list[LiftedSkeleton | None] = []
    for s, res, (j, std, readings) in zip(lifted, results, placed, strict=True):
        try:
            check_output(s.track_id, res, j)
        except SkipSkeleton:
            out.append(None)
            continue
        out.append(replace(s, result=res, joints_m=j, std_m=std, depth=readings))
    return out


def _with_ahead(checked: CheckedFrame, after: list[CheckedFrame], stamps: list[int], n: int) -> CheckedFrame:
    """``checked`` with each tracked skeleton's next frames (:func:`with_frames_ahead`: at most
    ``n`` of the same track id, from the ``after`` frames in order, stamped ``stamps``)."""
    skeletons: list[SkeletonInput | SkipSkeleton] = []
    for x in checked.skeletons:
        if isinstance(x, SkipSkeleton) or x.track_id < 0:
            skeletons.append(x)
            continue
        nxt = [(s, y) for s, c in zip(stamps, after, strict=True) for y in c.skeletons
               if isinstance(y, SkeletonInput) and y.track_id == x.track_id][:n]
        skeletons.append(with_frames_ahead([(0, x), *nxt], n)[0] if nxt else x)
    return replace(checked, skeletons=tuple(skeletons))
