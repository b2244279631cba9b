"""The lifter node's parts that need no ROS graph: input checks, the one output check, warning
throttle, marker bookkeeping, the one frame counter and its two reports (the statistics line and
the ``/diagnostics`` values; rosbags message types stand in for rclpy's)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.results import Camera, LiftResult
from pose_lifter.core.track.placement import place_in_camera
from pose_lifter.messages import cdr
from pose_lifter.messages import convert as m
from pose_lifter.messages.frame import (
    SkeletonInput,
    SkipSkeleton,
    admitted_track,
    check_output,
    frame_over_cap,
    skeleton_input,
)
from pose_lifter.messages.layouts import frame_joints
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.messages.typestore import pose_lifter_typestore
from pose_lifter.ros.checks import WarningThrottle
from pose_lifter.ros.diagnostics import status_level, values
from pose_lifter.ros.frame_queue import FrameQueue
from pose_lifter.ros.params import PARAMS, NodeSettings
from pose_lifter.ros.stats import FrameCounter, FrameStats

T = m.rosbags_types()
SETTINGS = NodeSettings.read({p.name: p.default for p in PARAMS}.__getitem__).frame


def skeleton(track_id: int = 0, scale: float = 1.0, confidence: float = 0.9, k: int = 17) -> Any:
    rng = np.random.default_rng(track_id + 10)
    return m.arrays_to_skeleton2d(rng.uniform(100, 400, (k, 2)) * scale, np.full(k, confidence), track_id, T)


def checked(skel: Any, seen: set[int], threshold: float, warnings: list[str]) -> SkeletonInput:
    """One skeleton through the frame pipeline's checks: the caps, its joints, the joints' checks."""
    track_id = admitted_track(skel, SETTINGS, seen)
    (read,) = frame_joints([skel], "coco17")
    if isinstance(read, Exception):
        raise read
    return skeleton_input(track_id, *read, SETTINGS, threshold, warnings.append)


def lift_result(scale: float = 80.0) -> LiftResult:
    pose = np.random.default_rng(0).normal(size=(12, 3))
    return LiftResult(pose=pose, pose_camera=pose, camera=Camera(np.eye(3), scale, np.array([300.0, 200.0])),
                      alpha=np.zeros(5), objective=1.5, reprojection_error=2.5, limb_violation=0.0, n_iter=7,
                      converged=True, n_starts=3, start_index=1, weights=np.ones(12), total_alternations=19)


def test_skeleton_input_takes_a_good_skeleton_and_skips_each_bad_kind() -> None:
    seen: set[int] = set()
    warnings: list[str] = []
    inp = checked(skeleton(3), seen, 0.1, warnings)
    assert inp.track_id == 3 and inp.points.shape == (12, 2) and seen == {3} and warnings == []
    cases = [  # (skeleton, kind)
        (skeleton(3), "duplicate track id"),
        (skeleton(4, k=SETTINGS.max_keypoints + 1), "too many keypoints"),
        (skeleton(5, confidence=0.05), "no confident keypoints"),
        (skeleton(6, scale=1e5), "absurd coordinates"),
    ]
    for skel, kind in cases:
        with pytest.raises(SkipSkeleton) as err:
            checked(skel, seen, 0.1, warnings)
        assert err.value.kind == kind
    with pytest.raises(InvalidInputError):  # wrong keypoint count for the layout
        checked(skeleton(7, k=10), seen, 0.1, warnings)
    # untracked skeletons (-1) may repeat
    for _ in range(2):
        checked(skeleton(-1), seen, 0.1, warnings)


def test_clipped_confidences_are_reported_even_when_the_skeleton_is_then_skipped() -> None:
    warnings: list[str] = []
    inp = checked(skeleton(1, confidence=1.5), set(), 0.1, warnings)
    assert np.all(inp.confidence == 1.0) and len(warnings) == 1 and "clipped" in warnings[0]
    with pytest.raises(SkipSkeleton, match="beyond"):
        checked(skeleton(2, scale=1e5, confidence=-0.5), set(), 0.0, warnings)
    assert len(warnings) == 2 and "-0.5" in warnings[1]


def test_one_output_check_covers_what_is_published() -> None:
    good = lift_result()
    joints = place_in_camera(good, 0.43, None, None, 5.0)
    check_output(0, good, joints)
    bad_joints = joints.copy()
    bad_joints[3, 1] = np.nan
    with pytest.raises(SkipSkeleton, match="non-finite") as err:
        check_output(0, good, bad_joints)
    assert err.value.kind == "non-finite result"
    for bad in (lift_result(scale=np.inf), LiftResult(**{**good.__dict__, "objective": np.nan})):
        with pytest.raises(SkipSkeleton):
            check_output(0, bad, joints)


def test_frames_over_a_cap_are_refused_with_the_cap_named() -> None:
    frame = T.Skeleton2DArray(header=m.make_header(1, "x" * 257, T), layout="coco17", skeletons=[])
    skip = frame_over_cap(frame, SETTINGS)
    assert skip is not None and skip.kind == "frame_id too long" and "max_frame_id_length=256" in str(skip)
    frame = T.Skeleton2DArray(header=m.make_header(1, "cam", T), layout="y" * 65, skeletons=[])
    skip = frame_over_cap(frame, SETTINGS)
    assert skip is not None and skip.kind == "layout too long"
    frame = T.Skeleton2DArray(header=m.make_header(1, "cam", T), layout="coco17", skeletons=[])
    assert frame_over_cap(frame, SETTINGS) is None


def test_warnings_are_rate_limited_per_kind() -> None:
    lines: list[str] = []
    throttle = WarningThrottle(lines.append, period=60.0)
    throttle.warn("a", "first " + "x" * 1000)
    throttle.warn("a", "second")
    throttle.warn("b", "other kind")
    assert len(lines) == 2 and lines[0].startswith("first") and "other kind" in lines[1]
    assert len(lines[0]) < 400  # input-derived text is cut
    WarningThrottle(lines.append, period=0.0).warn("a", "again")
    assert lines[-1].startswith("again")


def test_marker_book_clears_first_then_shows_and_deletes_what_is_gone() -> None:
    """The node's and the offline lift's MarkerBook: the first MarkerArray clears what an earlier
    run left (DELETEALL), then the skeletons' markers are those of convert.skeleton_markers (the
    same bytes), and later ones delete the tracks and untracked positions no longer shown."""
    store = pose_lifter_typestore()
    kind = "visualization_msgs/msg/MarkerArray"
    header = m.make_header(5, "cam", T)
    j = np.stack([np.full((12, 3), float(i)) for i in range(3)])
    book = MarkerBook("ns")

    def shown(track_ids: list[int], joints_m: np.ndarray) -> bytes:
        return cdr.marker_array_cdr(cdr.message_header(header), track_ids, joints_m, book.ns, 1.0,
                                    **book.update(track_ids)._asdict())

    first = store.deserialize_cdr(shown([4, 9, -1], j), kind)
    assert [(x.ns, x.action) for x in first.markers[:2]] == [("ns/joints", 3), ("ns/bones", 3)]
    from_arrays = m.skeleton_markers(header, [(4, j[0]), (9, j[1]), (-1, j[2])], "ns", 1.0, T)
    assert (bytes(store.serialize_cdr(T.MarkerArray(markers=first.markers[2:]), kind))
            == bytes(store.serialize_cdr(from_arrays, kind)))
    second = store.deserialize_cdr(shown([9], j[1:2]), kind)
    assert [(x.ns, x.id, x.action) for x in second.markers[2:]] == [
        ("ns/joints", 4, 2), ("ns/bones", 4, 2), ("ns/joints", -1, 2), ("ns/bones", -1, 2)]
    third = store.deserialize_cdr(shown([9], j[1:2]), kind)
    assert len(third.markers) == 2  # nothing more to delete, no DELETEALL again


def test_stats_line() -> None:
    stats = FrameStats()
    assert stats.line() == ""
    skel = m.result_to_skeleton3d(lift_result(), 0, np.zeros((12, 3)), T, solve_time=0.004, warm_started=True)
    stats.frame([skel, skel], 0.010)
    stats.skipped["duplicate track id"] += 2
    stats.clipped = 1
    line = stats.line()
    assert line.startswith("1 frames (") and "2 skeletons (2 warm)" in line and "solve median 4.0 ms" in line
    assert "latency median 10.0 ms" in line and line.endswith("skipped: duplicate track id 2")
    assert "confidences clipped in 1 skeletons" in line


def skeleton3d(track_id: int, solve_time: float, warm: bool) -> Any:
    return m.result_to_skeleton3d(lift_result(), track_id, np.zeros((12, 3)), T, solve_time=solve_time,
                                  warm_started=warm)


def test_one_counter_gives_each_report_its_own_window() -> None:
    counter = FrameCounter()
    skel = skeleton3d(0, 0.004, False)
    counter.frame([skel], 0.01)  # no report open: counted nowhere
    counter.open("line")
    counter.frame([skel], 0.01)
    counter.open("diagnostics")
    counter.frame([skel, skel], 0.02)
    counter.skip("out-of-order stamp")
    counter.clip()
    line = counter.take("line")
    assert (line.frames, line.lifted, line.warm, dict(line.skipped), line.clipped) == (
        2, 3, 0, {"out-of-order stamp": 1}, 1)
    assert counter.take("line").frames == 0  # a take starts a new window
    counter.frame([], 0.01)
    diag = counter.take("diagnostics")
    assert (diag.frames, diag.lifted, diag.latencies) == (2, 2, [0.02, 0.01])
    counter.close("line")
    counter.frame([], 0.01)
    assert counter.take("diagnostics").frames == 1
    with pytest.raises(KeyError):
        counter.take("line")


def test_diagnostics_values_and_levels_of_a_window() -> None:
    window = FrameStats()
    assert status_level(0, 0, 0) == (1, "no input on keypoints_2d")
    skel, cold = skeleton3d(0, 0.004, True), skeleton3d(1, 0.002, False)
    window.frame([skel, cold, skel, skel], 0.010)
    kv = dict(values(window))
    assert (kv["frames"], kv["skeletons lifted"]) == ("1", "4")
    assert (kv["warm share"], kv["cold share"]) == ("0.750", "0.250")
    assert (kv["latency median (ms)"], kv["solve median (ms)"], kv["skipped total"]) == ("10.00", "4.00", "0")
    assert status_level(window.frames, window.lifted, 0) == (0, "lifting")
    window.skipped["no confident keypoints"] += 2
    kv = dict(values(window))
    assert (kv["skipped total"], kv["skipped: no confident keypoints"]) == ("2", "2")
    assert status_level(1, 4, 2) == (1, "2 inputs skipped")
    assert status_level(3, 0, 3) == (2, "no skeleton could be lifted (3 skipped)")
    assert dict(values(FrameStats()))["warm share"] == "nan"


def test_swapped_back_labels_are_counted_in_the_line_and_the_diagnostics() -> None:
    """A lifted skeleton whose track swapped back its detector's left/right labels
    (``LiftedSkeleton.swapped``) is counted once per report; one as given is not."""
    counter = FrameCounter()
    counter.open("line")
    counter.open("diagnostics")
    plain = SimpleNamespace(warm_started=True, solve_time=0.001, swapped=None)
    relabelled = SimpleNamespace(warm_started=True, solve_time=0.001, swapped=np.array([True, False]))
    counter.frame([plain, relabelled], 0.01)
    counter.frame([relabelled, skeleton3d(0, 0.004, True)], 0.01)
    line = counter.take("line")
    assert line.relabelled == 2 and "left/right labels swapped back in 2 skeletons" in line.line()
    assert dict(values(counter.take("diagnostics")))["labels swapped back"] == "2"
    counter.frame([plain], 0.01)
    line = counter.take("line")
    assert line.frames == 1 and "labels swapped back" not in line.line()
    assert dict(values(counter.take("diagnostics")))["labels swapped back"] == "0"


def test_dropped_frames_are_counted_in_the_line_and_the_diagnostics() -> None:
    counter = FrameCounter()
    counter.open("line")
    counter.open("diagnostics")
    counter.drop()
    counter.drop()
    line = counter.take("line")
    assert line.dropped == 2 and "2 frames dropped (the node was busy)" in line.line()
    counter.frame([skeleton3d(0, 0.004, True)], 0.01)
    diag = counter.take("diagnostics")
    before = diag.elapsed()
    kv = dict(values(diag))
    after = diag.elapsed()
    assert (kv["frames"], kv["frames dropped"]) == ("1", "2")
    assert 3 / after - 0.005 <= float(kv["input rate (Hz)"]) <= 3 / before + 0.005  # received: 1 + 2
    assert status_level(1, 1, 0, 2) == (1, "2 of 3 frames dropped: the input is faster than the lift")
    assert status_level(0, 0, 0, 4)[0] == 1 and "4 of 4 frames dropped" in status_level(0, 0, 0, 4)[1]
    assert status_level(3, 0, 3, 1)[0] == 2  # nothing liftable stays the ERROR it is


def test_the_frame_queue_drops_the_oldest_whole_frame() -> None:
    with pytest.raises(ValueError):
        FrameQueue(0)
    q: FrameQueue[int] = FrameQueue(2)
    assert q.pop() is None
    assert q.put(1) is None and q.put(2) is None
    assert q.put(3) == 1 and q.put(4) == 2  # the oldest waiting frame goes first
    assert len(q) == 2 and q.pop() == 3 and q.pop() == 4 and q.pop() is None
    assert q.put(5) is None and q.clear() == 1 and len(q) == 0
    one: FrameQueue[int] = FrameQueue()  # the default: only the newest frame waits
    assert [one.put(i) for i in range(4)] == [None, 0, 1, 2] and one.pop() == 3


def test_freeze_long_lived_frees_what_an_earlier_freeze_kept_and_freezes_the_rest() -> None:
    """The node freezes its start-up objects once a lifter is built (a full collection then walks
    only what the frames make); built again (a lifecycle re-configure, a new ``bases_file``), the
    replaced lifter's reference cycles must be freed, not stay frozen, and what is still held must
    be frozen again."""
    import gc
    import weakref

    from pose_lifter.ros.node import freeze_long_lived

    class Held:
        def __init__(self) -> None:
            self.me = self  # a reference cycle: only the collector frees it

    old, kept = Held(), Held()
    freeze_long_lived()  # the first lifter: both held
    assert gc.get_freeze_count() > 0
    gone = weakref.ref(old)
    del old  # the lifter replaced: its cycle is garbage, but frozen
    gc.collect()
    assert gone() is not None  # a frozen cycle is not collected
    try:
        freeze_long_lived()  # the new lifter built
        assert gone() is None
        assert any(o is kept for o in gc.get_objects()) is False  # frozen: not in the generations
        assert weakref.ref(kept)() is kept
    finally:
        gc.unfreeze()
