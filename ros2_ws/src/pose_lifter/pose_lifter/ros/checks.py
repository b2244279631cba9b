"""What the lifter node refuses, and how it says so: input caps and sanitising, the one check of
what it publishes, and rate-limited warnings.

Each refusal is a :class:`SkipSkeleton` (or, for a whole frame over a cap, a reason string)
with a short kind, counted in the statistics line and warned at most once per
:data:`WARN_PERIOD` per kind (:class:`WarningThrottle`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.layouts import Layout
from pose_lifter.core.results import LiftResult
from pose_lifter.messages import convert as messages
from pose_lifter.ros.params import NodeSettings

__all__ = [
    "MAX_WARNING_CHARS",
    "WARN_PERIOD",
    "SkeletonInput",
    "SkipSkeleton",
    "WarningThrottle",
    "check_output",
    "frame_over_cap",
    "skeleton_input",
]

#: Seconds between two warnings of one kind (each kind is warned at least once per period).
WARN_PERIOD: Final[float] = 5.0
#: Characters of a warning at most (input-derived text is never logged whole).
MAX_WARNING_CHARS: Final[int] = 300


class SkipSkeleton(Exception):
    """One skeleton of a frame is left out of the answer.

    Parameters
    ----------
    kind : str
        Short category, counted in the statistics line (e.g. ``"duplicate track id"``).
    text : str
        The warning.
    """

    def __init__(self, kind: str, text: str) -> None:
        super().__init__(text)
        self.kind = kind


class WarningThrottle:
    """Warnings rate-limited per kind: the first of a kind, then at most one per ``period``.

    Parameters
    ----------
    warn : callable
        Logs one line (the node logger's ``warning``).
    period : float
        Seconds.
    """

    def __init__(self, warn: Callable[[str], Any], period: float = WARN_PERIOD) -> None:
        self._warn = warn
        self._period = period
        self._last: dict[str, float] = {}  # kind -> monotonic time of its last warning

    def warn(self, kind: str, text: str) -> None:
        now = time.monotonic()
        last = self._last.get(kind)
        if last is not None and now - last < self._period:
            return
        self._last[kind] = now
        self._warn(f"{text[:MAX_WARNING_CHARS]} (warnings of this kind are rate-limited "
                   f"to one per {self._period:g} s; counts in the stats line)")


def frame_over_cap(msg: Any, settings: NodeSettings) -> tuple[str, str] | None:
    """(kind, warning) when a frame's strings would be copied into outputs or logs beyond the
    caps (the frame is then skipped, unanswered); None when it is within them."""
    n_frame, n_layout = len(msg.header.frame_id), len(msg.layout)
    if n_frame > settings.max_frame_id_length:
        return ("frame_id too long", f"frame skipped, unanswered: header.frame_id of {n_frame} characters, "
                f"more than max_frame_id_length={settings.max_frame_id_length}")
    if n_layout > settings.max_layout_length:
        return ("layout too long", f"frame skipped, unanswered: layout name of {n_layout} characters, "
                f"more than max_layout_length={settings.max_layout_length}")
    return None


@dataclass(frozen=True)
class SkeletonInput:
    """One skeleton, checked and ready to lift.

    Attributes
    ----------
    track_id : int
    points : ndarray, shape (12, 2)
        Pixels (missing joints 0).
    confidence : ndarray, shape (12,)
        Clipped into [0, 1].
    """

    track_id: int
    points: NDArray[np.float64]
    confidence: NDArray[np.float64]


def skeleton_input(skel: Any, layout: Layout, settings: NodeSettings, confidence_threshold: float,
                   seen: set[int], on_clipped: Callable[[str], Any]) -> SkeletonInput:
    """The paper's 12 joints of one ``Skeleton2D`` of a frame, or :class:`SkipSkeleton`.

    Refused: more keypoints than ``max_keypoints``, a track id already in ``seen`` (this
    frame's; the skeleton's id is added), no keypoint at or above ``confidence_threshold``,
    visible keypoints beyond ``max_coordinate`` pixels; malformed keypoints raise the
    :class:`~pose_lifter.core.errors.InvalidInputError` of
    :func:`messages.skeleton2d_to_arrays`. Confidences outside [0, 1] are clipped into it and
    ``on_clipped(warning)`` is called (before the checks that follow may skip the skeleton).
    """
    track_id = int(skel.track_id)
    if len(skel.keypoints) > settings.max_keypoints:
        raise SkipSkeleton("too many keypoints", f"track {track_id}: {len(skel.keypoints)} keypoints, "
                           f"more than max_keypoints={settings.max_keypoints}")
    if track_id >= 0:
        if track_id in seen:
            raise SkipSkeleton("duplicate track id",
                               f"duplicate track id {track_id} in one frame: later copy skipped")
        seen.add(track_id)
    points, confidence = messages.skeleton2d_to_arrays(skel, layout)
    outside = (confidence < 0.0) | (confidence > 1.0)
    if np.any(outside):  # they weigh the solve: clipped into [0, 1], with a warning
        worst = float(confidence[outside][np.argmax(np.abs(confidence[outside]))])
        on_clipped(f"track {track_id}: {int(outside.sum())} confidences outside [0, 1] "
                   f"(e.g. {worst:.3g}) clipped into it")
        confidence = np.clip(confidence, 0.0, 1.0)
    visible = confidence >= confidence_threshold
    if not np.any(visible):
        raise SkipSkeleton("no confident keypoints",
                           f"track {track_id}: no keypoint above the confidence threshold")
    limit = settings.max_coordinate
    if np.max(np.abs(points[visible])) > limit:
        raise SkipSkeleton("absurd coordinates",
                           f"track {track_id}: keypoints beyond {limit:g} px (max_coordinate)")
    return SkeletonInput(track_id, points, confidence)


def check_output(track_id: int, result: LiftResult, joints_m: NDArray[np.float64]) -> None:
    """The node's one check of what it publishes: the metric joints and the lift's camera,
    objective and reprojection error must be finite, else :class:`SkipSkeleton`."""
    cam = result.camera
    values: Sequence[Any] = (joints_m, cam.rotation, cam.scale, cam.translation, result.objective,
                             result.reprojection_error)
    if not all(bool(np.all(np.isfinite(np.asarray(v, dtype=np.float64)))) for v in values):
        raise SkipSkeleton("non-finite result", f"track {track_id}: the solve returned non-finite values")
