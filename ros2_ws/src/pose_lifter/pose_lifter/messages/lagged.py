"""A frame pipeline's answers published a few frames late (the node's ``output_lag``).

:class:`LaggedFrames` holds each lifted frame until ``lag`` later frames have been lifted, then
gives it with each skeleton's pose refined over the frames then known
(:class:`~pose_lifter.core.track.lagged.LaggedPoses`: the offline lift's measurement update of
the smoothed 2D and its centred window, over the track's newest frames) and placed again in the
camera frame. The lift is the pipeline's own, each frame lifted when it arrives; the pipeline's
policy keeps what the update reads of each frame (:attr:`TrackPolicy.smoothed_later`) instead of
running the node's causal update.

Frames leave in the order they came, each once: a frame answered unlagged today is answered
``lag`` frames later, none is dropped (:meth:`LaggedFrames.flush` gives the ones still held, e.g.
when the input stops). No rclpy: the node publishes what this gives.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from typing import Final, Generic, NamedTuple, TypeVar

import numpy as np

from pose_lifter.core.results import with_camera_poses
from pose_lifter.core.track.lagged import MAX_LAG, LaggedPoses
from pose_lifter.core.track.later import LaterFrame
from pose_lifter.core.track.placement import place_poses
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S
from pose_lifter.messages.frame import FramePipeline, Intrinsics, LiftedSkeleton, check_output

__all__ = ["MAX_LAG", "LaggedFrame", "LaggedFrames"]

T = TypeVar("T")

#: The lag's window (seconds): the offline lift's centred smoothing.
LAG_SMOOTHING_S: Final[float] = OFFLINE_SMOOTHING_S


class LaggedFrame(NamedTuple, Generic[T]):
    """A frame held for the lag: the caller's ``token`` (e.g. its header and arrival time), its
    stamp, intrinsics and lifted skeletons."""

    token: T
    stamp_ns: int
    intrinsics: Intrinsics
    lifted: list[LiftedSkeleton]


class LaggedFrames(Generic[T]):
    """The frames of one :class:`FramePipeline`, each given ``lag`` frames after it was lifted.

    Parameters
    ----------
    pipeline : FramePipeline
        Its policy keeps the frames for the offline update from now on
        (:attr:`~pose_lifter.core.track.policy.TrackPolicy.smoothed_later`).
    lag : int
        Frames (1 to :data:`MAX_LAG`).
    """

    def __init__(self, pipeline: FramePipeline, lag: int) -> None:
        if not 1 <= lag <= MAX_LAG:
            raise ValueError(f"lag must be 1 to {MAX_LAG} frames, got {lag}")
        self.pipeline, self.lag = pipeline, lag
        pipeline.policy.smoothed_later = True
        self._held: deque[LaggedFrame[T]] = deque()
        self._poses = self._new_poses()

    def _new_poses(self) -> LaggedPoses:
        opts = self.pipeline.lifter.options
        return LaggedPoses(LAG_SMOOTHING_S, self.pipeline.settings.track_timeout, opts.measurement_depth,
                           opts.measurement_gate)

    def __len__(self) -> int:
        """Frames held."""
        return len(self._held)

    def push(self, token: T, stamp_ns: int, intrinsics: Intrinsics, lifted: list[LiftedSkeleton]
             ) -> list[LaggedFrame[T]]:
        """A frame the pipeline just lifted (``lifted``: its skeletons, in order); returns the
        frames now ``lag`` frames old (at most one), their skeletons refined."""
        opts = self.pipeline.lifter.options  # the node may have changed them since
        self._poses.depth, self._poses.gate = opts.measurement_depth, opts.measurement_gate
        self._poses.gap_s = self.pipeline.settings.track_timeout
        kept = self.pipeline.policy.kept_later()
        for s in lifted:
            if s.track_id < 0:  # untracked: no past, no future; published as lifted
                continue
            frames = [f for f in kept.get(s.track_id, []) if f.stamp_ns == stamp_ns]
            later: LaterFrame | None = frames[-1] if frames else None
            self._poses.add(s.track_id, stamp_ns, s.result.pose_camera, later)
        self._held.append(LaggedFrame(token, stamp_ns, intrinsics, lifted))
        out = []
        while len(self._held) > self.lag:
            out.append(self._refined(self._held.popleft()))
        # tracks unseen for the timeout are forgotten, as the policy forgets them
        self._poses.forget(stamp_ns - round(self.pipeline.settings.track_timeout * 1e9))
        return out

    def flush(self) -> list[LaggedFrame[T]]:
        """Every frame still held, refined over the frames known now (the input stopped)."""
        out = [self._refined(f) for f in self._held]
        self._held.clear()
        return out

    def clear(self) -> None:
        """Forget the held frames and the tracks (unpublished: e.g. a lifecycle cleanup)."""
        self._held.clear()
        self._poses = self._new_poses()
        self.pipeline.policy.kept_later()

    def _refined(self, frame: LaggedFrame[T]) -> LaggedFrame[T]:
        """``frame`` with each tracked skeleton's pose refined (:class:`LaggedPoses`) and placed
        again; a skeleton whose refined pose cannot be placed keeps the pose it was lifted with."""
        rows, poses = [], []
        for k, s in enumerate(frame.lifted):
            pose = self._poses.pose(s.track_id, frame.stamp_ns) if s.track_id >= 0 else None
            if pose is not None:
                rows.append(k)
                poses.append(pose)
        if not rows:
            return frame
        st = self.pipeline.settings
        results = with_camera_poses([frame.lifted[k].result for k in rows], np.array(poses))
        focal, centre = frame.intrinsics if frame.intrinsics is not None else (None, None)
        try:
            joints = place_poses(np.array(poses), np.array([float(r.camera.scale) for r in results]),
                                 np.array([r.camera.translation for r in results]), st.lower_leg_length,
                                 focal, centre, st.default_distance)
        except Exception:  # the lifted poses were placed: keep them
            return frame
        lifted = list(frame.lifted)
        for m, (k, res) in enumerate(zip(rows, results, strict=True)):
            try:
                check_output(lifted[k].track_id, res, joints[m])
            except Exception:
                continue
            lifted[k] = replace(lifted[k], result=res, joints_m=joints[m])
        return frame._replace(lifted=lifted)
