"""Lift every ``/keypoints_2d`` message of a bag offline.

``lift_bag`` is what the node does, frame by frame, without ROS: each message goes through the
node's frame pipeline (:mod:`pose_lifter.messages.frame`: the input caps and checks, the
confidence clipping, per-track warm starts and expiry, metric placement from ``/camera_info``,
the output check), and each message's answer (:func:`pose_lifter.messages.answer.frame_answer`,
what the node publishes: ``/skeletons_3d``, ``/skeleton_markers`` and the REP-155 bodies) is
written next to the input topics. Where it differs, on purpose:

* the stamp of a message is its bag time (when it was recorded), not its header's;
* the camera intrinsics are those of the latest ``/camera_info`` at or before the message
  (before the first one: the first one), not of the latest received;
* the node's ``frame_id`` is not an offline setting (the headers are copied unchanged);
* a depth topic (``--depth-topic``; by default the bag's one depth image topic,
  :func:`pose_lifter.offline.depth.depth_topic_of`) pairs each message with the depth image of the
  nearest header stamp within ``depth_tolerance`` once, before the lift (the images' stamps read
  with the keypoints, :func:`~pose_lifter.offline.depth.pair_depth`), and the images are read one
  at a time as the messages are lifted (the node pairs each frame as it comes, from a buffer of
  the newest images);
* ``smoothing_s > 0`` reads each track's next frames into its offline prior
  (:func:`pose_lifter.messages.frame.with_frames_ahead`) and smooths each track's poses with past and
  future frames (:func:`pose_lifter.offline.chains.refine_chain`); 0 gives the node's causal
  priors and poses, and with ``output_lag`` N the node's answers with ``output_lag:=N``
  (:class:`pose_lifter.messages.lagged.LaggedFrames`, the messages in order in one process).

The lifted bag is evaluated by :mod:`pose_lifter.offline.evaluate`.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.results import LiftResult
from pose_lifter.messages import cdr, hri
from pose_lifter.messages import convert as m
from pose_lifter.messages.answer import FrameAnswer, frame_answer
from pose_lifter.messages.cdr import SkeletonFrame
from pose_lifter.messages.frame import (
    CheckedFrame,
    FramePipeline,
    FrameSettings,
    LiftedSkeleton,
    SkipSkeleton,
)
from pose_lifter.messages.lagged import LaggedFrame, LaggedFrames
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.messages.names import (
    CAMERA_INFO,
    SKELETON2D_ARRAY,
    TOPIC_CAMERA_INFO,
    TOPIC_KEYPOINTS,
    YOLO_DETECTION_ARRAY,
)
from pose_lifter.messages.typestore import pose_lifter_typestore
from pose_lifter.offline.bags import (
    BagError,
    BagReadError,
    BagWriter,
    bag_path,
    bag_topics,
    check_output,
    is_rosbag2_dir,
    read_raw,
)
from pose_lifter.offline.chains import (
    ChainLift,
    ChainWork,
    Item,
    chain_groups,
    kept_part,
    lift_chains,
    lift_parallel,
    pieces,
    split_chains,
)
from pose_lifter.offline.chunk_copy import copy_with
from pose_lifter.offline.depth import BagDepth, depth_topic_of, pair_depth
from pose_lifter.offline.first_pass import FirstPassAhead, FirstPassPlan, read_ahead, read_first_pass
from pose_lifter.offline.mcap_index import chunked_mcap
from pose_lifter.offline.settings import LiftSettings

__all__ = [
    "LIFTABLE_TYPES",
    "FirstPassPlan",
    "FrameLift",
    "LiftSummary",
    "check_lift_inputs",
    "frame_settings",
    "lift_bag",
    "lift_messages",
    "read_ahead",
]

_MARKER_NS: Final[str] = "pose_lifter"
#: Message types ``lift_bag`` lifts: ours as they are, yolo_ros' through :mod:`pose_lifter.messages.adapters`.
LIFTABLE_TYPES: Final[tuple[str, ...]] = (SKELETON2D_ARRAY, YOLO_DETECTION_ARRAY)


def frame_settings(settings: LiftSettings) -> FrameSettings:
    """The frame pipeline's settings of an offline lift."""
    return settings.frame


@dataclass
class LiftSummary:
    """What :func:`lift_bag` did. ``n_skeletons`` counts every input skeleton of the answered
    messages (those the node would answer); ``n_failed`` those skipped or not lifted."""

    n_messages: int = 0
    n_skeletons: int = 0
    n_lifted: int = 0
    n_failed: int = 0
    n_warm: int = 0
    solve_time_s: float = 0.0
    failures: list[str] = field(default_factory=list)
    #: the depth topic and each message's partner on it (None: no depth)
    depth: BagDepth | None = None
    #: what the lift says besides its counts (the depth pairing, or why it used no depth)
    notes: list[str] = field(default_factory=list)

    def depth_line(self) -> str:
        """The depth pairing in one line (``""``: no depth topic)."""
        d = self.depth
        if d is None:
            return ""
        why = ", ".join(f"{k} {n}" for k, n in sorted(d.unpaired.items()))
        return (f"depth from {d.topic}: {d.paired} of {len(d.partners)} messages paired"
                + (f" (without: {why})" if why else ""))

    @property
    def mean_solve_time_ms(self) -> float:
        return 1e3 * self.solve_time_s / max(1, self.n_lifted)

    def fail(self, stamp: int, text: str, n: int = 1) -> None:
        """Count ``n`` skeletons not lifted (the first 20 reasons are kept)."""
        self.n_failed += n
        if len(self.failures) < 20:
            self.failures.append(f"{stamp} {text}")


@dataclass(frozen=True)
class FrameLift:
    """One lifted skeleton (for plots and tests): its input (confidences clipped into [0, 1], as
    the pipeline lifted them, its left/right labels as its track gave them) and its metric
    joints."""

    stamp_ns: int
    track_id: int
    points_2d: NDArray[np.float64]
    confidence: NDArray[np.float64]
    joints_m: NDArray[np.float64]
    warm_started: bool
    solve_time: float
    std_m: NDArray[np.float64]  #: (12, 3) each joint's standard deviation, metres (NaN: unknown)


def lift_messages(
    keypoint_msgs: list[tuple[int, Any]],
    camera_infos: list[tuple[int, Any]],
    lifter: Lifter,
    settings: LiftSettings,
    *,
    progress: bool = False,
    on_frame: Callable[[int, Any, list[FrameLift], list[LiftResult]], None] | None = None,
    on_answer: Callable[[int, Any, SkeletonFrame], None] | None = None,
    summary: LiftSummary | None = None,
    workers: int = 1,
    depth: BagDepth | None = None,
) -> list[FrameLift]:
    """Lift ``Skeleton2DArray`` messages in order through the node's frame pipeline.

    A tracked person (track_id >= 0) starts from its solution in its previous frame within
    ``track_timeout`` (as the node does); untracked skeletons are solved cold. Tracks are
    independent chains, so ``workers > 1`` lifts them in parallel processes with results
    identical to ``workers=1``, and identical to :meth:`FramePipeline.frame` over the messages.

    Parameters
    ----------
    keypoint_msgs : list of (stamp_ns, Skeleton2DArray)
    camera_infos : list of (stamp_ns, CameraInfo), time-ordered
    lifter : Lifter
    settings : LiftSettings
        Read here: ``frame`` (the per-track policy, the placement and the caps,
        :func:`frame_settings`) and ``smoothing_s``: 0 gives the node's causal poses; ``> 0``
        refines each track's poses over its whole recording (the offline measurement update, then
        a centred Gaussian window of this standard deviation in seconds,
        :func:`pose_lifter.offline.chains.lift_chains`);
        ``output_lag`` (with ``smoothing_s`` 0): the node's lagged answers (``workers`` unused).
        Its ``options`` and ``bases`` are not read (``lifter`` is the solver).
    progress : bool
        Show a tqdm progress bar (skeletons).
    on_frame : callable, optional
        ``on_frame(stamp_ns, msg, lifted, results)`` for each answered message (not one over a
        cap), in order, after the lifting (``results`` holds the LiftResult of each lifted
        skeleton, in the order of ``lifted``; the workers send them back only when this is given).
    on_answer : callable, optional
        ``on_answer(stamp_ns, msg, lifted)`` for each answered message, in order, with its lifted
        skeletons as columns (:class:`~pose_lifter.messages.cdr.SkeletonFrame`: what its
        answer carries, :func:`~pose_lifter.messages.answer.frame_answer`).
    summary : LiftSummary, optional
        Filled in place.
    workers : int
        Processes (fork) lifting the chains; 1 lifts in this process.
    depth : BagDepth, optional
        Each message's depth image (:func:`~pose_lifter.offline.depth.pair_depth`, the messages
        of ``keypoint_msgs`` in order): its people placed on it.
    """
    if workers < 1:
        raise ValueError("workers must be >= 1")
    summ = summary if summary is not None else LiftSummary()
    frame = frame_settings(settings)
    chains, per_msg, checked = split_chains(keypoint_msgs, camera_infos, FramePipeline(lifter, frame))
    keep_results = on_frame is not None
    if settings.output_lag:
        parts = _lift_lagged(lifter, keypoint_msgs, per_msg, checked, frame, settings.output_lag,
                             keep_results, depth)
    else:
        parts = _lift_chains(lifter, chains, frame, settings.smoothing_s, workers, keep_results, progress,
                             depth)
    columns = SkeletonFrame.concat([p.lifted for _, p in parts]) if parts else SkeletonFrame.of([])
    results = [r for _, p in parts for r in (p.results or [])]
    row_of: dict[int, int | str] = {}  # id(item) -> its row of columns, or why it was not lifted
    base = 0
    for items, part in parts:
        for item, failure in zip(items, part.failures, strict=True):
            row_of[id(item)] = failure if failure is not None else base
            base += failure is None
    out: list[FrameLift] = []
    for (stamp, msg), row, frame_check in zip(keypoint_msgs, per_msg, checked, strict=True):
        for skip in frame_check.skipped:
            summ.fail(stamp, str(skip), frame_check.n_left_out if frame_check.answered else 0)
        if not frame_check.answered:
            continue
        summ.n_messages += 1
        summ.n_skeletons += len(row) + frame_check.n_left_out
        rows: list[int] = []
        for x in row:
            r = str(x) if isinstance(x, SkipSkeleton) else row_of[id(x)]
            if isinstance(r, str):
                summ.fail(stamp, f"track {x.track_id}: {r}")
            else:
                rows.append(r)
        # a message's rows are most often consecutive (one person, or people of one chain group)
        lifted = columns.take(slice(rows[0], rows[0] + len(rows))
                              if rows and rows == list(range(rows[0], rows[0] + len(rows)))
                              else np.array(rows, dtype=np.intp))
        summ.n_lifted += len(rows)
        summ.n_warm += int(lifted.warm_started.sum())
        summ.solve_time_s += float(lifted.solve_time.sum())
        frames = [FrameLift(stamp, t, p, c, j, w, dt, sd) for t, p, c, j, w, dt, sd in zip(
            lifted.track_ids.tolist(), lifted.points, lifted.confidence, lifted.joints_m,
            lifted.warm_started.tolist(), lifted.solve_time.tolist(), np.asarray(lifted.std_m), strict=True)]
        out.extend(frames)
        if on_frame is not None:
            on_frame(stamp, msg, frames, [results[r] for r in rows])
        if on_answer is not None:
            on_answer(stamp, msg, lifted)
    return out


def _lift_lagged(lifter: Lifter, keypoint_msgs: list[tuple[int, Any]],
                 per_msg: list[list[Item | SkipSkeleton]], checked: list[CheckedFrame], frame: FrameSettings,
                 lag: int, keep_results: bool, depth: BagDepth | None = None
                 ) -> list[tuple[list[Item], ChainLift]]:
    """The node's answers with ``output_lag`` = ``lag``: every answered message through one frame
    pipeline, in order, as the node lifts it, and its skeletons refined when ``lag`` later messages
    have been lifted (:class:`~pose_lifter.messages.lagged.LaggedFrames`; the last ``lag`` when the
    messages end, as the node publishes them when its input stops). One process; the items
    with what lifting them gave."""
    pipeline = FramePipeline(lifter, frame)
    lagged: LaggedFrames[int] = LaggedFrames(pipeline, lag)
    items: list[Item] = []
    outcomes: list[LiftedSkeleton | SkipSkeleton] = []

    def release(f: LaggedFrame[int]) -> None:
        for x, s in zip(per_msg[f.token], f.outcomes, strict=True):  # one per checked skeleton
            if isinstance(x, Item):
                items.append(x)
                outcomes.append(s)

    images = depth.frames() if depth is not None else None
    try:
        for i, ((stamp, _), row, check) in enumerate(zip(keypoint_msgs, per_msg, checked, strict=True)):
            if not check.answered:
                continue
            first = next((x for x in row if isinstance(x, Item)), None)
            image = images.image(i) if images is not None and first is not None else None
            for f in lagged.lift(i, stamp, first.intrinsics if first is not None else None, check, image):
                release(f)
    finally:
        if images is not None:
            images.close()
    for f in lagged.flush():
        release(f)
    return [(items, ChainLift.of(outcomes, keep_results))]


def _lift_chains(lifter: Lifter, chains: list[list[Item]], frame: FrameSettings, smoothing_s: float,
                 workers: int, keep_results: bool, progress: bool, depth: BagDepth | None = None
                 ) -> list[tuple[list[Item], ChainLift]]:
    """Every chain lifted, in this process (``workers`` 1, or a single chain) or in ``workers``
    forked processes (one group of chains each, :func:`chain_groups`), a long chain as its
    :func:`~pose_lifter.offline.chains.pieces` (without depth): each chain's or piece's kept items
    with what lifting them gave."""
    from tqdm import tqdm

    # a long chain's pieces are chains of their own, each kept from its first to its last kept item
    # (not with depth, nor for the node's causal poses: smoothing_s 0 gives what the node gives)
    whole = depth is not None or smoothing_s <= 0
    cut = [(c, *p) for c, chain in enumerate(chains)
           for p in ([(0, 0, len(chain), len(chain))] if whole else pieces(chain))]
    work_chains = [chains[c][a:e] for c, a, _, _, e in cut]
    bar = tqdm(total=sum(len(c) for c in work_chains), desc="lifting", unit="skeleton", disable=not progress)
    lifted: list[ChainLift]
    if workers == 1 or len(work_chains) < 2:
        lifted = [ChainLift.of([], keep_results)] * len(work_chains)
        for group in chain_groups(work_chains, 1):
            # one list of outcomes per chain of the group: the bar advances by that chain's items
            for c, outcomes in zip(group, lift_chains(lifter, [work_chains[c] for c in group], frame,
                                                      smoothing_s, depth), strict=True):
                lifted[c] = ChainLift.of(outcomes, keep_results)
                bar.update(len(outcomes))
    else:
        work = ChainWork(lifter, frame, smoothing_s, work_chains, chain_groups(work_chains, workers),
                         keep_results, depth)
        lifted = lift_parallel(work, workers, bar)
    bar.close()
    return [(chains[c][k:b], kept_part(part, k - a, b - a)) for (c, a, k, b, _), part in
            zip(cut, lifted, strict=True)]


def check_lift_inputs(
    in_path: str | Path,
    out_path: str | Path,
    topic: str = TOPIC_KEYPOINTS,
    camera_info_topic: str | None = TOPIC_CAMERA_INFO,
    keep: Sequence[str] | None = None,
    overwrite: bool = False,
    depth_topic: str = "",
) -> dict[str, str]:
    """Everything :func:`lift_bag` can check before any work; returns the bag's topic -> type.

    Raises
    ------
    BagError
        ``out_path`` does not end in ``.mcap``, exists (without ``overwrite``), is a directory,
        has no parent directory, is the input or lies inside the input rosbag2 directory; the
        input is missing or unreadable; ``topic`` is missing or not a
        liftable type; a kept topic is missing; ``camera_info_topic`` has another type; a named
        ``depth_topic`` is missing or not an image topic (:func:`~pose_lifter.offline.depth.depth_topic_of`).
    """
    out = check_output(out_path, (".mcap",), overwrite)
    source = bag_path(in_path).resolve()
    if source == out.resolve():
        raise BagError("the output would overwrite the input")
    if is_rosbag2_dir(source) and out.resolve().is_relative_to(source):
        raise BagError(f"the output {out} would be written inside the input recording {source}")
    try:
        topics = bag_topics(in_path)
    except BagError:
        raise
    except Exception as exc:  # rosbags' reader errors: a truncated, empty or foreign file
        raise BagReadError(f"cannot read {in_path}: {exc}") from None
    if topic not in topics:
        raise BagError(f"{in_path} has no topic {topic!r}; its topics: {sorted(topics)}")
    if topics[topic] not in LIFTABLE_TYPES:
        raise BagError(f"topic {topic!r} is {topics[topic]}; lift takes {', '.join(LIFTABLE_TYPES)}")
    if camera_info_topic and camera_info_topic in topics and topics[camera_info_topic] != CAMERA_INFO:
        raise BagError(f"camera-info topic {camera_info_topic!r} is {topics[camera_info_topic]}, "
                       f"not {CAMERA_INFO}")
    missing = sorted(set(keep or ()) - set(topics))
    if missing:
        raise BagError(f"{in_path} has no topic(s) {missing} to keep; its topics: {sorted(topics)}")
    depth_topic_of(topics, depth_topic, in_path)
    return topics


def lift_bag(
    in_path: str | Path,
    out_path: str | Path,
    lifter: Lifter,
    settings: LiftSettings,
    *,
    progress: bool = True,
    overwrite: bool = False,
    workers: int = 1,
    first_pass: FirstPassAhead | None = None,
) -> tuple[LiftSummary, list[FrameLift]]:
    """Lift every message of ``settings.topic`` of a bag into a new bag.

    The output holds the kept input topics (copied byte for byte, same stamps; all of them by
    default) plus ``/skeletons_3d`` (``Skeleton3DArray``, camera optical frame, metres) and
    ``/skeleton_markers`` (``MarkerArray``: joints and bones per track, DELETE for vanished
    tracks), one of each per answered keypoint message (as the node answers). Everything checkable
    is checked before any work (:func:`check_lift_inputs`).

    Memory: the bag is read in passes that hold one message (or one MCAP chunk) at a time: first
    ``topic`` and ``camera_info_topic`` (deserialised, kept for the lifting) and the depth
    images' header stamps (:mod:`pose_lifter.offline.depth`); then, while the lifting, each paired
    depth image; then the output is written: every kept topic copied as serialised bytes
    (a single chunked MCAP file all of whose topics are kept: its chunks copied as they are,
    :func:`_write_lifted`), each answer after every input message of its log time. Large topics
    (images) are never held.

    Parameters
    ----------
    in_path, out_path : path
        The input bag: an MCAP file or a rosbag2 directory (or its ``metadata.yaml``), its split
        files read as one stream, so tracks continue across them; the output: an MCAP file.
    lifter : Lifter
    settings : LiftSettings
        Read here besides what :func:`lift_messages` reads: ``every`` (lift only every
        ``every``-th keypoint message; the others are copied but not lifted), ``max_messages``
        (stop after this many keypoint messages; inputs are cut there too), ``topic`` (the
        keypoints: ``pose_lifter_msgs/msg/Skeleton2DArray`` or ``yolo_msgs/msg/DetectionArray``),
        ``camera_info_topic`` (``sensor_msgs/msg/CameraInfo`` for the metric placement; None or
        absent: the default distance), ``frame.depth_topic`` and ``frame.depth_tolerance`` (the
        depth images, :mod:`pose_lifter.offline.depth`; the summary's ``depth`` says how many
        messages were paired), ``keep`` (input topics copied to the output; None = all,
        ``[]`` = none), ``marker_lifetime`` (seconds, 0 = until replaced or deleted).
    progress, overwrite : bool
    workers : int
        Processes lifting the tracks in parallel (results identical to 1), see
        :func:`lift_messages`.
    first_pass : FirstPassAhead, optional
        The bag's first pass, read ahead by the caller
        (:func:`~pose_lifter.offline.first_pass.read_ahead` of this bag and ``settings``'
        :class:`~pose_lifter.offline.first_pass.FirstPassPlan`: another plan is a ``ValueError``);
        None: read here (:func:`~pose_lifter.offline.first_pass.read_first_pass`).
    """
    every, max_messages, topic = settings.every, settings.max_messages, settings.topic
    if every < 1:
        raise ValueError("every must be >= 1")
    topics = check_lift_inputs(in_path, out_path, topic, settings.camera_info_topic, settings.keep, overwrite,
                               settings.frame.depth_topic)
    plan = FirstPassPlan.of(in_path, settings, topics)
    depth_topic = None if plan.depth is None else plan.depth[0]
    cdr.check_definitions(pose_lifter_typestore())
    if first_pass is not None and first_pass.plan != plan:
        raise ValueError(f"the first pass read ahead was planned for other settings: {first_pass.plan} "
                         f"instead of {plan}")
    first = first_pass() if first_pass is not None else read_first_pass(in_path, plan)
    kp_all, infos = first.keypoints, first.infos
    last = kp_all[-1][0] if max_messages is not None else None
    to_lift = kp_all[::every]
    index_of = {id(msg): i * every for i, (_, msg) in enumerate(to_lift)}
    summary = LiftSummary()
    answers: dict[int, FrameAnswer] = {}  # index of the keypoint message -> its answer
    markers = MarkerBook(_MARKER_NS) if settings.publish_markers else None
    bodies = hri.BodyBook(settings.frame.track_timeout) if settings.publish_hri else None
    sizes = [(s, (float(i.width), float(i.height))) for s, i in infos if i.width > 0 and i.height > 0]
    size_stamps = [s for s, _ in sizes]
    answered: list[tuple[int, Any, SkeletonFrame]] = []  # (stamp, message, its lifted skeletons)
    if depth_topic is not None and not infos:
        summary.notes.append(f"depth topic {depth_topic} but no camera_info: lifted from the 2D alone")
    elif depth_topic is not None:  # each message's camera size: the last camera_info's at or before it
        summary.depth = pair_depth(
            in_path, depth_topic, topics[depth_topic],
            [m.stamp_to_ns(msg.header.stamp) or stamp for stamp, msg in to_lift],
            [sizes[max(0, bisect.bisect_right(size_stamps, stamp) - 1)][1] if sizes else None
             for stamp, _ in to_lift], settings.frame.depth_tolerance, first.depth_stamps)
        refused = summary.depth.first_refusal()
        if refused:
            summary.notes.append(f"depth image refused: {refused}; such frames are lifted from the 2D alone")
    frames = lift_messages(to_lift, infos, lifter, settings, progress=progress,
                           on_answer=lambda *a: answered.append(a), summary=summary, workers=workers,
                           depth=summary.depth)
    # the node's answers (messages/answer.py), in order: the REP-155 bodies timed by the header
    # stamp (the bag stamp when it is 0, as the node's arrival time), with the image size of the
    # last camera_info at or before the frame; the bodies' poses of every frame in one pass
    poses = hri.tracked_body_poses([lifted for _, _, lifted in answered]) if bodies is not None else None
    for k, (stamp, msg, lifted) in enumerate(answered):
        at = bisect.bisect_right(size_stamps, stamp) - 1
        size = sizes[at][1] if at >= 0 else None
        answers[index_of[id(msg)]] = frame_answer(
            msg.header, m.stamp_to_ns(msg.header.stamp) or stamp, lifted, markers=markers,
            marker_lifetime=settings.marker_lifetime, bodies=bodies, image_size=size,
            body_poses=None if poses is None else poses[k])
    if summary.depth is not None:
        summary.notes.insert(0, summary.depth_line())
    kept = set(topics) if settings.keep is None else set(settings.keep)
    _write_lifted(in_path, out_path, topic, kept, last, answers, [stamp for stamp, _ in kp_all], overwrite)
    return summary, frames


def _write_lifted(in_path: str | Path, out_path: str | Path, topic: str, kept: set[str], last: int | None,
                  answers: dict[int, FrameAnswer], stamps: Sequence[int], overwrite: bool) -> None:
    """The output bag: the ``kept`` input topics copied byte for byte up to the stamp ``last``
    (None: all), each keypoint message's answer (``answers``: the keypoint message's index in the
    bag -> its answer; ``stamps``: each keypoint message's bag stamp) after every input message of
    its log time (a reader in log-time order reads a copied chunk's messages of one log time
    together, :mod:`pose_lifter.offline.chunk_copy`).

    A single chunked MCAP file all of whose topics are kept (without ``last``) has its chunks
    copied as they are (:func:`~pose_lifter.offline.chunk_copy.copy_with`: nothing decompressed or
    compressed again); any other input is read and written message by message."""
    if last is None:
        mcap = chunked_mcap(in_path)
        if mcap is not None and {c.topic for c in mcap.channels.values()} <= kept:
            additions = [(stamps[i], answers[i].messages()) for i in sorted(answers)]
            if copy_with(mcap, out_path, additions, overwrite):
                return
    index = 0
    pending: list[tuple[int, FrameAnswer]] = []  # answers waiting for the last input message of their stamp
    with BagWriter(out_path, overwrite=overwrite) as w:

        def flush(before: int | None) -> None:
            while pending and (before is None or pending[0][0] < before):
                stamp, answer = pending.pop(0)
                for out_topic, data, msgtype in answer.messages():
                    w.write_cdr(out_topic, stamp, data, msgtype)

        for raw in read_raw(in_path, kept | {topic}):
            if last is not None and raw.stamp_ns > last:
                break
            flush(raw.stamp_ns)
            if raw.topic in kept:
                w.write_raw(raw)
            if raw.topic == topic:
                answer = answers.pop(index, None)
                if answer is not None:
                    pending.append((raw.stamp_ns, answer))
                index += 1
        flush(None)
