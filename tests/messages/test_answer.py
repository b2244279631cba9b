"""pose_lifter.messages.answer: a frame's messages from its lifted skeletons, in the node's order."""

from __future__ import annotations

import numpy as np
from pose_lifter.messages import cdr, hri
from pose_lifter.messages.answer import frame_answer
from pose_lifter.messages.cdr import DecodedHeader, DecodedStamp, SkeletonFrame
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.messages.names import MARKER_ARRAY, SKELETON3D_ARRAY, TOPIC_MARKERS, TOPIC_SKELETONS
from scipy.spatial.transform import Rotation
from test_body import ground_truth_poses
from test_convert import fake_result

HEADER = DecodedHeader(DecodedStamp(12, 345), "camera")
STAMP_NS = 12 * 10**9 + 345


def _frame(track_ids: list[int]) -> SkeletonFrame:
    """Lifted skeletons of mocap poses, one per track id, with their 2D."""
    poses = ground_truth_poses(len(track_ids))
    results = [fake_result(Rotation.from_euler("y", 10 * k, degrees=True).as_matrix(), 80.0,
                           np.array([300.0, 200.0]), seed=k) for k in range(len(track_ids))]
    points = [np.column_stack([np.linspace(100, 400, 12), np.linspace(50, 350, 12)]) + k
              for k in range(len(track_ids))]
    return SkeletonFrame.from_results(track_ids, poses, results, [0.01] * len(track_ids),
                                      [False] * len(track_ids), points, [np.full(12, 0.8)] * len(track_ids))


def test_the_answer_is_each_writer_s_bytes_in_the_node_s_order() -> None:
    """The skeletons, the markers (their book updated), then the bodies' messages (theirs), each
    the bytes of its own writer; an output without its book is left out."""
    lifted = _frame([3, 8, -1])
    markers, bodies = MarkerBook("ns"), hri.BodyBook(1.0)
    answer = frame_answer(HEADER, STAMP_NS, lifted, markers=markers, marker_lifetime=0.5, bodies=bodies,
                          image_size=(640.0, 480.0))
    assert answer.skeletons == cdr.skeleton3d_array_cdr(HEADER, lifted)
    same_markers, same_bodies = MarkerBook("ns"), hri.BodyBook(1.0)
    assert answer.markers == same_markers.update(HEADER, [3, 8, -1], lifted.joints_m, 0.5)
    people = same_bodies.frame(STAMP_NS, "camera", lifted, (640.0, 480.0))
    assert answer.bodies is not None and answer.bodies.messages() == people.messages()
    assert len(bodies) == 2  # the untracked skeleton has no body
    got = answer.messages()
    assert got[:2] == [(TOPIC_SKELETONS, answer.skeletons, SKELETON3D_ARRAY),
                       (TOPIC_MARKERS, answer.markers, MARKER_ARRAY)]
    assert got[2:] == people.messages()
    # the books carry over: the next frame's markers delete the track that went
    again = frame_answer(HEADER, STAMP_NS + 10**8, lifted.take(np.array([0])), markers=markers)
    assert again.markers == same_markers.update(HEADER, [3], lifted.joints_m[:1], 0.0)
    assert again.bodies is None and [t for t, _, _ in again.messages()] == [TOPIC_SKELETONS, TOPIC_MARKERS]
    alone = frame_answer(HEADER, STAMP_NS, lifted)
    assert alone.markers is None and alone.bodies is None and len(alone.messages()) == 1


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
    assert cdr.skeleton3d_array_cdr(HEADER, first) == cdr.skeleton3d_array_cdr(HEADER, a)
