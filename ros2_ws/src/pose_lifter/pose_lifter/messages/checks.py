"""Step 1 of a recording's frames in array passes: :func:`check_frames` gives what
:meth:`~pose_lifter.messages.frame.FramePipeline.check` gives for each frame, the usual frames'
keypoints checked together.

A usual frame is within the caps, holds 1 to ``max_skeletons`` decoded skeletons
(:class:`~pose_lifter.messages.cdr.DecodedSkeleton2D`, the keypoints as one array) of its layout's
keypoint count and distinct track ids. Their keypoints are stacked per layout and mapped to the
paper's joints with one index; the checks of
:func:`~pose_lifter.messages.layouts.frame_joints` and
:func:`~pose_lifter.messages.frame.skeleton_input` run on the stack. A frame any of whose skeletons
would be refused, clipped or repaired, and every other frame, goes through
:meth:`~pose_lifter.messages.frame.FramePipeline.check` itself, which words the refusals.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

import numpy as np

from pose_lifter.messages.frame import (
    CheckedFrame,
    FramePipeline,
    SkeletonInput,
    SkipSkeleton,
    admitted_track,
    frame_over_cap,
)
from pose_lifter.messages.layouts import Layout, get_layout

__all__ = ["PASS_FRAMES", "check_frames"]

#: Frames checked in one array pass at most (the stack's copy of their keypoints is bounded).
PASS_FRAMES: Final[int] = 8192


def check_frames(pipeline: FramePipeline, msgs: Sequence[Any]) -> list[CheckedFrame]:
    """``[pipeline.check(msg) for msg in msgs]``, equal frame by frame, the usual frames (see the
    module doc) checked in one array pass per layout.

    Parameters
    ----------
    pipeline : FramePipeline
        Its settings (the caps, ``max_coordinate``) and its lifter's ``confidence_threshold``.
    msgs : sequence of ``Skeleton2DArray``
        Decoded messages (others are checked one by one).

    Returns
    -------
    list of CheckedFrame
        Per message, in order.
    """
    out: list[CheckedFrame | None] = [None] * len(msgs)
    usual: dict[tuple[str, int], list[int]] = {}  # (layout, keypoints) -> its usual messages
    layouts: dict[str, Layout | None] = {}
    for i, msg in enumerate(msgs):
        key = _usual(msg, pipeline, layouts)
        if key is not None:
            usual.setdefault(key, []).append(i)
    for (name, _), members in usual.items():
        lay = layouts[name]
        assert lay is not None
        for a in range(0, len(members), PASS_FRAMES):
            part = members[a:a + PASS_FRAMES]
            for i, frame in zip(part, _check_usual([msgs[i] for i in part], lay, pipeline), strict=True):
                out[i] = frame
    return [frame if frame is not None else pipeline.check(msg) for frame, msg in zip(out, msgs, strict=True)]


def _usual(msg: Any, pipeline: FramePipeline, layouts: dict[str, Layout | None]) -> tuple[str, int] | None:
    """The (layout, keypoint count) of a usual frame; None for any other."""
    st = pipeline.settings
    skeletons = getattr(msg, "skeletons", None)
    if skeletons is None or not 0 < len(skeletons) <= st.max_skeletons or frame_over_cap(msg, st) is not None:
        return None
    name = str(msg.layout)
    if name not in layouts:
        try:
            layouts[name] = get_layout(name)
        except Exception:  # unknown: the frame's own check words it
            layouts[name] = None
    lay = layouts[name]
    if lay is None:
        return None
    seen: set[int] = set()
    for skel in skeletons:
        xyc = getattr(skel, "xyc", None)
        if xyc is None or xyc.shape != (lay.n_keypoints, 3):
            return None
        try:  # the frame's own caps: too many keypoints, a repeated track id
            admitted_track(skel, st, seen)
        except SkipSkeleton:
            return None
    return name, lay.n_keypoints


def _check_usual(msgs: list[Any], lay: Layout, pipeline: FramePipeline) -> list[CheckedFrame | None]:
    """Usual frames of one layout checked together: per frame its checked skeletons, or None
    where one of them is not plainly accepted (a refusal, a clipped confidence, a missing joint's
    non-finite coordinates set to 0)."""
    counts = [len(m.skeletons) for m in msgs]
    xyc = np.stack([s.xyc for m in msgs for s in m.skeletons]).astype(np.float64, copy=False)
    xyc = xyc[:, lay.index_array]  # (rows, 12, 3)
    points, confidence = np.ascontiguousarray(xyc[..., :2]), np.ascontiguousarray(xyc[..., 2])
    threshold = pipeline.lifter.options.confidence_threshold
    visible = confidence >= threshold
    with np.errstate(invalid="ignore"):
        far = np.where(visible[..., None], np.abs(points), 0.0).max(axis=(1, 2))
        plain = (np.isfinite(xyc).all(axis=(1, 2)) & ((confidence >= 0.0) & (confidence <= 1.0)).all(axis=1)
                 & visible.any(axis=1) & (far <= pipeline.settings.max_coordinate))
    out: list[CheckedFrame | None] = []
    row = 0
    accepted = plain.tolist()
    for msg, n in zip(msgs, counts, strict=True):
        if all(accepted[row:row + n]):
            out.append(CheckedFrame(True, tuple(
                SkeletonInput(int(s.track_id), points[row + k], confidence[row + k])
                for k, s in enumerate(msg.skeletons))))
        else:
            out.append(None)
        row += n
    return out
