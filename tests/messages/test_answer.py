"""pose_lifter.messages.answer: a frame's messages from its lifted skeletons, in the node's order."""

from __future__ import annotations

from typing import Any

import numpy as np
from pose_lifter.core import Lifter, LifterOptions, PoseBases
from pose_lifter.messages import cdr, hri
from pose_lifter.messages.answer import AnswerStream, frame_answer
from pose_lifter.messages.cdr import DecodedHeader, DecodedStamp, SkeletonFrame
from pose_lifter.messages.frame import FramePipeline, FrameSettings, LiftedSkeleton, SkipSkeleton
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.messages.names import (
    MARKER_ARRAY,
    SKELETON2D_ARRAY,
    SKELETON3D_ARRAY,
    TOPIC_MARKERS,
    TOPIC_SKELETONS,
)
from pose_lifter.messages.typestore import pose_lifter_typestore
from scipy.spatial.transform import Rotation
from test_body import ground_truth_poses
from test_convert import fake_result
from test_frame import sequence

HEADER = DecodedHeader(DecodedStamp(12, 345), "camera")
STAMP_NS = 12 * 10**9 + 345
HEAD = cdr.message_header(HEADER)  # its CDR


def _frame(track_ids: list[int]) -> SkeletonFrame:
    """Lifted skeletons of mocap poses, one per track id, with their 2D."""
    poses = ground_truth_poses(len(track_ids))
    results = [fake_result(Rotation.from_euler("y", 10 * k, degrees=True).as_matrix(), 80.0,
                           np.array([300.0, 200.0]), seed=k) for k in range(len(track_ids))]
    points = [np.column_stack([np.linspace(100, 400, 12), np.linspace(50, 350, 12)]) + k
              for k in range(len(track_ids))]
    return SkeletonFrame.from_results(track_ids, poses, results, [0.01] * len(track_ids),
                                      [False] * len(track_ids), points, [np.full(12, 0.8)] * len(track_ids))


def _markers(book: MarkerBook, track_ids: list[int], joints_m: np.ndarray, lifetime: float) -> bytes:
    """The ``MarkerArray`` of ``HEADER`` showing these skeletons, deleting what ``book`` says is gone."""
    return cdr.marker_array_cdr(HEAD, track_ids, joints_m, book.ns, lifetime,
                                **book.update(track_ids)._asdict())


def test_the_answer_is_each_writer_s_bytes_in_the_node_s_order() -> None:
    """The skeletons, the markers (their book updated), then the bodies' messages (theirs), each
    the bytes of its own writer; an output without its book is left out."""
    lifted = _frame([3, 8, -1])
    markers, bodies = MarkerBook("ns"), hri.BodyBook(1.0)
    answer = frame_answer(HEADER, STAMP_NS, lifted, markers=markers, marker_lifetime=0.5, bodies=bodies,
                          image_size=(640.0, 480.0))
    assert answer.skeletons == cdr.skeleton3d_array_cdr(HEAD, lifted)
    same_markers, same_bodies = MarkerBook("ns"), hri.BodyBook(1.0)
    assert answer.markers == _markers(same_markers, [3, 8, -1], lifted.joints_m, 0.5)
    people = same_bodies.frame(STAMP_NS, HEAD, lifted, (640.0, 480.0))
    assert answer.bodies is not None and answer.bodies.messages() == people.messages()
    assert len(bodies) == 2  # the untracked skeleton has no body
    got = answer.messages()
    assert got[:2] == [(TOPIC_SKELETONS, answer.skeletons, SKELETON3D_ARRAY),
                       (TOPIC_MARKERS, answer.markers, MARKER_ARRAY)]
    assert got[2:] == people.messages()
    # the books carry over: the next frame's markers delete the track that went
    again = frame_answer(HEADER, STAMP_NS + 10**8, lifted.take(np.array([0])), markers=markers)
    assert again.markers == _markers(same_markers, [3], lifted.joints_m[:1], 0.0)
    assert again.bodies is None and [t for t, _, _ in again.messages()] == [TOPIC_SKELETONS, TOPIC_MARKERS]
    alone = frame_answer(HEADER, STAMP_NS, lifted)
    assert alone.markers is None and alone.bodies is None and len(alone.messages()) == 1


def test_a_frames_bodies_are_computed_when_read_and_in_the_books_order() -> None:
    """A frame's REP-155 bodies are computed when first read (so a publisher sends the skeletons
    first); a frame whose bodies were not read yet is computed before the book's next frame, so the
    book sees every frame in order and each answer's bodies are what the eager book gives."""
    lifted, later = _frame([3, 8]), _frame([3])
    book, eager = hri.BodyBook(1.0), hri.BodyBook(1.0)
    first = frame_answer(HEADER, STAMP_NS, lifted, bodies=book)
    assert len(book) == 0  # not computed yet
    second = frame_answer(HEADER, STAMP_NS + 10**8, later, bodies=book)
    assert len(book) == 2  # the first frame's bodies, computed before the second frame's
    head2 = cdr.message_header(DecodedHeader(DecodedStamp(12, 345 + 10**8), "camera"))
    want1 = eager.frame(STAMP_NS, HEAD, lifted, None).messages()
    want2 = eager.frame(STAMP_NS + 10**8, head2, later, None).messages()
    assert second.bodies is not None and second.bodies.messages() == want2
    assert first.bodies is not None and first.bodies.messages() == want1


def test_bodies_posed_for_many_frames_in_one_pass_give_each_frames_own_messages() -> None:
    """The bodies' poses of several frames computed in one pass (an offline lift's:
    hri.tracked_body_poses) give each frame the messages the book computes of that frame alone."""
    frames = [_frame([3, 8, -1]), _frame([-1]), _frame([3])]
    poses = hri.tracked_body_poses(frames)
    assert [len(p) for p in poses] == [2, 0, 1]
    ahead, alone = hri.BodyBook(1.0), hri.BodyBook(1.0)
    for k, (lifted, posed) in enumerate(zip(frames, poses, strict=True)):
        stamp = STAMP_NS + k * 10**8
        head = cdr.message_header(DecodedHeader(DecodedStamp(12, 345 + k * 10**8), "camera"))
        got = frame_answer(HEADER, stamp, lifted, bodies=ahead, image_size=(640.0, 480.0), body_poses=posed)
        assert got.bodies is not None
        assert got.bodies.messages() == alone.frame(stamp, head, lifted, (640.0, 480.0)).messages()
    assert hri.tracked_body_poses([]) == []


def test_columns_take_and_concat_keep_the_rows() -> None:
    """A frame's rows taken from the columns of several are those rows, field by field."""
    a, b = _frame([1, 2]), _frame([5, 6, 7])
    both = SkeletonFrame.concat([a, b])
    assert len(both) == 5
    picked = both.take(np.array([4, 0]))
    np.testing.assert_array_equal(picked.track_ids, [7, 1])
    np.testing.assert_array_equal(picked.joints_m, np.stack([b.joints_m[2], a.joints_m[0]]))
    np.testing.assert_array_equal(picked.points, np.stack([b.points[2], a.points[0]]))
    first = both.take(np.array([0, 1]))
    assert cdr.skeleton3d_array_cdr(HEAD, first) == cdr.skeleton3d_array_cdr(HEAD, a)


def _untimed(skeletons: list[LiftedSkeleton]) -> bytes:
    """Lifted skeletons written without their solve times (each solve's own)."""
    return cdr.skeleton3d_array_cdr(HEAD, SkeletonFrame.of([x.timed(0.0) for x in skeletons]))


def _unread(data: bytes) -> Any:
    raise AssertionError("the array reader reads these bytes")


def test_a_stream_answers_each_frame_s_bytes_as_its_parts_do() -> None:
    """:class:`AnswerStream` reads the serialised frame, checks, lifts and answers it: the same
    answer bytes as the pipeline's steps and :func:`frame_answer` called one by one, with the
    frame's own refusals, its skeletons' and its clipped confidences returned beside it; a frame
    over a cap is left unanswered; an empty ``frame_id`` is the stream's; with a lag the same
    answers come later, the last ones at the flush; bytes the array reader refuses are read by
    the fallback."""
    lifter = Lifter(PoseBases.load(), LifterOptions())
    store = pose_lifter_typestore()
    seq, _ = sequence()
    stream = AnswerStream(FramePipeline(lifter, FrameSettings()), 0, _unread)
    stream.markers, stream.frame_id = MarkerBook("ns"), "fallback"
    pipeline, markers = FramePipeline(lifter, FrameSettings()), MarkerBook("ns")
    answered: list[bytes] = []
    firsts: list[list[LiftedSkeleton]] = []
    kinds: list[str] = []
    for i, (stamp, msg) in enumerate(seq):
        if i == 1:
            msg.header.frame_id = ""
        step = stream.answer(bytes(store.serialize_cdr(msg, SKELETON2D_ARRAY)), float(i), 0)
        clipped: list[str] = []
        checked = pipeline.check(msg, clipped.append)
        n_frame = len(checked.skipped)
        assert list(step.skipped[:n_frame]) == [(s.kind, str(s)) for s in checked.skipped]
        assert list(step.clipped) == clipped
        if not checked.answered:
            assert step.answers == ()
            continue
        outcomes = pipeline.frame(checked, stamp, None)
        header = DecodedHeader(msg.header.stamp, msg.header.frame_id or "fallback")
        lifted = [x for x in outcomes if isinstance(x, LiftedSkeleton)]
        want = frame_answer(header, stamp, SkeletonFrame.of(lifted), markers=markers)
        (got,) = step.answers
        assert (got.answer.markers, got.received) == (want.markers, float(i))
        assert _untimed(got.lifted) == _untimed(lifted) and len(got.answer.skeletons) == len(want.skeletons)
        firsts.append(got.lifted)
        assert list(step.skipped[n_frame:]) == [
            (x.kind, f"skeleton skipped: {x}") for x in outcomes if isinstance(x, SkipSkeleton)]
        kinds += [kind for kind, _ in step.skipped]
        answered.append(got.answer.skeletons)
    assert "duplicate track id" in kinds and "UnknownLayoutError" in kinds and len(answered) == len(seq) - 1
    assert b"fallback" in answered[1] and b"fallback" not in answered[0]

    lagged = AnswerStream(FramePipeline(lifter, FrameSettings()), 2, _unread)
    steps = [lagged.answer(bytes(store.serialize_cdr(msg, SKELETON2D_ARRAY)), 0.0, 0) for _, msg in seq[:6]]
    assert [len(s.answers) for s in steps] == [0, 0, 1, 1, 0, 1]  # frame 4 is left unanswered
    assert len(lagged) == 2 and len(lagged.flush().answers) == 2 and len(lagged) == 0

    big = bytes(store.serialize_cdr(seq[0][1], SKELETON2D_ARRAY, little_endian=False))
    read: list[bytes] = []

    def fallback(data: bytes) -> Any:
        read.append(data)
        return store.deserialize_cdr(data, SKELETON2D_ARRAY)

    again = AnswerStream(FramePipeline(lifter, FrameSettings()), 0, fallback)
    (first,) = again.answer(big, 0.0, 0).answers
    assert read == [big] and _untimed(first.lifted) == _untimed(firsts[0])
