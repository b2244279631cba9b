"""Offline work on bags: lift every ``/keypoints_2d`` message, and evaluate against ground truth.

``lift_bag`` is what the node does, frame by frame, without ROS: per-track warm starts,
metric placement in the camera frame from ``/camera_info``, ``/skeletons_3d`` and
``/skeleton_markers`` written next to the input topics. ``evaluate_bag`` matches
``/skeletons_3d`` to ``/ground_truth/skeletons_3d`` by stamp and track id and reports the
errors with two floors that any lifter must beat (see ``shared/notes/method-pitfalls.md``).
"""

from __future__ import annotations

import gc
import json
import os
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.bases import PoseBases
from pose_lifter.core.errors import InvalidInputError, PoseLifterError, TooFewJointsError
from pose_lifter.core.lifter import Lifter
from pose_lifter.core.metrics import mpjpe, normalised_error, p_mpjpe, similarity_normalised_error
from pose_lifter.core.placement import DEFAULT_DISTANCE_M, DEFAULT_LEG_LENGTH_M
from pose_lifter.core.skeleton import N_JOINTS
from pose_lifter.core.smoothing import centred_smoothing
from pose_lifter.core.tracking import TrackPolicy
from pose_lifter.messages import cdr
from pose_lifter.messages import convert as m
from pose_lifter.mocap.scenes import (
    TOPIC_CAMERA_INFO,
    TOPIC_GROUND_TRUTH,
    TOPIC_KEYPOINTS,
    TOPIC_MARKERS,
    TOPIC_SKELETONS,
)
from pose_lifter.offline.bags import (
    BagError,
    BagReadError,
    BagWriter,
    bag_topics,
    check_output,
    pose_lifter_typestore,
    read_messages,
    read_raw,
)

__all__ = [
    "DEFAULT_DISTANCE_M",
    "DEFAULT_LEG_LENGTH_M",
    "LIFTABLE_TYPES",
    "Evaluation",
    "FrameLift",
    "LiftSummary",
    "MessageFields",
    "check_lift_inputs",
    "evaluate_bag",
    "format_evaluation",
    "lift_bag",
    "lift_messages",
]

#: The node's default ``track_timeout`` (seconds of input time a warm start stays valid).
DEFAULT_TRACK_TIMEOUT_S: Final[float] = 1.0
#: The node's default ``reinit_ratio`` (a degraded warm solve is redone cold).
DEFAULT_REINIT_RATIO: Final[float] = 2.0
_MARKER_NS: Final[str] = "pose_lifter"
_MSG_2D: Final[str] = cdr.SKELETON2D_ARRAY
_MSG_3D: Final[str] = cdr.SKELETON3D_ARRAY
_MSG_MARKERS: Final[str] = cdr.MARKER_ARRAY


@dataclass
class LiftSummary:
    """What :func:`lift_bag` did."""

    n_messages: int = 0
    n_skeletons: int = 0
    n_lifted: int = 0
    n_failed: int = 0
    n_warm: int = 0
    solve_time_s: float = 0.0
    failures: list[str] = field(default_factory=list)

    @property
    def mean_solve_time_ms(self) -> float:
        return 1e3 * self.solve_time_s / max(1, self.n_lifted)


@dataclass(frozen=True)
class FrameLift:
    """One lifted skeleton (for plots and tests)."""

    stamp_ns: int
    track_id: int
    points_2d: NDArray[np.float64]
    confidence: NDArray[np.float64]
    joints_m: NDArray[np.float64]
    warm_started: bool
    solve_time: float


def _intrinsics(camera_infos: list[tuple[int, Any]], stamp: int
                ) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """Intrinsics of the latest CameraInfo at or before ``stamp`` (else the first one)."""
    if not camera_infos:
        return None, None
    chosen = camera_infos[0][1]
    for s, info in camera_infos:
        if s > stamp:
            break
        chosen = info
    focal, pp = m.intrinsics_from_camera_info(chosen)
    return focal, pp


@dataclass(frozen=True)
class _Item:
    """One skeleton of one message, ready to lift (or the reason it cannot be)."""

    msg_index: int
    stamp_ns: int
    track_id: int
    points: NDArray[np.float64] | None
    confidence: NDArray[np.float64] | None
    focal: tuple[float, float] | None
    centre: tuple[float, float] | None
    error: str | None


@dataclass(frozen=True)
class _Done:
    """What lifting one :class:`_Item` gave: the result and metric joints, or the failure."""

    item: _Item
    result: Any | None
    joints_m: NDArray[np.float64] | None
    warm_started: bool
    solve_time: float
    failure: str | None


def _chains(keypoint_msgs: list[tuple[int, Any]], camera_infos: list[tuple[int, Any]],
            warm_start: bool) -> tuple[list[list[_Item]], list[list[_Item]]]:
    """Split the skeletons into independent chains: one per track id (in message order) when
    warm-starting, one per skeleton otherwise. Returns (chains, items per message)."""
    per_track: dict[int, list[_Item]] = {}
    chains: list[list[_Item]] = []
    per_msg: list[list[_Item]] = []
    for i, (stamp, msg) in enumerate(keypoint_msgs):
        focal, centre = _intrinsics(camera_infos, stamp)
        items: list[_Item] = []
        seen: set[int] = set()
        for skel in msg.skeletons:
            tid = int(skel.track_id)
            try:
                if tid >= 0 and tid in seen:  # as the node: a later copy is skipped
                    raise InvalidInputError(f"duplicate track id {tid} in one frame: later copy skipped")
                seen.add(tid)
                pts, conf = m.skeleton2d_to_arrays(skel, msg.layout)
                item = _Item(i, stamp, tid, pts, conf, focal, centre, None)
            except (InvalidInputError, TooFewJointsError) as exc:
                item = _Item(i, stamp, tid, None, None, focal, centre, str(exc))
            items.append(item)
            if warm_start and tid >= 0:
                per_track.setdefault(tid, []).append(item)
            else:
                chains.append([item])
        per_msg.append(items)
    return chains + list(per_track.values()), per_msg


def _lift_chain(lifter: Lifter, chain: list[_Item], leg_length_m: float, default_distance_m: float,
                track_timeout: float = DEFAULT_TRACK_TIMEOUT_S, warm_start: bool = True,
                reinit_ratio: float = DEFAULT_REINIT_RATIO, smoothing_s: float = 0.0) -> list[_Done]:
    """Lift one chain in order through the node's per-track policy
    (:class:`pose_lifter.core.tracking.TrackPolicy`: warm starts within ``track_timeout``,
    re-initialisation, out-of-order frames refused, a failure starts over); with
    ``smoothing_s > 0`` the chain's poses are then smoothed centred (:func:`_smooth_chain`)."""
    out: list[_Done] = []
    fits: list[NDArray[np.float64] | None] = []  # the fit's own pose_camera per outcome
    policy = TrackPolicy(lifter, track_timeout, warm_start, reinit_ratio)
    for item in chain:
        try:
            if item.error is not None:
                raise InvalidInputError(item.error)
            assert item.points is not None
            t0 = time.perf_counter()
            tracked = policy.lift(item.track_id, item.stamp_ns, item.points, item.confidence)
            dt = time.perf_counter() - t0
            res = tracked.result
            joints = m.place_in_camera(res, leg_length_m, item.focal, item.centre, default_distance_m)
        except PoseLifterError as exc:
            out.append(_Done(item, None, None, False, 0.0, str(exc)))
            fits.append(None)
            continue
        out.append(_Done(item, res, joints, tracked.warm_started, dt, None))
        # the centred smoothing starts from the fit's own pose; with the measurement update, from
        # the published one (which has read each frame's 2D; docs/tuning.md)
        fits.append(None if lifter.options.measurement_update else tracked.fit_pose_camera)
    if smoothing_s > 0:
        return _smooth_chain(out, fits, leg_length_m, default_distance_m, smoothing_s, track_timeout)
    return out


def _smooth_chain(done: list[_Done], fits: list[NDArray[np.float64] | None], leg_length_m: float,
                  default_distance_m: float, smoothing_s: float, gap_s: float) -> list[_Done]:
    """A lifted chain with its metric joints smoothed by a centred Gaussian window of
    ``smoothing_s`` seconds (:func:`pose_lifter.core.smoothing.centred_smoothing`, segments split at
    gaps over ``gap_s``), from the fit's own poses (``fits[i]``; None: from the result's pose, the
    fit's or, with ``measurement_update``, the published one): without the update the causal
    output smoothing of the live node is replaced, not compounded. Each
    result's ``pose`` and ``pose_camera`` become the smoothed pose (camera and the rest kept)."""
    rows = [i for i, d in enumerate(done) if d.result is not None and d.joints_m is not None]
    if len(rows) < 2:
        return done
    placed = np.empty((len(rows), N_JOINTS, 3))
    for r, i in enumerate(rows):
        d, fit = done[i], fits[i]
        res = d.result if fit is None else replace(d.result, pose_camera=fit)
        placed[r] = m.place_in_camera(res, leg_length_m, d.item.focal, d.item.centre, default_distance_m)
    stamps = np.array([done[i].item.stamp_ns for i in rows], dtype=np.int64)
    smooth = centred_smoothing(placed, stamps, np.ones(len(rows), dtype=bool), smoothing_s, gap_s)
    out = list(done)
    for r, i in enumerate(rows):
        d = done[i]
        pose_camera = (smooth[r] - smooth[r].mean(axis=0)) / leg_length_m
        # the body-frame pose with the same camera: pose_camera = (pose - mean) @ R^T
        pose = pose_camera @ d.result.camera.rotation + d.result.pose.mean(axis=0)
        res = replace(d.result, pose=pose, pose_camera=pose_camera)
        out[i] = _Done(d.item, res, smooth[r], d.warm_started, d.solve_time, None)
    return out


#: The lifter of the worker processes of :func:`lift_messages` (inherited through fork).
_WORKER: dict[str, Any] = {}


def _worker_init() -> None:
    """Ctrl-C ends a worker silently (the parent reports it once), not with a traceback each."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _stop_workers(ex: Any) -> None:
    """Terminate a ProcessPoolExecutor's processes and drop its queued work."""
    processes = getattr(ex, "_processes", None) or {}  # pid -> Process (no public accessor)
    for proc in list(processes.values()):
        proc.terminate()
    ex.shutdown(wait=True, cancel_futures=True)


#: What a worker sends back per item: (result, joints_m, warm_started, solve_time, failure).
_Outcome = tuple[Any, NDArray[np.float64] | None, bool, float, str | None]


@dataclass(frozen=True)
class MessageFields:
    """The part of a ``LiftResult`` that the output messages carry
    (:meth:`pose_lifter.messages.cdr.SkeletonFrame.from_results`): what a worker of :func:`lift_bag` sends
    back instead of the whole result (its history, prior pose, ...), as columns of a chain
    (:func:`_columns`)."""

    camera: Any
    objective: float
    reprojection_error: float
    total_alternations: int
    converged: bool
    weights: NDArray[np.float64]



def _columns(done: list[_Done]) -> tuple[list[tuple[bool, float, str | None, int]],
                                        dict[str, NDArray[Any]]]:
    """A chain's outcomes as a few arrays (one pickle each, not one object tree per pose): per
    item (warm_started, solve_time, failure, row of its lift or -1), and the rows' message fields."""
    ok = [d for d in done if d.failure is None and d.result is not None and d.joints_m is not None]
    row = {id(d): i for i, d in enumerate(ok)}
    items = [(d.warm_started, d.solve_time, d.failure, row.get(id(d), -1)) for d in done]
    res: list[Any] = [d.result for d in ok]
    cams = [r.camera for r in res]
    cols: dict[str, NDArray[Any]] = {
        "rotation": np.array([c.rotation for c in cams], dtype=np.float64).reshape(-1, 3, 3),
        "scale": np.array([c.scale for c in cams], dtype=np.float64),
        "translation": np.array([c.translation for c in cams], dtype=np.float64).reshape(-1, 2),
        "objective": np.array([r.objective for r in res], dtype=np.float64),
        "reprojection_error": np.array([r.reprojection_error for r in res], dtype=np.float64),
        "total_alternations": np.array([r.total_alternations for r in res], dtype=np.int64),
        "converged": np.array([r.converged for r in res], dtype=bool),
        "weights": np.array([r.weights for r in res], dtype=np.float64).reshape(-1, N_JOINTS),
        "joints_m": np.array([d.joints_m for d in ok], dtype=np.float64).reshape(-1, N_JOINTS, 3),
    }
    return items, cols


def _from_columns(chain: list[_Item], items: list[tuple[bool, float, str | None, int]],
                  cols: dict[str, NDArray[Any]]) -> list[_Done]:
    """The :class:`_Done` s of a chain from :func:`_columns` (results as :class:`MessageFields`)."""
    from pose_lifter.core.results import Camera

    out = []
    for item, (warm, dt, failure, i) in zip(chain, items, strict=True):
        if i < 0:
            out.append(_Done(item, None, None, warm, dt, failure))
            continue
        cam = Camera(cols["rotation"][i], float(cols["scale"][i]), cols["translation"][i])
        fields = MessageFields(cam, float(cols["objective"][i]), float(cols["reprojection_error"][i]),
                               int(cols["total_alternations"][i]), bool(cols["converged"][i]),
                               cols["weights"][i])
        out.append(_Done(item, fields, cols["joints_m"][i], warm, dt, None))
    return out


def _worker_chain(index: int) -> Any:
    """Lift chain ``index`` of the chains the worker inherited (fork): the chain's items are not
    pickled to the worker, and only the outcomes come back (the parent holds the items): whole
    results, or only their message fields as columns (:func:`_columns`)."""
    chain = _WORKER["chains"][index]
    done = _lift_chain(_WORKER["lifter"], chain, _WORKER["leg"], _WORKER["distance"], _WORKER["timeout"],
                       True, _WORKER["reinit"], _WORKER["smoothing"])
    if _WORKER["slim"]:
        return _columns(done)
    return [(d.result, d.joints_m, d.warm_started, d.solve_time, d.failure) for d in done]


def lift_messages(
    keypoint_msgs: list[tuple[int, Any]],
    camera_infos: list[tuple[int, Any]],
    lifter: Lifter,
    warm_start: bool = True,
    leg_length_m: float = DEFAULT_LEG_LENGTH_M,
    default_distance_m: float = DEFAULT_DISTANCE_M,
    progress: bool = False,
    on_frame: Callable[[int, Any, list[FrameLift], list[Any]], None] | None = None,
    summary: LiftSummary | None = None,
    workers: int = 1,
    track_timeout: float = DEFAULT_TRACK_TIMEOUT_S,
    reinit_ratio: float = DEFAULT_REINIT_RATIO,
    message_fields_only: bool = False,
    smoothing_s: float = 0.0,
) -> list[FrameLift]:
    """Lift ``Skeleton2DArray`` messages in order with per-track warm starts.

    A tracked person (track_id >= 0) starts from its solution in the previous message when it
    was lifted there (as the node does); untracked skeletons and tracks that were absent or
    failed in the previous message are solved cold. Tracks are independent chains, so
    ``workers > 1`` lifts them in parallel processes with results identical to ``workers=1``.

    Parameters
    ----------
    keypoint_msgs : list of (stamp_ns, Skeleton2DArray)
    camera_infos : list of (stamp_ns, CameraInfo), time-ordered
    lifter : Lifter
    warm_start : bool
        Start each tracked person (track_id >= 0) from its previous frame's solution.
    leg_length_m, default_distance_m : float
        See :func:`pose_lifter.messages.convert.place_in_camera`.
    progress : bool
        Show a tqdm progress bar (skeletons).
    on_frame : callable, optional
        ``on_frame(stamp_ns, msg, lifted, results)`` for each message, in order, after the
        lifting (``results`` holds the LiftResult of each lifted skeleton, in the order of
        ``lifted``).
    summary : LiftSummary, optional
        Filled in place.
    workers : int
        Processes (fork) lifting the chains; 1 lifts in this process.
    track_timeout : float
        Seconds of input time a track's warm start stays valid (the node's ``track_timeout``).
    reinit_ratio : float
        The node's ``reinit_ratio`` (:class:`pose_lifter.core.tracking.TrackPolicy`).
    message_fields_only : bool
        With ``workers > 1``, ``on_frame`` gets :class:`MessageFields` (what the output messages
        carry) in place of whole ``LiftResult`` s: less to send back from the workers.
    smoothing_s : float
        0 (default): each track's poses are the node's, causal. ``> 0``: each track's poses are
        smoothed with a centred Gaussian window of this standard deviation in seconds, past and
        future frames alike (:mod:`pose_lifter.core.smoothing`; ``pose-lifter lift``'s default is
        :data:`~pose_lifter.core.smoothing.OFFLINE_SMOOTHING_S`).
    """
    from tqdm import tqdm

    if workers < 1:
        raise ValueError("workers must be >= 1")
    summ = summary if summary is not None else LiftSummary()
    chains, per_msg = _chains(keypoint_msgs, camera_infos, warm_start)
    done: dict[int, _Done] = {}  # id(item) -> outcome
    bar = tqdm(total=sum(len(c) for c in chains), desc="lifting", unit="skeleton", disable=not progress)
    if workers == 1 or len(chains) < 2:
        for chain in chains:
            for d in _lift_chain(lifter, chain, leg_length_m, default_distance_m, track_timeout, True,
                                 reinit_ratio, smoothing_s):
                done[id(d.item)] = d
                bar.update(1)
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        order = sorted(chains, key=len, reverse=True)  # longest first: balanced workers
        _WORKER.update(lifter=lifter, leg=leg_length_m, distance=default_distance_m, timeout=track_timeout,
                       reinit=reinit_ratio, smoothing=smoothing_s, chains=order, slim=message_fields_only)
        # never more processes than chains or cores (1000 workers for 5 tracks forked 1000)
        n_proc = min(workers, len(chains), os.cpu_count() or 1)
        # the workers inherit every object of this process (the bag's messages too): frozen, the
        # garbage collector of a worker does not walk them, so their pages are not copied
        gc.freeze()
        try:
            ex = ProcessPoolExecutor(n_proc, mp_context=multiprocessing.get_context("fork"),
                                     initializer=_worker_init)
            try:
                for chain, outcomes in zip(order, ex.map(_worker_chain, range(len(order))), strict=True):
                    if message_fields_only:
                        for d in _from_columns(chain, *outcomes):
                            done[id(d.item)] = d
                        bar.update(len(chain))
                        continue
                    for item, (res, joints, warm, dt, failure) in zip(chain, outcomes, strict=True):
                        done[id(item)] = _Done(item, res, joints, warm, dt, failure)
                        bar.update(1)
            except BaseException:  # Ctrl-C or a failure: stop the workers now, not after their chains
                _stop_workers(ex)
                raise
            ex.shutdown()
        finally:
            _WORKER.clear()
            gc.unfreeze()
    bar.close()

    out: list[FrameLift] = []
    for (stamp, msg), items in zip(keypoint_msgs, per_msg, strict=True):
        summ.n_messages += 1
        lifted: list[FrameLift] = []
        results: list[Any] = []
        for item in items:
            summ.n_skeletons += 1
            d = done[id(item)]
            if d.failure is not None or d.result is None or d.joints_m is None:
                summ.n_failed += 1
                if len(summ.failures) < 20:
                    summ.failures.append(f"{stamp} track {item.track_id}: {d.failure}")
                continue
            summ.n_lifted += 1
            summ.n_warm += int(d.warm_started)
            summ.solve_time_s += d.solve_time
            assert item.points is not None and item.confidence is not None
            lifted.append(FrameLift(stamp, item.track_id, item.points, item.confidence, d.joints_m,
                                    d.warm_started, d.solve_time))
            results.append(d.result)
        out.extend(lifted)
        if on_frame is not None:
            on_frame(stamp, msg, lifted, results)
    return out


#: Message types ``lift_bag`` lifts: ours as they are, yolo_ros' through :mod:`pose_lifter.messages.adapters`.
LIFTABLE_TYPES: Final[tuple[str, ...]] = (_MSG_2D, "yolo_msgs/msg/DetectionArray")
_MSG_CAMERA_INFO: Final[str] = "sensor_msgs/msg/CameraInfo"


def check_lift_inputs(
    in_path: str | Path,
    out_path: str | Path,
    topic: str = TOPIC_KEYPOINTS,
    camera_info_topic: str | None = TOPIC_CAMERA_INFO,
    keep: Sequence[str] | None = None,
    overwrite: bool = False,
) -> dict[str, str]:
    """Everything :func:`lift_bag` can check before any work; returns the bag's topic -> type.

    Raises
    ------
    BagError
        ``out_path`` does not end in ``.mcap``, exists (without ``overwrite``), is a directory or
        has no parent directory; the input is missing or unreadable; ``topic`` is missing or not a
        liftable type; a kept topic is missing; ``camera_info_topic`` has another type.
    """
    out = check_output(out_path, (".mcap",), overwrite)
    if Path(in_path).resolve() == out.resolve():
        raise BagError("the output would overwrite the input")
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
    if camera_info_topic and camera_info_topic in topics and topics[camera_info_topic] != _MSG_CAMERA_INFO:
        raise BagError(f"camera-info topic {camera_info_topic!r} is {topics[camera_info_topic]}, "
                       f"not {_MSG_CAMERA_INFO}")
    missing = sorted(set(keep or ()) - set(topics))
    if missing:
        raise BagError(f"{in_path} has no topic(s) {missing} to keep; its topics: {sorted(topics)}")
    return topics


def _as_skeleton2d(msg: Any, msgtype: str, types: Any, track_ids: Any) -> Any:
    """A Skeleton2DArray from a liftable message (yolo DetectionArray -> wang12 array)."""
    if msgtype == _MSG_2D:
        return msg
    from pose_lifter.messages import adapters

    people, _ = adapters.yolo_detections_to_people(msg, track_ids)
    return adapters.people_to_skeleton2d_array(msg.header, people, types)


def lift_bag(
    in_path: str | Path,
    out_path: str | Path,
    lifter: Lifter,
    warm_start: bool = True,
    leg_length_m: float = DEFAULT_LEG_LENGTH_M,
    default_distance_m: float = DEFAULT_DISTANCE_M,
    every: int = 1,
    max_messages: int | None = None,
    progress: bool = True,
    overwrite: bool = False,
    marker_lifetime: float = 0.0,
    workers: int = 1,
    topic: str = TOPIC_KEYPOINTS,
    camera_info_topic: str | None = TOPIC_CAMERA_INFO,
    keep: Sequence[str] | None = None,
    track_timeout: float = DEFAULT_TRACK_TIMEOUT_S,
    reinit_ratio: float = DEFAULT_REINIT_RATIO,
    smoothing_s: float = 0.0,
) -> tuple[LiftSummary, list[FrameLift]]:
    """Lift every message of ``topic`` of a bag into a new bag.

    The output holds the kept input topics (copied byte for byte, same stamps; all of them by
    default) plus ``/skeletons_3d`` (``Skeleton3DArray``, camera optical frame, metres) and
    ``/skeleton_markers`` (``MarkerArray``: joints and bones per track, DELETE for vanished
    tracks). Everything checkable is checked before any work (:func:`check_lift_inputs`).

    Memory: the bag is read twice, streaming: first only ``topic`` and ``camera_info_topic``
    (deserialised, kept for the lifting), then every kept topic one message at a time, copied
    as serialised bytes. Large topics (images) are never held.

    Parameters
    ----------
    in_path, out_path : path
        MCAP files.
    lifter : Lifter
    warm_start : bool
    leg_length_m, default_distance_m : float
    every : int
        Lift only every ``every``-th keypoint message (the others are copied but not lifted).
    max_messages : int, optional
        Stop after this many keypoint messages (inputs are cut there too).
    progress : bool
    overwrite : bool
    marker_lifetime : float
        Seconds (0 = until replaced/deleted).
    workers : int
        Processes lifting the tracks in parallel (results identical to 1), see
        :func:`lift_messages`.
    topic : str
        The keypoints: ``pose_lifter_msgs/msg/Skeleton2DArray`` or ``yolo_msgs/msg/DetectionArray``.
    camera_info_topic : str or None
        ``sensor_msgs/msg/CameraInfo`` for the metric placement (None or absent: the default
        distance).
    keep : sequence of str, optional
        Input topics copied to the output; None = all, ``[]`` = none.
    track_timeout, reinit_ratio, smoothing_s : float
        See :func:`lift_messages` (``smoothing_s`` 0: the node's causal poses).
    """
    if every < 1:
        raise ValueError("every must be >= 1")
    topics = check_lift_inputs(in_path, out_path, topic, camera_info_topic, keep, overwrite)
    from pose_lifter.messages.adapters import TrackIds

    cdr.check_definitions(pose_lifter_typestore())
    types = m.rosbags_types()
    ids = TrackIds()
    wanted = [topic] + ([camera_info_topic] if camera_info_topic in topics else [])
    kp_all: list[tuple[int, Any]] = []
    infos: list[tuple[int, Any]] = []
    for x in read_messages(in_path, wanted, decoders={_MSG_2D: cdr.decode_skeleton2d_array}):
        if x.topic == topic:
            if max_messages is not None and len(kp_all) >= max_messages * every:
                break
            kp_all.append((x.stamp_ns, _as_skeleton2d(x.msg, x.msgtype, types, ids)))
        else:
            infos.append((x.stamp_ns, x.msg))
    if not kp_all:
        raise InvalidInputError(f"{in_path} has no {topic} messages")
    last = kp_all[-1][0] if max_messages is not None else None
    to_lift = kp_all[::every]
    summary = LiftSummary()
    outputs: dict[int, tuple[bytes, bytes]] = {}  # index of the keypoint message -> its answers (CDR)
    previous: set[int] = set()

    def record(stamp: int, msg: Any, lifted: list[FrameLift], results: list[Any]) -> None:
        # serialised here, straight from the arrays: the bytes of the node's builders
        # (messages.result_to_skeleton3d / skeleton_markers) through rosbags, see pose_lifter.messages.cdr
        nonlocal previous
        frame = cdr.SkeletonFrame.from_results([f.track_id for f in lifted], [f.joints_m for f in lifted],
                                               results, [f.solve_time for f in lifted],
                                               [f.warm_started for f in lifted])
        now = {f.track_id for f in lifted if f.track_id >= 0}
        markers = cdr.marker_array_cdr(msg.header, frame.track_ids.tolist(), frame.joints_m, _MARKER_NS,
                                       marker_lifetime, deleted_track_ids=sorted(previous - now))
        previous = now
        outputs[len(outputs) * every] = (cdr.skeleton3d_array_cdr(msg.header, frame), markers)

    frames = lift_messages(to_lift, infos, lifter, warm_start, leg_length_m, default_distance_m,
                           progress, record, summary, workers=workers, track_timeout=track_timeout,
                           reinit_ratio=reinit_ratio, message_fields_only=True, smoothing_s=smoothing_s)
    kept = set(topics) if keep is None else set(keep)
    index = 0
    with BagWriter(out_path, overwrite=overwrite) as w:
        for raw in read_raw(in_path, kept | {topic}):
            if last is not None and raw.stamp_ns > last:
                break
            if raw.topic in kept:
                w.write_raw(raw)
            if raw.topic == topic:
                if index in outputs:
                    skels, markers = outputs.pop(index)
                    w.write_cdr(TOPIC_SKELETONS, raw.stamp_ns, skels, _MSG_3D)
                    w.write_cdr(TOPIC_MARKERS, raw.stamp_ns, markers, _MSG_MARKERS)
                index += 1
    return summary, frames


# --------------------------------------------------------------------------- evaluation


@dataclass
class Evaluation:
    """Errors of a lifted bag against its ground truth, per matched skeleton.

    Arrays have one entry per matched (stamp, track) pair. Floors are computed on the same
    pairs: ``flat`` is the 2D input with zero depth, ``mean_pose`` the bases' mean pose,
    both similarity-aligned to the truth.
    """

    n_ground_truth: int
    n_estimates: int
    n_matched: int
    mpjpe_mm: NDArray[np.float64]
    p_mpjpe_mm: NDArray[np.float64]
    normalised: NDArray[np.float64]
    flat_p_mpjpe_mm: NDArray[np.float64]
    flat_normalised: NDArray[np.float64]
    mean_pose_p_mpjpe_mm: NDArray[np.float64]
    mean_pose_normalised: NDArray[np.float64]
    track_ids: NDArray[np.int64]

    def table(self) -> dict[str, dict[str, float | None]]:
        """Mean errors: {row: {"mpjpe_mm", "p_mpjpe_mm", "normalised"}}."""

        def mean(a: NDArray[np.float64]) -> float | None:
            return float(np.mean(a)) if a.size else None

        return {
            "lifter": {"mpjpe_mm": mean(self.mpjpe_mm), "p_mpjpe_mm": mean(self.p_mpjpe_mm),
                       "normalised": mean(self.normalised)},
            "flat_floor": {"mpjpe_mm": None, "p_mpjpe_mm": mean(self.flat_p_mpjpe_mm),
                           "normalised": mean(self.flat_normalised)},
            "mean_pose_floor": {"mpjpe_mm": None, "p_mpjpe_mm": mean(self.mean_pose_p_mpjpe_mm),
                                "normalised": mean(self.mean_pose_normalised)},
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (means, medians, counts, per-track means)."""
        per_track = {}
        for tid in np.unique(self.track_ids):
            sel = self.track_ids == tid
            per_track[str(int(tid))] = {
                "n": int(sel.sum()), "mpjpe_mm": float(self.mpjpe_mm[sel].mean()),
                "p_mpjpe_mm": float(self.p_mpjpe_mm[sel].mean()),
                "normalised": float(self.normalised[sel].mean()),
            }
        return {
            "n_ground_truth": self.n_ground_truth, "n_estimates": self.n_estimates,
            "n_matched": self.n_matched, "mean": self.table(),
            "median": {"lifter": {"mpjpe_mm": _median(self.mpjpe_mm),
                                  "p_mpjpe_mm": _median(self.p_mpjpe_mm),
                                  "normalised": _median(self.normalised)}},
            "per_track": per_track,
        }


def _median(a: NDArray[np.float64]) -> float | None:
    return float(np.median(a)) if a.size else None


def _flat(points: NDArray[np.float64], confidence: NDArray[np.float64]) -> NDArray[np.float64]:
    """2D input with zero depth; missing joints at the centroid of the visible ones."""
    pts = np.array(points, dtype=np.float64, copy=True)
    vis = confidence > 0
    if vis.any():
        pts[~vis] = pts[vis].mean(axis=0)
    return np.concatenate([pts, np.zeros((N_JOINTS, 1))], axis=1)


def evaluate_bag(path: str | Path, bases: PoseBases | None = None) -> Evaluation:
    """Match ``/skeletons_3d`` with ``/ground_truth/skeletons_3d`` by (stamp, track id).

    Parameters
    ----------
    path : path
        A bag written by :func:`lift_bag` (or any bag with both topics and ``/keypoints_2d``).
    bases : PoseBases, optional
        For the mean-pose floor (default: the packaged bases).
    """
    b = bases if bases is not None else PoseBases.load()
    gt: dict[tuple[int, int], NDArray[np.float64]] = {}
    est: dict[tuple[int, int], NDArray[np.float64]] = {}
    inp: dict[tuple[int, int], tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    joints_of = {TOPIC_GROUND_TRUTH: gt, TOPIC_SKELETONS: est}  # the 3D topics: (stamp, track) -> joints
    for x in read_messages(path):
        if x.topic in joints_of:
            s = m.stamp_to_ns(x.msg.header.stamp)
            for sk in x.msg.skeletons:
                joints_of[x.topic][(s, int(sk.track_id))] = m.skeleton3d_to_joints(sk)
        elif x.topic == TOPIC_KEYPOINTS:
            s = m.stamp_to_ns(x.msg.header.stamp)
            for sk in x.msg.skeletons:
                try:
                    inp[(s, int(sk.track_id))] = m.skeleton2d_to_arrays(sk, x.msg.layout)
                except InvalidInputError:
                    continue
    if not gt:
        raise InvalidInputError(f"{path} has no {TOPIC_GROUND_TRUTH} messages")
    keys = sorted(k for k in est if k in gt)
    if not est:  # an input bag: floors only, over every ground-truth skeleton with 2D input
        floor_keys = sorted(k for k in gt if k in inp)
    else:
        floor_keys = [k for k in keys if k in inp]
    pred = np.array([est[k] for k in keys]).reshape(-1, N_JOINTS, 3)
    truth = np.array([gt[k] for k in keys]).reshape(-1, N_JOINTS, 3)
    ftruth = np.array([gt[k] for k in floor_keys]).reshape(-1, N_JOINTS, 3)
    flat = np.array([_flat(*inp[k]) for k in floor_keys]).reshape(-1, N_JOINTS, 3)
    meanp = np.broadcast_to(b.mean_pose, ftruth.shape)

    def per_pose(fn: Callable[..., NDArray[np.float64]], p: NDArray[np.float64], g: NDArray[np.float64],
                 factor: float = 1.0) -> NDArray[np.float64]:
        return factor * fn(p, g) if len(g) else np.zeros(0)

    return Evaluation(
        n_ground_truth=len(gt), n_estimates=len(est), n_matched=len(keys),
        mpjpe_mm=per_pose(mpjpe, pred, truth, 1e3), p_mpjpe_mm=per_pose(p_mpjpe, pred, truth, 1e3),
        normalised=per_pose(normalised_error, pred, truth),
        flat_p_mpjpe_mm=per_pose(p_mpjpe, flat, ftruth, 1e3),
        flat_normalised=per_pose(similarity_normalised_error, flat, ftruth),
        mean_pose_p_mpjpe_mm=per_pose(p_mpjpe, meanp, ftruth, 1e3),
        mean_pose_normalised=per_pose(similarity_normalised_error, meanp, ftruth),
        track_ids=np.array([k[1] for k in keys], dtype=np.int64),
    )


def format_evaluation(ev: Evaluation, as_json: bool = False) -> str:
    """The error table as text (or JSON)."""
    if as_json:
        return json.dumps(ev.to_dict(), indent=2, sort_keys=True)

    def f(v: float | None, fmt: str) -> str:
        return "n/a" if v is None else format(v, fmt)

    rows = ev.table()
    lines = [
        f"matched {ev.n_matched} of {ev.n_ground_truth} ground-truth skeletons "
        f"({ev.n_estimates} estimates)",
        f"{'':22s}{'MPJPE mm':>10s}{'P-MPJPE mm':>12s}{'normalised':>12s}",
    ]
    labels = {"lifter": "lifter", "flat_floor": "floor: flat 2D", "mean_pose_floor": "floor: mean pose"}
    for key, label in labels.items():
        r = rows[key]
        lines.append(f"{label:22s}{f(r['mpjpe_mm'], '.1f'):>10s}{f(r['p_mpjpe_mm'], '.1f'):>12s}"
                     f"{f(r['normalised'], '.3f'):>12s}")
    lines.append("normalised: the paper's error in right-lower-leg units (lifter: rotation-aligned, "
                 "own leg = 1; floors: similarity-aligned, truth's leg = 1)")
    if len(np.unique(ev.track_ids)) > 1:
        for tid, d in ev.to_dict()["per_track"].items():
            lines.append(f"  track {tid}: n={d['n']} MPJPE {d['mpjpe_mm']:.1f} mm, "
                         f"P-MPJPE {d['p_mpjpe_mm']:.1f} mm, normalised {d['normalised']:.3f}")
    return "\n".join(lines)
