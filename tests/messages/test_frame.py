"""The frame pipeline (pose_lifter.messages.frame): the node's path (one pipeline, frame by frame)
and the offline lift's (every frame checked first, then each track on its own pipeline, in one
process or in workers) give the same outputs for the same skeleton sequence, refusals included;
bad input is refused with a kind and a reason that name what was wrong."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions, PoseBases
from pose_lifter.core.errors import SolverError
from pose_lifter.core.lift import batch
from pose_lifter.core.lift.batch import LiftRow, PriorCall
from pose_lifter.core.results import Camera, LiftOutcome, LiftResult, WarmStart
from pose_lifter.messages import convert as m
from pose_lifter.messages.cdr import SkeletonFrame
from pose_lifter.messages.frame import (
    CROWD_SCAN,
    FramePipeline,
    FrameSettings,
    LiftedSkeleton,
    SkipSkeleton,
)
from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_KEYPOINTS
from pose_lifter.offline import bags
from pose_lifter.offline.chains import expiry_stamps
from pose_lifter.offline.lift import FrameLift, LiftSummary, frame_settings, lift_messages
from pose_lifter.offline.settings import LiftSettings
from pose_lifter.ros.params import PARAMS, NodeSettings
from stub_runs import RUNS_NEEDED_NONE, lift_each

REPO = Path(__file__).resolve().parents[2]
T = m.rosbags_types()
STEP_NS = 100_000_000  # 10 Hz
N_FRAMES = 23
#: Frames of track 1's absence (1.2 s > track_timeout): the node forgets it before it returns.
GAP = range(8, 20)
#: The frame whose track 0 the detector gave with the arms' left and right labels swapped (COCO-17:
#: shoulders 5, 6, elbows 7, 8, wrists 9, 10).
SWAPPED = 12
COCO_ARMS, COCO_ARMS_SWAPPED = [5, 6, 7, 8, 9, 10], [6, 5, 8, 7, 10, 9]
#: that skeleton as the bag has it (the right labels), kept by :func:`sequence`
UNSWAPPED: dict[str, Any] = {}


def _skeleton(skel: Any, track_id: int | None = None, scale: float = 1.0,
              confidence: float | None = None, order: list[int] | None = None) -> Any:
    kp = np.array([[k.x, k.y] for k in skel.keypoints]) * scale
    cf = np.array([k.confidence for k in skel.keypoints]) if confidence is None else \
        np.full(len(skel.keypoints), confidence)
    if order is not None:  # keypoints relabelled: keypoint i is the input's order[i]
        kp, cf = kp[order], cf[order]
    return m.arrays_to_skeleton2d(kp, cf, int(skel.track_id) if track_id is None else track_id, T)


def sequence() -> tuple[list[tuple[int, Any]], list[tuple[int, Any]]]:
    """Two people of a committed bag re-stamped at 10 Hz, with every kind of bad input the
    pipeline refuses and a track that is forgotten and comes back; and the bag's camera_info."""
    kps, infos = [], []
    for x in bags.read_messages(REPO / "bags" / "two_people.mcap", [TOPIC_KEYPOINTS, TOPIC_CAMERA_INFO]):
        (kps if x.topic == TOPIC_KEYPOINTS else infos).append(x.msg)
    seq = []
    stamp = 1_000_000_000
    for i, msg in enumerate(kps[:N_FRAMES]):
        # frame 22: older than both tracks' last frames (track 0's is frame 20): out of order
        stamp = stamp - 3 * STEP_NS // 2 if i == 22 else stamp + STEP_NS
        skels = [s for s in msg.skeletons if not (i in GAP and int(s.track_id) == 1)]
        layout, frame_id = str(msg.layout), "camera"
        if i == 2:
            skels.append(_skeleton(skels[0]))  # a duplicate track id
        if i == 3:
            skels[1] = _skeleton(skels[1], confidence=1.5)  # clipped into [0, 1]
        if i == 4:
            frame_id = "x" * 300  # over max_frame_id_length: unanswered
        if i == 5:
            layout = "no_such_layout"
        if i == 6:
            skels.append(_skeleton(skels[1], track_id=-1, scale=1.1))  # untracked
        if i == SWAPPED:
            UNSWAPPED["skeleton"] = skels[0]
            order = list(range(len(skels[0].keypoints)))
            order[COCO_ARMS[0]:COCO_ARMS[-1] + 1] = COCO_ARMS_SWAPPED
            skels[0] = _skeleton(skels[0], confidence=None, order=order)
        if i == 21:
            skels[0] = _skeleton(skels[0], scale=1e6)  # absurd coordinates
        if i == 22:
            skels.append(_skeleton(skels[0], confidence=0.0, track_id=7))  # no confident keypoint
        header = m.make_header(stamp, frame_id, T)
        seq.append((stamp, T.Skeleton2DArray(header=header, layout=layout, skeletons=skels)))
    return seq, [(seq[0][0], infos[0])]


def node_path(lifter: Lifter, settings: FrameSettings, seq: list[tuple[int, Any]], intrinsics: Any
              ) -> tuple[list[tuple[int, LiftedSkeleton | SkipSkeleton]], dict[str, Any]]:
    """What :meth:`LifterNode.on_keypoints` does with the pipeline, frame by frame."""
    pipeline = FramePipeline(lifter, settings)
    clipped: list[str] = []
    seen: dict[str, Any] = {"unanswered": [], "frame_skips": [], "tracks_after_gap": None}
    out: list[tuple[int, LiftedSkeleton | SkipSkeleton]] = []
    for i, (stamp, msg) in enumerate(seq):
        checked = pipeline.check(msg, clipped.append)
        seen["frame_skips"] += [s.kind for s in checked.skipped]
        if not checked.answered:
            seen["unanswered"].append(i)
        out += [(stamp, x) for x in pipeline.frame(checked, stamp, intrinsics)]
        if i == GAP[-1]:
            seen["tracks_after_gap"] = len(pipeline.policy)
    seen["clipped"] = clipped
    return out, seen


@pytest.fixture(scope="module")
def lifter() -> Lifter:
    return Lifter(PoseBases.load(), LifterOptions())  # hybrid


@pytest.mark.parametrize(("warm_start", "workers", "results"),
                         [(True, 1, True), (True, 2, True), (True, 2, False), (False, 1, True)])
def test_the_node_and_the_offline_lift_give_the_same_outputs(lifter: Lifter, warm_start: bool,
                                                             workers: int, results: bool) -> None:
    seq, infos = sequence()
    settings = LiftSettings(frame=FrameSettings(warm_start=warm_start), smoothing_s=0.0)
    intrinsics = m.intrinsics_from_camera_info(infos[0][1])
    node, seen = node_path(lifter, frame_settings(settings), seq, intrinsics)
    # the scenario exercised what it means to
    assert seen["unanswered"] == [4] and seen["clipped"]
    assert seen["frame_skips"] == ["frame_id too long", "UnknownLayoutError"]
    assert seen["tracks_after_gap"] == 1  # track 1 forgotten, track 0 kept
    skips = [x.kind for _, x in node if isinstance(x, SkipSkeleton)]
    assert sorted(skips) == sorted(["duplicate track id", "absurd coordinates", "no confident keypoints",
                                    "out-of-order stamp", "out-of-order stamp"]), skips

    answered: list[int] = []
    columns: list[SkeletonFrame] = []
    summary = LiftSummary()

    def on_frame(stamp: int, msg: Any, lifted: list[FrameLift], results: list[Any]) -> None:
        assert len(results) == len(lifted)
        answered.append(stamp)

    def on_answer(stamp: int, msg: Any, lifted: SkeletonFrame) -> None:
        columns.append(lifted)
        if not results:  # the workers send back columns only
            answered.append(stamp)

    offline = lift_messages(seq, infos, lifter, settings, on_frame=on_frame if results else None,
                            on_answer=on_answer, summary=summary, workers=workers)
    lifted = [(s, x) for s, x in node if isinstance(x, LiftedSkeleton)]
    assert answered == [s for i, (s, _) in enumerate(seq) if i != 4]
    # each message's columns are its answer's: what the node builds of its lifted skeletons
    node_columns = SkeletonFrame.of([x for _, x in lifted])
    offline_columns = SkeletonFrame.concat(columns)
    for name in ("track_ids", "joints_m", "projection", "scale", "orientation_xyzw", "translation",
                 "objective", "reprojection_error", "iterations", "converged", "warm_started", "weights",
                 "points", "confidence", "std_m"):
        np.testing.assert_array_equal(getattr(offline_columns, name), getattr(node_columns, name),
                                      err_msg=name)
    assert summary.n_lifted == len(offline) == len(lifted)
    assert summary.n_failed == len(skips) + 2  # and frame 5's two skeletons (unknown layout)
    assert [(f.stamp_ns, f.track_id, f.warm_started) for f in offline] == [
        (s, x.track_id, x.warm_started) for s, x in lifted]
    assert any(f.warm_started for f in offline) == warm_start
    # bit for bit: the same solves in the same order per track
    np.testing.assert_array_equal(np.array([f.joints_m for f in offline]),
                                  np.array([x.joints_m for _, x in lifted]))
    # the 2D each output carries is labelled as its 3D joints: the node's (REP-155 skeleton2d) and
    # the offline lift's alike; the frame whose arms' labels the detector swapped, swapped back
    np.testing.assert_array_equal(np.array([f.points_2d for f in offline]),
                                  np.array([x.labelled_2d()[0] for _, x in lifted]))
    np.testing.assert_array_equal(np.array([f.confidence for f in offline]),
                                  np.array([x.labelled_2d()[1] for _, x in lifted]))
    assert max(f.confidence.max() for f in offline) <= 1.0
    swapped = [(s, x.track_id) for s, x in lifted if x.swapped is not None]
    assert swapped == ([(seq[SWAPPED][0], 0)] if warm_start else [])  # a cold frame has no track to check
    if warm_start:  # the arms swapped back: the 2D as the detector should have labelled it
        (x,) = [x for s, x in lifted if x.swapped is not None]
        assert x.swapped is not None and x.swapped.tolist() == [True, False]
        right = m.skeleton2d_to_arrays(UNSWAPPED["skeleton"], "coco17")
        assert not np.array_equal(x.input.points, right[0])
        np.testing.assert_array_equal(x.labelled_2d()[0], right[0])
        np.testing.assert_array_equal(x.labelled_2d()[1], right[1])


def test_expiry_stamps_are_the_latest_answered_stamp_since_the_tracks_last_frame() -> None:
    stamps = [10, 20, None, 40, 35, 60]
    assert expiry_stamps(stamps, [0, 3, 5]) == [None, 20, 40]
    assert expiry_stamps(stamps, [1, 2]) == [None, 20]
    assert expiry_stamps([None, None, 5], [0, 2]) == [None, None]


def test_a_frames_people_share_one_pass_of_the_prior_and_get_their_own_poses(
        lifter: Lifter, monkeypatch: pytest.MonkeyPatch) -> None:
    """The node lifts the people of a frame together, the offline lift the chains of a step: the
    prior's poses of all of them go through one pass of the network (batch.prior_calls), and
    every output is the one computed with each pose alone, bit for bit."""
    seq, infos = sequence()
    settings = LiftSettings(smoothing_s=0.0)
    intrinsics = m.intrinsics_from_camera_info(infos[0][1])
    runs: dict[str, tuple[np.ndarray, np.ndarray, list[int]]] = {}
    together = batch.prior_calls

    def alone(calls: list[PriorCall], threads: int = 1) -> list[Any]:
        return [together([c], threads)[0] for c in calls]

    for name, how in (("together", together), ("alone", alone)):
        sizes: list[int] = []

        def counted(calls: list[PriorCall], threads: int = 1, how: Any = how,
                    sizes: list[int] = sizes) -> list[Any]:
            sizes.append(len(calls))
            return how(calls, threads)

        with monkeypatch.context() as mp:
            mp.setattr(batch, "prior_calls", counted)
            node, _ = node_path(lifter, frame_settings(settings), seq, intrinsics)
            offline = lift_messages(seq, infos, lifter, settings)
        lifted = [(s, x) for s, x in node if isinstance(x, LiftedSkeleton)]
        runs[name] = (np.array([x.joints_m for _, x in lifted]), np.array([f.joints_m for f in offline]),
                      sizes)
    np.testing.assert_array_equal(runs["together"][0], runs["alone"][0])
    np.testing.assert_array_equal(runs["together"][1], runs["alone"][1])
    # the frames of two people, node and offline: both priors' poses asked for in one round
    stamps = [s for s, _ in lifted]
    in_pairs = sum(1 for s in stamps if stamps.count(s) >= 2) // 2
    assert in_pairs >= 5
    assert sum(1 for n in runs["together"][2] if n >= 2) >= 2 * in_pairs, runs["together"][2]


class StubLifter:
    """Paper-mode stand-in: a fixed pose, the camera at the 2D mean; ``fail`` decides per call."""

    options = LifterOptions(mode="paper")

    def __init__(self, fail: Any = None) -> None:
        self.calls = 0
        self.fail = fail
        self.pose = np.random.default_rng(0).normal(size=(12, 3))
        self.pose -= self.pose.mean(axis=0)

    runs = RUNS_NEEDED_NONE

    def lift_people(self, rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        """:meth:`lift` of each row (the lifter's batch), with its status."""
        return lift_each(self, rows)

    def lift(self, points: np.ndarray, confidence: np.ndarray, warm: WarmStart | None = None,
             **per_frame: Any) -> LiftResult:
        self.calls += 1
        if self.fail is not None:
            self.fail(self.calls)
        cam = Camera(np.eye(3), 100.0, points[confidence > 0].mean(axis=0))
        return LiftResult(self.pose, self.pose, cam, np.zeros(3), 1.0, 0.5, 0.0, 3, True, 1, 0, np.ones(12))


def _frame(*skeletons: Any, layout: str = "coco17", frame_id: str = "camera") -> Any:
    return T.Skeleton2DArray(header=m.make_header(1, frame_id, T), layout=layout, skeletons=list(skeletons))


def _person(track_id: int, k: int = 17, confidence: float = 0.9, offset: float = 0.0) -> Any:
    rng = np.random.default_rng(track_id + 3)
    return m.arrays_to_skeleton2d(rng.uniform(100, 400, (k, 2)) + offset, np.full(k, confidence), track_id, T)


def test_bad_input_is_refused_with_its_kind_and_reason() -> None:
    pipeline = FramePipeline(StubLifter())  # type: ignore[arg-type]
    checked = pipeline.check(_frame(_person(1), layout="nope"))
    (skip,) = checked.skipped
    assert checked.answered and checked.n_left_out == 1 and not checked.skeletons
    assert skip.kind == "UnknownLayoutError" and str(skip).startswith("frame skipped:")
    assert "nope" in str(skip)
    checked = pipeline.check(_frame(layout="y" * 65))
    assert not checked.answered and "max_layout_length=64" in str(checked.skipped[0])
    many = FramePipeline(StubLifter(), FrameSettings(max_skeletons=2))  # type: ignore[arg-type]
    checked = many.check(_frame(_person(1), _person(2), _person(3)))
    assert checked.n_left_out == 1 and "lifting the 2 largest (max_skeletons)" in str(checked.skipped[0])
    checked = pipeline.check(_frame(_person(1, k=10), _person(2), _person(3, k=600), _person(4)))
    wrong, ok, too_many, ok2 = checked.skeletons
    assert isinstance(wrong, SkipSkeleton) and wrong.kind == "InvalidInputError" and wrong.track_id == 1
    assert "keypoints" in str(wrong)  # the layout's count is named
    assert isinstance(too_many, SkipSkeleton) and "more than max_keypoints=512" in str(too_many)
    assert not isinstance(ok, SkipSkeleton) and not isinstance(ok2, SkipSkeleton)


def _sized(track_id: int, size: float, confidence: float = 0.9) -> Any:
    """A person whose confident joints span a box of diagonal ``size`` pixels (a far, low-confidence
    keypoint does not count)."""
    xy = np.zeros((17, 2))
    xy[:, 0] = np.linspace(0.0, size / np.sqrt(2.0), 17) + 50.0 * track_id
    xy[:, 1] = np.linspace(0.0, size / np.sqrt(2.0), 17)[::-1] + 100.0
    conf = np.full(17, confidence)
    xy[0] = [5000.0, 5000.0]  # the nose, below the confidence threshold
    conf[0] = 0.01
    return m.arrays_to_skeleton2d(xy, conf, track_id, T)


def test_a_crowd_over_the_cap_lifts_its_largest_people_in_the_frames_order() -> None:
    pipeline = FramePipeline(StubLifter(), FrameSettings(max_skeletons=3))  # type: ignore[arg-type]
    people = [_sized(0, 100.0), _sized(1, 300.0), _person(2, k=10), _sized(3, 200.0, 0.6),
              _sized(4, 200.0, 0.8), _sized(5, 50.0), _sized(6, 250.0)]
    checked = pipeline.check(_frame(*people))
    # 6 liftable people (2 is malformed): 1 (300 px), 6 (250) and 4 (200, more confident than 3)
    ids = [x.track_id for x in checked.skeletons]
    assert ids == [1, 2, 4, 6]
    assert isinstance(checked.skeletons[1], SkipSkeleton)  # the malformed one stays refused
    assert checked.n_left_out == 3 and "7 skeletons in one frame" in str(checked.skipped[0])
    # within the cap nothing is left out, whatever the sizes
    assert [x.track_id for x in FramePipeline(StubLifter(), FrameSettings(max_skeletons=6)).check(  # type: ignore[arg-type]
        _frame(*people)).skeletons] == list(range(7))
    # past CROWD_SCAN x the cap the skeletons are not read (here: the 4 after the first 4)
    small = FramePipeline(StubLifter(), FrameSettings(max_skeletons=1))  # type: ignore[arg-type]
    checked = small.check(_frame(*[_sized(i, 10.0 * (i + 1)) for i in range(8)]))
    assert [x.track_id for x in checked.skeletons] == [3] and checked.n_left_out == 7
    assert CROWD_SCAN == 4


def test_a_failed_or_non_finite_solve_is_one_refusal_and_the_others_are_lifted() -> None:
    def fail(call: int) -> None:
        if call == 1:
            raise SolverError("pose step diverged")
        if call == 2:
            raise RuntimeError("a bug")

    pipeline = FramePipeline(StubLifter(fail))  # type: ignore[arg-type]
    checked = pipeline.check(_frame(_person(1), _person(2), _person(3)))
    diverged, bug, lifted = pipeline.frame(checked, 1, None)
    assert isinstance(diverged, SkipSkeleton) and diverged.kind == "SolverError"
    assert isinstance(bug, SkipSkeleton) and bug.kind == "unexpected" and "a bug" in str(bug)
    assert isinstance(lifted, LiftedSkeleton) and np.isfinite(lifted.joints_m).all()
    assert lifted.joints_m.mean(axis=0)[2] == pytest.approx(FrameSettings().default_distance)
    nan = StubLifter()
    nan.pose = np.full((12, 3), np.nan)
    (out,) = FramePipeline(nan).frame(FramePipeline(nan).check(_frame(_person(1))), 1, None)  # type: ignore[arg-type]
    assert isinstance(out, SkipSkeleton) and out.kind == "non-finite result" and out.track_id == 1


def test_the_settings_defaults_are_written_once() -> None:
    defaults = NodeSettings.read({p.name: p.default for p in PARAMS}.__getitem__)
    assert defaults.frame == FrameSettings()
    assert frame_settings(LiftSettings()) == FrameSettings()
