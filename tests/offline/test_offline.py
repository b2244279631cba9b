"""pose_lifter.offline.lift.lift_bag plumbing with a stand-in lifter (the real one: test_bags.py)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tolerances as tol
from mcap_check import check_mcap
from pose_lifter.core.errors import SolverError, TooFewJointsError
from pose_lifter.core.lift.batch import LiftRow
from pose_lifter.core.options import LifterOptions
from pose_lifter.core.results import Camera, LiftOutcome, LiftResult, WarmStart
from pose_lifter.messages import convert as m
from pose_lifter.messages.settings import FrameSettings
from pose_lifter.mocap import scenes
from pose_lifter.offline import bags
from pose_lifter.offline import lift as offline
from pose_lifter.offline.settings import LiftSettings
from stub_runs import RUNS_NEEDED_NONE, lift_each

#: The node's causal poses (no centred smoothing).
NODE = LiftSettings(smoothing_s=0.0)


class EchoLifter:
    """Returns the mean of the visible 2D points as the camera translation, a fixed pose, and
    records the warm starts it was given."""

    def __init__(self) -> None:
        self.warm: list[WarmStart | None] = []
        self.pose = np.random.default_rng(0).normal(size=(12, 3))
        self.pose -= self.pose.mean(axis=0)

    options = LifterOptions(mode="paper")
    reads_ahead = False
    frames_ahead = 0  # a causal lift (Lifter.frames_ahead)

    runs = RUNS_NEEDED_NONE

    def lift_people(self, rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        """:meth:`lift` of each row (the lifter's batch), with its status."""
        return lift_each(self, rows)

    def lift(self, points: np.ndarray, confidence: np.ndarray, warm: WarmStart | None = None,
             **per_frame: Any) -> LiftResult:
        self.warm.append(warm)
        vis = confidence > 0
        if vis.sum() < 6:
            raise TooFewJointsError("too few")
        cam = Camera(np.eye(3), 100.0, points[vis].mean(axis=0))
        return LiftResult(self.pose, self.pose, cam, np.zeros(3), 1.0, 0.5, 0.0, 3, True, 1, 0, np.ones(12))


def make_input(tmp_path: Path) -> tuple[Path, scenes.Scene]:
    rng = np.random.default_rng(1)
    clip = rng.normal(scale=0.3, size=(6, 12, 3)) + np.array([0.0, 1.0, 0.0])
    sc = scenes.build_scene([clip, clip], scenes.SceneOptions(), track_ids=[0, 5])
    sc.confidence[1, 3, :8] = 0.0  # track 5 vanishes (too few joints) in frame 3
    path = tmp_path / "in.mcap"
    bags.write_messages(path, scenes.scene_messages(sc))
    return path, sc


def test_lift_bag_outputs(tmp_path: Path) -> None:
    path, sc = make_input(tmp_path)
    lifter: Any = EchoLifter()
    out = tmp_path / "out.mcap"
    settings = LiftSettings(frame=FrameSettings(lower_leg_length=0.5), smoothing_s=0.0)
    summary, frames = offline.lift_bag(path, out, lifter, settings, progress=False)
    assert (summary.n_messages, summary.n_skeletons, summary.n_lifted, summary.n_failed) == (6, 12, 11, 1)
    # warm starts: from the second frame of each track on, restarted after the gap of track 5
    assert summary.n_warm == 11 - 3
    # the tracks' chains are lifted in step, message by message (track 0, then track 5): cold
    # first frames, track 5 cold after its failure in frame 3
    assert [w is None for w in lifter.warm] == [True, True] + [False] * 6 + [False, True] + [False] * 2
    topics = bags.bag_topics(out)
    assert check_mcap(out)["/skeletons_3d"] == 6  # the independent reader: summary, index, decoding
    assert topics["/skeletons_3d"] == "pose_lifter_msgs/msg/Skeleton3DArray"
    assert topics["/skeleton_markers"] == "visualization_msgs/msg/MarkerArray"
    assert {"/keypoints_2d", "/camera_info", "/ground_truth/skeletons_3d"} <= set(topics)
    msgs = list(bags.read_messages(out))
    est = [x for x in msgs if x.topic == "/skeletons_3d"]
    kp = [x for x in msgs if x.topic == "/keypoints_2d"]
    assert [x.stamp_ns for x in est] == [x.stamp_ns for x in kp] == list(sc.stamps_ns)
    assert [len(x.msg.skeletons) for x in est] == [2, 2, 2, 1, 2, 2]
    s = est[4].msg.skeletons[1]
    assert s.track_id == 5 and not s.warm_started and est[5].msg.skeletons[1].warm_started
    # metric placement: depth = f * leg / scale = 800 * 0.5 / 100, centroid under the 2D mean
    j = m.skeleton3d_to_joints(est[0].msg.skeletons[0])
    assert j.mean(axis=0)[2] == pytest.approx(4.0)
    # the pose seen along the ray to its centroid, turned into the camera frame (core/track/placement.py)
    from pose_lifter.core.track.placement import ray_rotation

    turn = ray_rotation(j.mean(axis=0))
    np.testing.assert_allclose(j - j.mean(axis=0), lifter.pose @ turn.T * 0.5, atol=tol.ROUND_OFF_ACCUMULATED)
    u = 800 * j.mean(axis=0)[0] / 4.0 + 320
    assert u == pytest.approx(sc.points_2d[0, 0].mean(axis=0)[0])
    # markers: two per person, after the first message's two DELETEALL (what an earlier run left
    # on screen goes, as the node does); the vanished track gets DELETE markers
    mk = [x.msg.markers for x in msgs if x.topic == "/skeleton_markers"]
    assert [(k.id, k.action) for k in mk[0][:2]] == [(0, 3), (0, 3)]
    assert [len(a) for a in mk[:3]] == [6, 4, 4]
    assert [(k.id, k.action) for k in mk[3]] == [(0, 0), (0, 0), (5, 2), (5, 2)]
    assert len(frames) == 11


class DivergingLifter(EchoLifter):
    """:class:`EchoLifter` whose third solve diverges."""

    def lift(self, points: np.ndarray, confidence: np.ndarray, warm: WarmStart | None = None,
             **per_frame: Any) -> LiftResult:
        if len(self.warm) == 2:
            self.warm.append(warm)
            raise SolverError("pose step diverged (non-finite coefficients)")
        return super().lift(points, confidence, warm, **per_frame)


def test_a_diverged_solve_is_one_failed_skeleton_and_the_track_restarts_cold(tmp_path: Path) -> None:
    path, _ = make_input(tmp_path)
    lifter: Any = DivergingLifter()
    summary, _ = offline.lift_bag(path, tmp_path / "out.mcap", lifter, NODE, progress=False)
    assert (summary.n_lifted, summary.n_failed) == (10, 2)
    assert any("pose step diverged" in f for f in summary.failures)
    # solves in step (track 0, track 5 per message): the third is track 0's second frame, and
    # that track's next frame (the fifth solve) starts cold
    assert lifter.warm[3] is not None and lifter.warm[4] is None


def test_lift_bag_every_and_max(tmp_path: Path) -> None:
    path, _ = make_input(tmp_path)
    out = tmp_path / "out.mcap"
    settings = LiftSettings(every=2, max_messages=2, smoothing_s=0.0)
    summary, _ = offline.lift_bag(path, out, EchoLifter(), settings, progress=False)  # type: ignore[arg-type]
    assert summary.n_messages == 2
    kp = list(bags.read_messages(out, ["/keypoints_2d"]))
    est = list(bags.read_messages(out, ["/skeletons_3d"]))
    assert len(kp) == 4 and [x.stamp_ns for x in est] == [kp[0].stamp_ns, kp[2].stamp_ns]
    with pytest.raises(bags.BagError):
        offline.lift_bag(path, out, EchoLifter(), NODE, progress=False)  # type: ignore[arg-type]


def test_workers_lift_tracks_in_parallel_with_identical_results(tmp_path: Path) -> None:
    from pose_lifter.core import Lifter, LifterOptions, PoseBases

    bag = Path(__file__).resolve().parents[2] / "bags" / "five_people.mcap"
    lifter = Lifter(PoseBases.load(), LifterOptions())
    runs = []
    for workers in (1, 2):
        summary, frames = offline.lift_bag(bag, tmp_path / f"w{workers}.mcap", lifter,
                                           LiftSettings(max_messages=3, smoothing_s=0.0), progress=False,
                                           workers=workers)
        assert (summary.n_lifted, summary.n_warm, summary.n_failed) == (15, 10, 0)
        runs.append(frames)
    one, two = runs
    assert [(f.stamp_ns, f.track_id, f.warm_started) for f in one] == [
        (f.stamp_ns, f.track_id, f.warm_started) for f in two]
    np.testing.assert_array_equal(np.array([f.joints_m for f in one]), np.array([f.joints_m for f in two]))
    objectives = [[[s.objective for s in x.msg.skeletons]
                   for x in bags.read_messages(tmp_path / f"w{w}.mcap", ["/skeletons_3d"])] for w in (1, 2)]
    assert objectives[0] == objectives[1]


def test_centred_smoothing_changes_only_the_poses_and_takes_the_jitter_out(tmp_path: Path) -> None:
    """``smoothing_s > 0`` (pose-lifter lift's default): each track's joints are averaged over the
    frames around them, past and future; the fit (camera, objective) is the node's as it was."""
    from pose_lifter.core import Lifter, LifterOptions
    from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S

    bag = Path(__file__).resolve().parents[2] / "bags" / "two_people.mcap"  # 2D noise
    lifter = Lifter(options=LifterOptions())  # hybrid, its packaged bases
    runs = {}
    for s in (0.0, OFFLINE_SMOOTHING_S):
        _, frames = offline.lift_bag(bag, tmp_path / f"s{s}.mcap", lifter,
                                     LiftSettings(max_messages=45, smoothing_s=s), progress=False)
        runs[s] = frames
    causal, smooth = runs[0.0], runs[OFFLINE_SMOOTHING_S]
    assert [(f.stamp_ns, f.track_id) for f in causal] == [(f.stamp_ns, f.track_id) for f in smooth]
    for s in runs:
        msgs = list(bags.read_messages(tmp_path / f"s{s}.mcap", ["/skeletons_3d"]))
        runs[s] = [[(k.objective, tuple(k.camera.projection)) for k in x.msg.skeletons] for x in msgs]
    assert runs[0.0] == runs[OFFLINE_SMOOTHING_S]  # the same fits, frame by frame
    jitter = {}
    for name, frames in (("causal", causal), ("smooth", smooth)):
        per_track: dict[int, list[np.ndarray]] = {}
        for f in frames:
            per_track.setdefault(f.track_id, []).append(f.joints_m - f.joints_m.mean(axis=0))
        acc = [np.linalg.norm(np.diff(np.array(j), 2, axis=0), axis=-1).mean() for j in per_track.values()]
        jitter[name] = float(np.mean(acc))
    assert jitter["smooth"] < 0.7 * jitter["causal"], jitter


def test_the_camera_timeline_takes_the_latest_usable_camera_info_as_the_node_would() -> None:
    from pose_lifter.offline.chains import CameraTimeline

    t = m.rosbags_types()

    def info(f: float) -> Any:
        return m.camera_info(m.make_header(0, "cam", t), 640, 480, f, f, 320.0, 240.0, t)

    cameras = CameraTimeline([(10, info(500.0)), (20, info(-1.0)), (30, info(700.0))])
    assert cameras.at(5) == cameras.at(10) == cameras.at(25) == ((500.0, 500.0), (320.0, 240.0))
    assert cameras.at(30)[0] == (700.0, 700.0)  # type: ignore[index]
    assert CameraTimeline([(10, info(0.0))]).at(10) is None  # none usable: the default distance


def test_chain_groups_cover_every_chain_once_in_groups_of_equal_work() -> None:
    from pose_lifter.offline.chains import GROUP_CHAINS, Item, chain_groups

    def chain(first: int, n: int) -> list[Item]:
        return [Item(first + k, first + k, None, None) for k in range(n)]  # type: ignore[arg-type]

    # 20 tracks: 10 in the first half of the bag, 10 in the second; 4 single untracked skeletons
    chains = [chain(0, 50) for _ in range(10)] + [chain(60, 40) for _ in range(10)] + \
        [chain(k, 1) for k in (3, 30, 70, 99)]
    for workers in (1, 6, 200):
        groups = chain_groups(chains, workers)
        assert sorted(c for g in groups for c in g) == list(range(len(chains)))
        assert len(groups) == min(len(chains), workers)
        assert all(1 <= len(g) <= GROUP_CHAINS for g in groups)
        sizes = [sum(len(chains[c]) for c in g) for g in groups]
        assert sizes == sorted(sizes, reverse=True)
        # equal work: no group exceeds another by more than its own last (shortest) chain
        assert all(s - min(sizes) <= min(len(chains[c]) for c in g)
                   for s, g in zip(sizes, groups, strict=True))
        # within a group, the chains in the order of their first message
        assert all([chains[c][0].msg_index for c in g] == sorted(chains[c][0].msg_index for c in g)
                   for g in groups)
    # tracks of one length over 2 workers: two groups of equal work, as large as they can be
    assert [len(g) for g in chain_groups([chain(0, 30) for _ in range(36)], 2)] == [18, 18]
    # ... whether seen together or one after another
    assert [len(g) for g in chain_groups([chain(31 * k, 30) for k in range(36)], 2)] == [18, 18]
    # of different lengths: equal items, not equal counts
    uneven = [chain(0, 90)] + [chain(0, 10) for _ in range(9)]
    assert [sum(len(uneven[c]) for c in g) for g in chain_groups(uneven, 2)] == [90, 90]
    # more chains than a group holds: as few groups as hold them
    assert [len(g) for g in chain_groups([chain(k, 3) for k in range(GROUP_CHAINS + 1)], 1)] == [
        GROUP_CHAINS // 2 + 1, GROUP_CHAINS // 2]


def test_tracks_one_after_another_are_lifted_in_step_each_as_alone() -> None:
    """Tracks that follow one another in time (a second apart, other track ids) are lifted in
    step, the k-th frame of each in one batch of the lifter; each track's lifted skeletons are
    those it gets lifted alone (the batch's rows do not mix)."""
    from dataclasses import replace

    from pose_lifter.core import Lifter, LifterOptions

    bag = Path(__file__).resolve().parents[2] / "bags"
    n = 20
    first, second = ([(x.stamp_ns, x.msg) for x in bags.read_messages(bag / name, ["/keypoints_2d"])][:n]
                     for name in ("walk_noisy.mcap", "punch_outliers.mcap"))
    shift = first[-1][0] + 1_000_000_000 - second[0][0]

    def moved(msg: Any, stamp: int) -> Any:  # restamped, its people as track 7
        t = replace(msg.header.stamp, sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
        return replace(msg, header=replace(msg.header, stamp=t),
                       skeletons=[replace(s, track_id=7) for s in msg.skeletons])

    second = [(s + shift, moved(msg, s + shift)) for s, msg in second]
    lifter = Lifter(options=LifterOptions())
    batches: list[int] = []
    lift_people = lifter.lift_people

    def counted(rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        batches.append(len(rows))
        return lift_people(rows)

    alone = [offline.lift_messages(msgs, [], lifter, NODE) for msgs in (first, second)]
    lifter.lift_people = counted  # type: ignore[method-assign]
    both = offline.lift_messages(first + second, [], lifter, NODE)
    assert sum(batches) >= 2 * n and batches.count(2) >= n - 1  # in step: two rows a batch
    assert [(f.stamp_ns, f.track_id) for f in both] == [(f.stamp_ns, f.track_id) for f in alone[0] + alone[1]]
    assert len(both) == 2 * n
    for a, b in zip(alone[0] + alone[1], both, strict=True):
        np.testing.assert_allclose(b.joints_m, a.joints_m, rtol=0, atol=tol.ROUND_OFF_ACCUMULATED)


def test_an_offline_lift_reads_each_tracks_next_frames(tmp_path: Path) -> None:
    """With the centred smoothing (``smoothing_s > 0``) the lifter reads ahead: its temporal prior
    is the packaged offline one, and each item of a chain carries its track's next frames (the
    prior's ``future_frames`` items after it); at ``smoothing_s = 0`` the node's causal prior, and
    the items as they are. The next frames change the fits; the lifted skeletons are the same."""
    from pose_lifter.messages.frame import FramePipeline, with_frames_ahead
    from pose_lifter.offline.chains import split_chains

    ahead, causal = LiftSettings().build_lifter(), NODE.build_lifter()
    assert ahead.reads_ahead and not causal.reads_ahead
    assert causal.temporal_prior is not None and causal.temporal_prior.future_frames == 0
    n_ahead = ahead.temporal_prior.future_frames if ahead.temporal_prior is not None else 0
    assert n_ahead > 0
    bag = Path(__file__).resolve().parents[2] / "bags" / "two_people.mcap"
    msgs = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, ["/keypoints_2d"])][:20]
    chains, _, _ = split_chains(msgs, [], FramePipeline(causal, offline.frame_settings(NODE)))
    chain = max(chains, key=len)
    assert len(chain) > n_ahead + 1
    track = [(it.stamp_ns, it.input) for it in chain]
    kept = with_frames_ahead(track, causal.frames_ahead)
    assert all(x is it.input for x, it in zip(kept, chain, strict=True))
    for k, inp in enumerate(with_frames_ahead(track, ahead.frames_ahead)):
        nxt = chain[k + 1:k + 1 + n_ahead]
        assert inp.ahead is not None and inp.ahead.confidence is not None
        assert inp.ahead.stamps_ns.tolist() == [it.stamp_ns for it in nxt]
        points = np.array([it.input.points for it in nxt]).reshape(-1, 12, 2)
        np.testing.assert_array_equal(inp.ahead.points, points)
        np.testing.assert_array_equal(inp.ahead.confidence,
                                      np.array([it.input.confidence for it in nxt]).reshape(-1, 12))
        np.testing.assert_array_equal(inp.points, chain[k].input.points)
    fits = {}
    for name, lifter in (("ahead", ahead), ("causal", causal)):
        _, frames = offline.lift_bag(bag, tmp_path / f"{name}.mcap", lifter, LiftSettings(max_messages=30),
                                     progress=False)
        fits[name] = {(f.stamp_ns, f.track_id): f.joints_m for f in frames}
    assert fits["ahead"].keys() == fits["causal"].keys()
    moved = [np.abs(fits["ahead"][k] - fits["causal"][k]).max() for k in fits["ahead"]]
    assert max(moved) > 1e-3


def test_a_long_chain_is_cut_into_segments_that_tile_it() -> None:
    """A chain longer than a segment and its lead-in is cut into segments of about
    SEGMENT_FRAMES items whose kept ranges tile it, each started SEGMENT_LEAD items early (the
    first at the start); a short chain, or one whose clock steps back, is one segment."""
    from pose_lifter.offline import chains as ch

    def chain(n: int, back_at: int | None = None) -> list[ch.Item]:
        stamps = [i * 33_000_000 - (10**9 if back_at is not None and i >= back_at else 0) for i in range(n)]
        return [ch.Item(i, s, None, None) for i, s in enumerate(stamps)]  # type: ignore[arg-type]

    n = 4 * ch.SEGMENT_FRAMES + 17
    segs = ch.segments(chain(n))
    assert len(segs) == 4
    assert [k for _, k, _ in segs] == [0] + [b for _, _, b in segs[:-1]] and segs[-1][2] == n  # a tiling
    assert [k - a for a, k, _ in segs] == [0] + [ch.SEGMENT_LEAD] * 3
    assert all(abs((b - k) - ch.SEGMENT_FRAMES) <= ch.SEGMENT_FRAMES // 4 for _, k, b in segs)
    short = ch.SEGMENT_FRAMES + ch.SEGMENT_LEAD
    assert ch.segments(chain(short)) == [(0, 0, short)]
    assert ch.segments(chain(n, back_at=n // 2)) == [(0, 0, n)]


def test_a_long_track_is_lifted_as_segments_in_step_each_item_once(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Segments of a long track are lifted in step (rows of one batch), each from its lead-in, and
    stitched: with a lifter whose answer is the frame's own (no history) the stitched outcomes
    are the unsegmented lift's, item for item. The node's causal poses (no smoothing) lift the
    track whole."""
    from pose_lifter.offline import chains as ch

    rng = np.random.default_rng(3)
    clip = rng.normal(scale=0.3, size=(40, 12, 3)) + np.array([0.0, 1.0, 0.0])
    sc = scenes.build_scene([clip], scenes.SceneOptions(), track_ids=[2])
    path = tmp_path / "long.mcap"
    bags.write_messages(path, scenes.scene_messages(sc))
    msgs = [(x.stamp_ns, x.msg) for x in bags.read_messages(path, ["/keypoints_2d"])]

    from dataclasses import replace

    class FrameLifter(EchoLifter):  # its pose the frame's own
        def lift(self, points: np.ndarray, confidence: np.ndarray, warm: WarmStart | None = None,
                 **per_frame: Any) -> LiftResult:
            r = super().lift(points, confidence, warm, **per_frame)
            pose = self.pose * (1.0 + 1e-3 * float(points[0, 0]))
            return replace(r, pose=pose, pose_camera=pose)

    offline_lift = LiftSettings()  # the offline defaults: the centred smoothing
    alone = offline.lift_messages(msgs, [], FrameLifter(), offline_lift)
    assert len(alone) == 40 and len({float(f.joints_m[0, 0]) for f in alone}) == 40  # each frame its own
    monkeypatch.setattr(ch, "SEGMENT_FRAMES", 12)
    monkeypatch.setattr(ch, "SEGMENT_LEAD", 5)
    cut = FrameLifter()
    batches: list[int] = []
    lift_people = cut.lift_people

    def counted(rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        batches.append(len(rows))
        return lift_people(rows)

    cut.lift_people = counted  # type: ignore[method-assign]
    node = offline.lift_messages(msgs, [], cut, NODE)  # the node's causal poses: the track whole
    assert max(batches) == 1 and len(node) == 40
    batches.clear()
    parts = offline.lift_messages(msgs, [], cut, offline_lift)
    assert [(f.stamp_ns, f.track_id) for f in parts] == [(f.stamp_ns, f.track_id) for f in alone]
    np.testing.assert_array_equal([f.joints_m for f in parts], [f.joints_m for f in alone])
    assert max(batches) == 3 and sum(batches) == 40 + 2 * 5  # three segments in step, two lead-ins


def test_segments_of_real_tracks_are_as_accurate_as_whole_tracks(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Two noisy 45-frame tracks cut into segments of 15 frames with 8 of lead-in, lifted and
    smoothed over their whole tracks (the offline defaults): every frame once, warm-started as in
    the unsegmented lift, as accurate against the ground truth. A segment does not reach the
    track's own poses (a warm-started lift keeps the one of a pose's ambiguous 3D readings it
    started from, so a cold start may keep the other) but an equally good reading of the 2D."""
    from pose_lifter.core import Lifter, LifterOptions
    from pose_lifter.offline import chains as ch
    from pose_lifter.offline.evaluate import evaluate_bag

    bag = Path(__file__).resolve().parents[2] / "bags" / "two_people.mcap"
    lifter = Lifter(options=LifterOptions())
    runs, mpjpe = {}, {}
    for name, frames_per_segment in (("whole", ch.SEGMENT_FRAMES), ("cut", 15)):
        monkeypatch.setattr(ch, "SEGMENT_FRAMES", frames_per_segment)
        monkeypatch.setattr(ch, "SEGMENT_LEAD", 8)
        out = tmp_path / f"{name}.mcap"
        runs[name] = offline.lift_bag(bag, out, lifter, LiftSettings(max_messages=45), progress=False)[1]
        mpjpe[name] = float(np.mean(evaluate_bag(out).mpjpe_mm))
    assert [(f.stamp_ns, f.track_id, f.warm_started) for f in runs["cut"]] == [
        (f.stamp_ns, f.track_id, f.warm_started) for f in runs["whole"]]
    assert mpjpe["cut"] < 1.1 * mpjpe["whole"], mpjpe


def test_pieces_of_a_long_track_share_the_workers_with_results_identical_to_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A long track is split into pieces (chains of their own, margins lifted and dropped) that
    the workers share: every frame once, from the piece that keeps it, and the same skeletons with
    one worker or two."""
    from pose_lifter.core import Lifter, LifterOptions
    from pose_lifter.offline import chains as ch

    small = {"SEGMENT_FRAMES": 8, "SEGMENT_LEAD": 4, "PIECE_FRAMES": 20, "PIECE_MARGIN": 4}
    for name, value in small.items():
        monkeypatch.setattr(ch, name, value)
    items = [ch.Item(i, i * 33_000_000, None, None) for i in range(45)]  # type: ignore[arg-type]
    cut = ch.pieces(items)
    assert cut == [(0, 0, 22, 26), (18, 22, 45, 45)]
    bag = Path(__file__).resolve().parents[2] / "bags" / "two_people.mcap"
    lifter = Lifter(options=LifterOptions())
    runs = {}
    for workers in (1, 2):
        runs[workers] = offline.lift_bag(bag, tmp_path / f"w{workers}.mcap", lifter,
                                         LiftSettings(max_messages=45), progress=False, workers=workers)[1]
    one, two = runs[1], runs[2]
    assert len(one) == 90
    assert [(f.stamp_ns, f.track_id) for f in one] == [(f.stamp_ns, f.track_id) for f in two]
    np.testing.assert_array_equal([f.joints_m for f in one], [f.joints_m for f in two])


def test_a_pieces_kept_part_takes_its_items_and_their_rows() -> None:
    """``kept_part``: the failures of the kept items, and the rows (and results) of those lifted."""
    from dataclasses import fields

    from pose_lifter.messages.cdr import SkeletonFrame
    from pose_lifter.offline.chains import ChainLift, kept_part

    frame = SkeletonFrame(*(np.arange(4) for _ in fields(SkeletonFrame)))
    whole = ChainLift([None, "no", None, None, "no", None], frame, ["r0", "r1", "r2", "r3"])  # type: ignore[arg-type]
    part = kept_part(whole, 1, 5)
    assert part.failures == ["no", None, None, "no"] and part.results == ["r1", "r2"]
    assert part.lifted.track_ids.tolist() == [1, 2]
    assert kept_part(whole, 0, 1).results == ["r0"]
    assert kept_part(whole, 5, 6).lifted.track_ids.tolist() == [3]
