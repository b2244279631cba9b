"""The frames of a recording checked in array passes (messages/checks.py) give what each frame's
own check gives, refusals, clipping and repairs included."""

from __future__ import annotations

from itertools import zip_longest
from typing import Any

import numpy as np
import pytest
from pose_lifter.core import LifterOptions
from pose_lifter.messages import checks
from pose_lifter.messages import convert as m
from pose_lifter.messages.cdr import decode_skeleton2d_array
from pose_lifter.messages.checks import check_frames
from pose_lifter.messages.frame import CheckedFrame, FramePipeline, FrameSettings, SkipSkeleton
from pose_lifter.messages.typestore import pose_lifter_typestore

T = m.rosbags_types()
ARRAY = "pose_lifter_msgs/msg/Skeleton2DArray"


class _Options:
    """What the checks read of a lifter."""

    options = LifterOptions()


def _person(rng: np.random.Generator, track_id: int, k: int = 17) -> tuple[np.ndarray, np.ndarray, int]:
    return rng.uniform(100, 400, (k, 2)), rng.uniform(0.4, 1.0, k), track_id


def _frame(people: list[tuple[np.ndarray, np.ndarray, int]], layout: str = "coco17", frame_id: str = "cam",
           decoded: bool = True) -> Any:
    msg = T.Skeleton2DArray(header=m.make_header(1, frame_id, T), layout=layout, skeletons=[
        m.arrays_to_skeleton2d(xy, c, t, T) for xy, c, t in people])
    if not decoded:
        return msg
    out = decode_skeleton2d_array(bytes(pose_lifter_typestore().serialize_cdr(msg, ARRAY)))
    assert out is not None
    return out


def _same(a: CheckedFrame, b: CheckedFrame) -> None:
    assert (a.answered, a.n_left_out) == (b.answered, b.n_left_out)
    assert [(s.kind, str(s)) for s in a.skipped] == [(s.kind, str(s)) for s in b.skipped]
    assert len(a.skeletons) == len(b.skeletons)
    for x, y in zip(a.skeletons, b.skeletons, strict=True):
        assert type(x) is type(y)
        if isinstance(x, SkipSkeleton):
            assert isinstance(y, SkipSkeleton)
            assert (x.kind, str(x), x.track_id) == (y.kind, str(y), y.track_id)
        else:
            assert not isinstance(y, SkipSkeleton)
            assert x.track_id == y.track_id and x.ahead is None and y.ahead is None
            np.testing.assert_array_equal(x.points, y.points)
            np.testing.assert_array_equal(x.confidence, y.confidence)
            assert x.points.dtype == y.points.dtype == np.float64 and x.points.shape == (12, 2)


@pytest.mark.parametrize("pass_frames", [checks.PASS_FRAMES, 3])
def test_a_recordings_frames_checked_together_are_each_frames_own_check(
        pass_frames: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(checks, "PASS_FRAMES", pass_frames)  # 3: the frames in several passes
    rng = np.random.default_rng(7)
    pipeline = FramePipeline(_Options(), FrameSettings(max_skeletons=3))  # type: ignore[arg-type]

    def person(track_id: int, k: int = 17) -> tuple[np.ndarray, np.ndarray, int]:
        return _person(rng, track_id, k)

    def edit(p: tuple[np.ndarray, np.ndarray, int], joint: int, xy: Any = None, c: Any = None
             ) -> tuple[np.ndarray, np.ndarray, int]:
        pts, conf, t = p[0].copy(), p[1].copy(), p[2]
        if xy is not None:
            pts[joint] = xy
        if c is not None:
            conf[joint] = c
        return pts, conf, t

    plain = [_frame([person(0)]) for _ in range(5)] + [_frame([person(1), person(-1), person(-1)])]
    plain += [_frame([person(2, 26)], layout="halpe26"), _frame([person(3)], layout="COCO17")]
    odd = [
        _frame([edit(person(4), 5, c=1.2)]),  # a confidence clipped
        _frame([edit(person(5), 9, c=-0.1)]),
        _frame([edit(person(6), 6, xy=[np.nan, 3.0], c=0.0)]),  # a missing joint's NaN set to 0
        _frame([edit(person(7), 11, xy=[np.nan, 3.0], c=0.9)]),  # a visible joint's NaN: refused
        _frame([edit(person(8), 11, c=np.nan)]),
        _frame([(person(9)[0], np.full(17, 0.01), 9)]),  # no confident keypoint
        _frame([edit(person(10), 12, xy=[1e6, 0.0])]),  # beyond max_coordinate
        _frame([edit(person(11), 12, xy=[1e6, 0.0], c=0.0), person(12)]),  # far but not visible: kept
        _frame([person(13), person(13)]),  # a duplicate track id
        _frame([person(14), person(15), person(16), person(17)]),  # over max_skeletons
        _frame([person(18, 10)]),  # a wrong keypoint count
        _frame([person(19, 600)]),  # over max_keypoints
        _frame([person(20)], layout="nope"),
        _frame([person(21)], frame_id="f" * 300),  # over max_frame_id_length: unanswered
        _frame([]),
        _frame([person(22)], decoded=False),  # a message object, not arrays
        _frame([person(23), edit(person(24), 7, c=2.0)]),  # one odd person: the whole frame checked alone
    ]
    # (the joints edited are among the paper's 12: coco17's 5 to 16)
    msgs = [x for pair in zip_longest(odd, plain) for x in pair if x is not None]
    calls: list[Any] = []
    own = FramePipeline.check

    def counted(self: FramePipeline, msg: Any, *a: Any) -> CheckedFrame:
        calls.append(msg)
        return own(self, msg, *a)

    expected = [pipeline.check(msg) for msg in msgs]
    FramePipeline.check = counted  # type: ignore[method-assign]
    try:
        got = check_frames(pipeline, msgs)
    finally:
        FramePipeline.check = own  # type: ignore[method-assign]
    assert len(got) == len(msgs)
    for a, b in zip(got, expected, strict=True):
        _same(a, b)
    # the plain frames (and the one whose far joint is not visible) took the array pass
    assert len(calls) == len(odd) - 1
    assert all(c is not msg for c in calls for msg in plain)
    kinds = {s.kind for f in expected for s in f.skeletons if isinstance(s, SkipSkeleton)}
    assert len(kinds) >= 5  # the odd frames did test refusals
