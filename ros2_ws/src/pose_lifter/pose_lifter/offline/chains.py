"""The chains of an offline lift: the checked skeletons of a bag split per track, each lifted
through its own frame pipeline (:mod:`pose_lifter.messages.frame`), serially or on forked worker
processes, with the same outcomes.

A track's frames depend on one another (warm starts, the track's history); different tracks do
not, so each track is a chain. A chain expires its track at the stamps a pipeline lifting every
frame would (:func:`~pose_lifter.messages.frame.expiry_stamps`), so the outcomes are those of the
node's one pipeline over the whole bag. Chains seen together are lifted in groups, in step
(:func:`lift_chains`), so that the prior's network runs once per step for all of them
(:func:`~pose_lifter.core.lift.batch.prior_calls`); a chain's outcomes do not depend on its group.
"""

from __future__ import annotations

import bisect
import gc
import os
import signal
import time
from collections import Counter
from dataclasses import dataclass, replace
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.model.skeleton import N_JOINTS
from pose_lifter.core.results import LiftResult, with_camera_poses
from pose_lifter.core.track.placement import place_poses
from pose_lifter.core.track.policy import FramesAhead
from pose_lifter.core.track.smoothing import centred_smoothing
from pose_lifter.messages import convert as m
from pose_lifter.messages.frame import (
    CheckedFrame,
    FramePipeline,
    FrameSettings,
    Intrinsics,
    LiftedSkeleton,
    SkeletonInput,
    SkipSkeleton,
    expiry_stamps,
    lift_together,
)

__all__ = [
    "GROUP_CHAINS",
    "CameraTimeline",
    "ChainWork",
    "Done",
    "Item",
    "MessageFields",
    "chain_groups",
    "inputs_ahead",
    "lift_chains",
    "lift_parallel",
    "measured_later",
    "smooth_chain",
    "split_chains",
    "stop_workers",
]


class CameraTimeline:
    """The usable intrinsics of a bag's CameraInfo messages, by stamp: a CameraInfo the node
    would ignore (bad intrinsics) is left out.

    Parameters
    ----------
    camera_infos : list of (stamp_ns, CameraInfo), time-ordered
    """

    def __init__(self, camera_infos: list[tuple[int, Any]]) -> None:
        self._stamps: list[int] = []
        self._intrinsics: list[Intrinsics] = []
        for stamp, info in camera_infos:
            try:
                intrinsics = m.intrinsics_from_camera_info(info)
            except (InvalidInputError, ValueError, TypeError):
                continue
            self._stamps.append(stamp)
            self._intrinsics.append(intrinsics)

    def at(self, stamp: int) -> Intrinsics:
        """The latest usable intrinsics at or before ``stamp`` (before the first: the first; none
        at all: None, the default distance)."""
        if not self._intrinsics:
            return None
        return self._intrinsics[max(0, bisect.bisect_right(self._stamps, stamp) - 1)]


@dataclass(frozen=True)
class Item:
    """One checked skeleton of one message, to lift: its input, the camera, and the stamp its
    track expires at before it (:func:`~pose_lifter.messages.frame.expiry_stamps`)."""

    msg_index: int
    stamp_ns: int
    input: SkeletonInput
    intrinsics: Intrinsics
    expire_ns: int | None = None

    @property
    def track_id(self) -> int:
        return self.input.track_id


@dataclass(frozen=True)
class Done:
    """What lifting one :class:`Item` gave: the result and metric joints, or the failure."""

    item: Item
    result: Any | None
    joints_m: NDArray[np.float64] | None
    warm_started: bool
    solve_time: float
    failure: str | None
    #: the left/right label groups its track swapped back (2,; None: none; ``LiftedSkeleton.swapped``)
    swapped: NDArray[np.bool_] | None = None

    @classmethod
    def of(cls, item: Item, outcome: LiftedSkeleton | SkipSkeleton) -> Done:
        """What the frame pipeline gave for ``item``: its lifted skeleton, or the refusal."""
        if isinstance(outcome, SkipSkeleton):
            return cls(item, None, None, False, 0.0, str(outcome))
        return cls(item, outcome.result, outcome.joints_m, outcome.warm_started, outcome.solve_time, None,
                   outcome.swapped)


def split_chains(keypoint_msgs: list[tuple[int, Any]], camera_infos: list[tuple[int, Any]],
                 pipeline: FramePipeline
                 ) -> tuple[list[list[Item]], list[list[Item | SkipSkeleton]], list[CheckedFrame]]:
    """Check every message (step 1 of the pipeline) and split the checked skeletons into
    independent chains: one per track id (in message order), one per untracked skeleton.
    Returns (chains, per message its items or refusals in input order, the checked frames)."""
    checked = [pipeline.check(msg) for _, msg in keypoint_msgs]
    cameras = CameraTimeline(camera_infos)
    per_track: dict[int, list[Item]] = {}
    chains: list[list[Item]] = []
    per_msg: list[list[Item | SkipSkeleton]] = []
    for i, ((stamp, _), frame) in enumerate(zip(keypoint_msgs, checked, strict=True)):
        row: list[Item | SkipSkeleton] = []
        intrinsics = cameras.at(stamp) if frame.skeletons else None
        for x in frame.skeletons:
            if isinstance(x, SkipSkeleton):
                row.append(x)
                continue
            item = Item(i, stamp, x, intrinsics)
            row.append(item)
            if x.track_id >= 0:
                per_track.setdefault(x.track_id, []).append(item)
            else:
                chains.append([item])
        per_msg.append(row)
    stamps = [s if c.answered else None for (s, _), c in zip(keypoint_msgs, checked, strict=True)]
    for track in per_track.values():
        expire = expiry_stamps(stamps, [it.msg_index for it in track])
        chains.append([replace(it, expire_ns=e) for it, e in zip(track, expire, strict=True)])
    # the items per message with their expiry (the same objects as in the chains)
    final = {(it.msg_index, id(it.input)): it for chain in chains for it in chain}
    per_msg = [[x if isinstance(x, SkipSkeleton) else final[(x.msg_index, id(x.input))] for x in row]
               for row in per_msg]
    return chains, per_msg, checked


#: Chains lifted in step by one task (:func:`chain_groups`): up to this many people's rounds
#: share one pass of the prior's network and one call of the run kernel
#: (:mod:`pose_lifter.core.lift.batch`), as the node's frame of up to ``max_skeletons`` (64) people.
#: One process, the 36-track bag (tools/bench_lift.py --workers 1): CPU 12.3 s with groups of
#: 8, 10.3 with 32, 9.7 with 64 (every track in step).
GROUP_CHAINS: Final[int] = 64


def chain_groups(chains: list[list[Item]], workers: int) -> list[list[int]]:
    """The chains (indices) split into groups lifted in step (:func:`lift_chains`), one per worker
    of a pool: in the order of their first message, a group closed when full or when the next
    chain starts after every chain of the group has ended (so a group's people are seen
    together). Full is :data:`GROUP_CHAINS` chains, or an equal share of the items (poses) among
    ``n`` groups (a chain longer than the share is a group alone), ``n`` the larger of
    ``workers`` (at most one per chain) and what groups of :data:`GROUP_CHAINS` chains need: the
    workers carry equal work, each group as large as it can be (a round's fixed costs are shared
    by every person of the group; the 36-track bag on 2 workers, tools/bench_lift.py: 497 poses/s
    and 24.2 CPU s with 3 groups per worker of equal chain counts, 526 and 22.8 with these). The
    groups with most items first."""
    order = sorted(range(len(chains)), key=lambda c: (chains[c][0].msg_index, -len(chains[c])))
    n_groups = max(min(len(chains), workers), -(-len(chains) // GROUP_CHAINS), 1)
    share = sum(len(c) for c in chains) / n_groups  # a group's items, at most (but one chain)
    groups: list[list[int]] = []
    current: list[int] = []
    items, end = 0, -1
    for c in order:
        if current and (len(current) >= GROUP_CHAINS or items + len(chains[c]) > share * (1.0 + 1e-9)
                        or chains[c][0].msg_index > end):
            groups.append(current)
            current, items, end = [], 0, -1
        current.append(c)
        items += len(chains[c])
        end = max(end, chains[c][-1].msg_index)
    if current:
        groups.append(current)
    return sorted(groups, key=lambda g: -sum(len(chains[c]) for c in g))


def lift_chains(lifter: Lifter, chains: list[list[Item]], settings: FrameSettings, smoothing_s: float = 0.0
                ) -> list[list[Done]]:
    """Lift independent chains in step, each through its own frame pipeline (steps 2 and 3: the
    per-track policy, the placement, the expiry at the node's stamps); with ``smoothing_s > 0``
    each chain's poses are then smoothed centred (:func:`smooth_chain`), and the policy's causal
    smoothing of noisy tracks is off (:attr:`TrackPolicy.smoothed_later`).

    With a lifter that reads ahead (``Lifter.reads_ahead``), each item carries its track's next
    frames for the offline prior (:func:`inputs_ahead`). Message by message, the chains' items of
    that message are expired as their chain requires, then lifted together, each in its chain's
    pipeline (:func:`lift_together`: the prior's networks in one pass, the runs of alternations in
    one compiled pass per round). A chain's
    outcomes are those of lifting it alone: the chains share only the lifter, whose prior's poses
    and runs are bit for bit those computed alone."""
    pipelines = [FramePipeline(lifter, settings) for _ in chains]
    for p in pipelines:  # the centred smoothing replaces the causal smoothing of noisy tracks
        p.policy.smoothed_later = smoothing_s > 0
    inputs = [inputs_ahead(lifter, chain) for chain in chains]
    out: list[list[Done]] = [[] for _ in chains]
    # the fit's own pose_camera per outcome (the centred smoothing's start)
    fits: list[list[NDArray[np.float64] | None]] = [[] for _ in chains]
    steps: dict[int, list[tuple[int, int, Item]]] = {}
    for c, chain in enumerate(chains):
        for k, item in enumerate(chain):
            steps.setdefault(item.msg_index, []).append((c, k, item))
    for msg_index in sorted(steps):
        step = steps[msg_index]
        for c, _, item in step:
            if item.expire_ns is not None:
                pipelines[c].end_frame(item.expire_ns)
        together = lift_together(lifter, [(pipelines[c], inputs[c][k], item.stamp_ns, item.intrinsics)
                                          for c, k, item in step])
        for (c, _, item), lifted in zip(step, together, strict=True):
            out[c].append(Done.of(item, lifted))
            if not isinstance(lifted, LiftedSkeleton):
                fits[c].append(None)
                continue
            # the centred smoothing starts from the fit's own pose; with the measurement update,
            # from the published one (which has read each frame's 2D; docs/tuning.md)
            fits[c].append(None if lifter.options.measurement_update else lifted.fit_pose_camera)
    if smoothing_s > 0:
        out = [measured_later(d, p) for d, p in zip(out, pipelines, strict=True)]
        return [smooth_chain(d, f, settings, smoothing_s) for d, f in zip(out, fits, strict=True)]
    return out


def measured_later(done: list[Done], pipeline: FramePipeline) -> list[Done]:
    """A lifted chain with the offline measurement update of its hybrid frames
    (:meth:`pose_lifter.core.track.policy.TrackPolicy.measured_later`: each track's 2D smoothed over
    past and future frames, then the update at every noise level): each updated result's
    ``pose_camera`` becomes the updated pose (its metric joints are placed again by
    :func:`smooth_chain`)."""
    updated = pipeline.policy.measured_later()
    if not updated:
        return done
    rows: list[int] = []
    results: list[LiftResult] = []
    poses: list[NDArray[np.float64]] = []
    seen: Counter[tuple[int, int]] = Counter()  # a stamp the input clock replayed comes again
    for i, d in enumerate(done):
        if d.result is None:
            continue
        key = (d.item.track_id, d.item.stamp_ns)
        pose = updated.get((*key, seen[key]))
        seen[key] += 1
        if pose is not None:
            rows.append(i)
            results.append(d.result)
            poses.append(pose)
    if not rows:
        return done
    out = list(done)
    for i, res in zip(rows, with_camera_poses(results, np.array(poses)), strict=True):
        out[i] = replace(done[i], result=res)
    return out


def inputs_ahead(lifter: Lifter, chain: list[Item]) -> list[SkeletonInput]:
    """The inputs of ``chain``'s items, each with its track's next frames
    (``SkeletonInput.ahead``: the prior's ``future_frames`` items after it) when ``lifter`` reads
    ahead and its temporal prior reads frames after the one it lifts."""
    n_ahead = lifter.frames_ahead
    if not n_ahead or len(chain) < 2:
        return [it.input for it in chain]
    stamps = np.array([it.stamp_ns for it in chain], dtype=np.int64)
    points = np.array([it.input.points for it in chain], dtype=np.float64)
    confidence = np.array([it.input.confidence for it in chain], dtype=np.float64)
    return [replace(it.input, ahead=FramesAhead(stamps[i + 1:i + 1 + n_ahead], points[i + 1:i + 1 + n_ahead],
                                                confidence[i + 1:i + 1 + n_ahead]))
            for i, it in enumerate(chain)]


def smooth_chain(done: list[Done], fits: list[NDArray[np.float64] | None], settings: FrameSettings,
                  smoothing_s: float) -> list[Done]:
    """A lifted chain with its metric joints smoothed by a centred Gaussian window of
    ``smoothing_s`` seconds (:func:`pose_lifter.core.track.smoothing.centred_smoothing`, segments split at
    gaps over ``track_timeout``), from the fit's own poses (``fits[i]``; None: from the result's
    pose, the fit's or, with ``measurement_update``, the published one): without the update the
    causal output smoothing of the live node is replaced, not compounded. Each result's ``pose``
    and ``pose_camera`` become the smoothed pose (camera and the rest kept)."""
    rows = [i for i, d in enumerate(done) if d.result is not None and d.joints_m is not None]
    if len(rows) < 2:
        return done
    leg = settings.lower_leg_length
    placed = np.empty((len(rows), N_JOINTS, 3))
    by_camera: dict[Intrinsics, list[int]] = {}  # the rows seen with each camera's intrinsics
    for r, i in enumerate(rows):
        by_camera.setdefault(done[i].item.intrinsics, []).append(r)
    for intrinsics, members in by_camera.items():
        poses = np.empty((len(members), N_JOINTS, 3))
        scales, translations = np.empty(len(members)), np.empty((len(members), 2))
        for j, r in enumerate(members):
            res, fit = done[rows[r]].result, fits[rows[r]]
            assert res is not None
            poses[j] = res.pose_camera if fit is None else fit
            scales[j], translations[j] = float(res.camera.scale), res.camera.translation
        focal, centre = intrinsics if intrinsics is not None else (None, None)
        placed[members] = place_poses(poses, scales, translations, leg, focal, centre,
                                      settings.default_distance)
    stamps = np.array([done[i].item.stamp_ns for i in rows], dtype=np.int64)
    smooth = centred_smoothing(placed, stamps, np.ones(len(rows), dtype=bool), smoothing_s,
                               settings.track_timeout)
    out = list(done)
    for r, i in enumerate(rows):
        d = done[i]
        assert d.result is not None
        res = d.result.with_camera_pose((smooth[r] - smooth[r].mean(axis=0)) / leg)
        out[i] = Done(d.item, res, smooth[r], d.warm_started, d.solve_time, None, d.swapped)
    return out


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


def _columns(done: list[Done]) -> tuple[list[tuple[bool, float, str | None, int]],
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
        "swapped": np.array([np.zeros(2, dtype=bool) if d.swapped is None else d.swapped for d in ok],
                            dtype=bool).reshape(-1, 2),
    }
    return items, cols


def _from_columns(chain: list[Item], items: list[tuple[bool, float, str | None, int]],
                  cols: dict[str, NDArray[Any]]) -> list[Done]:
    """The :class:`Done` s of a chain from :func:`_columns` (results as :class:`MessageFields`)."""
    from pose_lifter.core.results import Camera

    out = []
    for item, (warm, dt, failure, i) in zip(chain, items, strict=True):
        if i < 0:
            out.append(Done(item, None, None, warm, dt, failure))
            continue
        cam = Camera(cols["rotation"][i], float(cols["scale"][i]), cols["translation"][i])
        fields = MessageFields(cam, float(cols["objective"][i]), float(cols["reprojection_error"][i]),
                               int(cols["total_alternations"][i]), bool(cols["converged"][i]),
                               cols["weights"][i])
        swapped = cols["swapped"][i]
        out.append(Done(item, fields, cols["joints_m"][i], warm, dt, None,
                        swapped if swapped.any() else None))
    return out


@dataclass(frozen=True)
class ChainWork:
    """What the worker processes of :func:`lift_messages` lift: handed to each worker by the pool
    initialiser (:func:`_worker_init`; inherited through fork, not pickled), so a task is only the
    index of a group of chains (:func:`chain_groups`), and only the outcomes come back (the
    parent holds the items): whole results, or only their message fields as columns
    (:func:`_columns`)."""

    lifter: Lifter
    settings: FrameSettings
    smoothing_s: float
    chains: list[list[Item]]
    groups: list[list[int]]
    message_fields_only: bool

    def run(self, index: int) -> list[Any]:
        group = [self.chains[c] for c in self.groups[index]]
        out: list[Any] = []
        for done in lift_chains(self.lifter, group, self.settings, self.smoothing_s):
            if self.message_fields_only:
                out.append(_columns(done))
            else:
                out.append([(d.result, d.joints_m, d.warm_started, d.solve_time, d.failure, d.swapped)
                            for d in done])
        return out


#: The work of this worker process (set by :func:`_worker_init`; None in the parent).
_work: ChainWork | None = None


def _worker_init(work: ChainWork) -> None:
    """Keep the worker's work; Ctrl-C ends a worker silently (the parent reports it once), not
    with a traceback each, and SIGTERM (:func:`stop_workers`) ends it at once: a worker writes
    nothing, and a handler it inherited from the parent (which may turn SIGTERM into an
    exception) would leave it alive, the executor's worker loop catching what a task raises."""
    global _work
    _work = work
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _worker_chain(index: int) -> Any:
    assert _work is not None, "called outside a worker of lift_messages"
    return _work.run(index)


#: Seconds a worker has to exit after SIGTERM (a collection's worker discards the bag it was
#: writing first) before :func:`stop_workers` kills it.
STOP_TIMEOUT: Final[float] = 10.0


def stop_workers(ex: Any) -> None:
    """Stop a ProcessPoolExecutor (forked workers) now: its queued work dropped, each worker sent
    SIGTERM and killed if it has not exited within STOP_TIMEOUT; on return every worker has been
    reaped.

    The executor is not shut down with ``wait=True``: a worker whose task turned SIGTERM into an
    exception is kept alive by the executor's worker loop, which returns that exception as the
    task's result and waits for the next task, so that could wait forever. Its manager thread,
    which reaps the workers of a broken pool itself, is joined once they are gone and before they
    are joined here: two threads waiting for the same child race (the loser's wait finds no child
    and leaves the process marked alive).
    """
    import multiprocessing.connection

    processes = list((getattr(ex, "_processes", None) or {}).values())  # no public accessor
    manager = getattr(ex, "_executor_manager_thread", None)  # (shutdown forgets both)
    ex.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        proc.terminate()
    deadline = time.monotonic() + STOP_TIMEOUT
    running = {proc.sentinel: proc for proc in processes}  # ready once its process has exited
    while running and (left := deadline - time.monotonic()) > 0:
        for sentinel in multiprocessing.connection.wait(list(running), left):
            del running[sentinel]
    for proc in running.values():
        proc.kill()
    if manager is not None:
        manager.join(STOP_TIMEOUT)
    for proc in processes:
        proc.join()


def lift_parallel(work: ChainWork, workers: int, done: dict[int, Done], bar: Any) -> None:
    """Lift ``work.groups`` of ``work.chains`` on ``workers`` forked processes into ``done``
    (id(item) -> outcome)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # never more processes than groups or cores (1000 workers for 5 tracks forked 1000)
    n_proc = min(workers, len(work.groups), os.cpu_count() or 1)
    # the workers inherit every object of this process (the bag's messages too): frozen, the
    # garbage collector of a worker does not walk them, so their pages are not copied
    gc.freeze()
    try:
        ex = ProcessPoolExecutor(n_proc, mp_context=multiprocessing.get_context("fork"),
                                 initializer=_worker_init, initargs=(work,))
        try:
            outcomes_of = ex.map(_worker_chain, range(len(work.groups)))
            for group, per_chain in zip(work.groups, outcomes_of, strict=True):
                for c, outcomes in zip(group, per_chain, strict=True):
                    chain = work.chains[c]
                    if work.message_fields_only:
                        for d in _from_columns(chain, *outcomes):
                            done[id(d.item)] = d
                        bar.update(len(chain))
                        continue
                    for item, (res, joints, warm, dt, failure, swapped) in zip(chain, outcomes, strict=True):
                        done[id(item)] = Done(item, res, joints, warm, dt, failure, swapped)
                        bar.update(1)
        except BaseException:  # Ctrl-C or a failure: stop the workers now, not after their chains
            stop_workers(ex)
            raise
        ex.shutdown()
    finally:
        gc.unfreeze()
