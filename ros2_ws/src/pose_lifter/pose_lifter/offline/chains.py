"""The chains of an offline lift: the checked skeletons of a bag split per track, each lifted
through its own frame pipeline (:mod:`pose_lifter.messages.frame`), serially or on forked worker
processes, with the same outcomes.

A track's frames depend on one another (warm starts, the track's history); different tracks do
not, so each track is a chain. A chain expires its track at the stamps a pipeline lifting every
frame would (:func:`expiry_stamps`), so the outcomes are those of the node's one pipeline over the
whole bag. Chains are lifted in groups, in step, the k-th frame of each chain together whether
they were seen together or one after another (:func:`lift_chains`),
so that the prior's network runs once per step for all of them
(:func:`~pose_lifter.core.lift.batch.prior_calls`); a chain's outcomes do not depend on its group.
A long chain (one track recorded at length) is lifted as pieces that the workers share
(:func:`pieces`), each as segments in step with one another (:func:`segments`), so it too shares
each step among many rows; its outcomes are then as accurate as the one pipeline's, not the same
(each segment starts its track afresh a lead-in before its first kept frame).
What a chain gave comes back as columns (:class:`ChainLift`: its lifted skeletons as one
:class:`~pose_lifter.messages.cdr.SkeletonFrame`), from a worker as from this process.
"""

from __future__ import annotations

import bisect
import gc
import os
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from itertools import pairwise
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.smooth import smooth_fused, window_std_factor
from pose_lifter.core.depth.uncertainty import SMOOTHED_STD_FACTOR
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.results import LiftResult
from pose_lifter.core.track.later import LaterFrame, Placement, Refiner, placements
from pose_lifter.messages import convert as m
from pose_lifter.messages.cdr import SkeletonFrame
from pose_lifter.messages.checks import check_frames
from pose_lifter.messages.frame import (
    CheckedFrame,
    DepthImage,
    FramePipeline,
    FrameSettings,
    Intrinsics,
    LiftedSkeleton,
    SkeletonInput,
    SkipSkeleton,
    lift_together,
    with_frames_ahead,
)
from pose_lifter.messages.lagged import refined_skeletons
from pose_lifter.offline.depth import HELD_IMAGES, BagDepth
from pose_lifter.offline.workers import quiet_worker, stop_workers

__all__ = [
    "GROUP_CHAINS",
    "PIECE_FRAMES",
    "PIECE_MARGIN",
    "SEGMENT_FRAMES",
    "SEGMENT_LEAD",
    "CameraTimeline",
    "ChainLift",
    "ChainWork",
    "Item",
    "chain_groups",
    "expiry_stamps",
    "kept_part",
    "lift_chains",
    "lift_parallel",
    "pieces",
    "refine_chain",
    "segments",
    "split_chains",
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
    track expires at before it (:func:`expiry_stamps`)."""

    msg_index: int
    stamp_ns: int
    input: SkeletonInput
    intrinsics: Intrinsics
    expire_ns: int | None = None

    @property
    def track_id(self) -> int:
        return self.input.track_id


@dataclass(frozen=True)
class ChainLift:
    """What lifting a chain (or any list of items) gave, as columns: what a worker sends back
    (a few arrays, one pickle each, not one object tree per pose).

    Attributes
    ----------
    failures : list of str or None
        Per item, in order: why it was not lifted, or None (lifted: its row in ``lifted`` is the
        number of items lifted before it).
    lifted : SkeletonFrame
        The lifted items' rows, in order.
    results : list of LiftResult, optional
        Per row, the whole lift (None: not kept, only what the messages carry).
    """

    failures: list[str | None]
    lifted: SkeletonFrame
    results: list[LiftResult] | None = None

    @classmethod
    def of(cls, outcomes: Sequence[LiftedSkeleton | SkipSkeleton], keep_results: bool = True) -> ChainLift:
        """The columns of what the frame pipeline gave for each item, in order."""
        lifted = [x for x in outcomes if isinstance(x, LiftedSkeleton)]
        failures = [str(x) if isinstance(x, SkipSkeleton) else None for x in outcomes]
        return cls(failures, SkeletonFrame.of(lifted), [x.result for x in lifted] if keep_results else None)


def expiry_stamps(frame_stamps: Sequence[int | None], track_frames: Sequence[int]) -> list[int | None]:
    """For one track lifted apart from the others (its own
    :class:`~pose_lifter.messages.frame.FramePipeline`), the stamp to expire at before each of its
    frames, so that it is forgotten exactly when a pipeline lifting every frame would have
    forgotten it.

    Parameters
    ----------
    frame_stamps : sequence of int or None
        Every frame's stamp in order (None: a frame skipped unanswered, which expires nothing).
    track_frames : sequence of int
        Increasing indices into ``frame_stamps`` of the track's frames.

    Returns
    -------
    list of int or None
        Per track frame: the latest stamp among the frames from the track's previous frame
        (inclusive) to this one (exclusive), None for its first frame. Expiring at that stamp is
        expiring at each of them (only the track's last stamp, unchanged in between, is compared).
    """
    out: list[int | None] = []
    prev: int | None = None
    for j in track_frames:
        if prev is None:
            out.append(None)
        else:
            between = [s for s in frame_stamps[prev:j] if s is not None]
            out.append(max(between) if between else None)
        prev = j
    return out


def split_chains(keypoint_msgs: list[tuple[int, Any]], camera_infos: list[tuple[int, Any]],
                 pipeline: FramePipeline
                 ) -> tuple[list[list[Item]], list[list[Item | SkipSkeleton]], list[CheckedFrame]]:
    """Check every message (step 1 of the pipeline) and split the checked skeletons into
    independent chains: one per track id (in message order), one per untracked skeleton.
    Returns (chains, per message its items or refusals in input order, the checked frames)."""
    checked = check_frames(pipeline, [msg for _, msg in keypoint_msgs])
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
        chains.append([Item(it.msg_index, it.stamp_ns, it.input, it.intrinsics, e)
                       for it, e in zip(track, expire, strict=True)])
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


#: A track of at least twice :data:`SEGMENT_FRAMES` frames is lifted as segments of
#: about ``SEGMENT_FRAMES`` frames in step (:func:`segments`), each started ``SEGMENT_LEAD`` frames
#: early, its lead-in's outcomes discarded, so that it reaches its first kept frame as the track
#: would (docs/bench.md, "One person a frame": trial 01_06 at 120 Hz, 5133 frames in 7 segments:
#: MPJPE 49.726 -> 49.729 mm, the jitter 1.469 -> 1.466 mm/frame^2, the joins not seen in it).
SEGMENT_FRAMES: Final[int] = 720
SEGMENT_LEAD: Final[int] = 90


def _bounds(chain: list[Item], size: int) -> list[int] | None:
    """The item indices that cut ``chain`` into parts of about ``size`` items (the first 0, the
    last its length), or None: fewer than two parts' worth, or stamps that do not increase
    strictly (a replayed clock: the parts' frames are told apart by stamp)."""
    n = len(chain)
    count = n // size
    if count < 2 or any(b.stamp_ns <= a.stamp_ns for a, b in pairwise(chain)):
        return None
    return [round(i * n / count) for i in range(count + 1)]


def segments(chain: list[Item]) -> list[tuple[int, int, int]]:
    """A chain's segments (:data:`SEGMENT_FRAMES`), as ``(start, first kept, end)`` item indices:
    each lifted from ``start``, its outcomes kept from ``first kept`` to ``end``; the kept ranges
    tile the chain. One segment for a short chain, or one whose stamps do not increase strictly."""
    bounds = _bounds(chain, SEGMENT_FRAMES)
    if bounds is None:
        return [(0, 0, len(chain))]
    return [(max(0, a - SEGMENT_LEAD), a, b) for a, b in pairwise(bounds)]


#: A track of at least twice :data:`PIECE_FRAMES` frames is split into pieces of
#: about ``PIECE_FRAMES`` kept frames (:func:`pieces`), lifted and refined as chains of their own
#: (so the workers share a long track), each with ``PIECE_MARGIN`` frames more at either end that
#: are lifted and refined but dropped: its first kept frame starts warm, as a segment's, and the
#: centred smoothing and the offline update of its last kept frames see the frames after them.
PIECE_FRAMES: Final[int] = 4 * SEGMENT_FRAMES
PIECE_MARGIN: Final[int] = SEGMENT_LEAD


def pieces(chain: list[Item]) -> list[tuple[int, int, int, int]]:
    """A chain's pieces (:data:`PIECE_FRAMES`) as ``(start, first kept, end kept, end)`` item
    indices: each lifted from ``start`` to ``end``, its outcomes kept from ``first kept`` to
    ``end kept``; the kept ranges tile the chain. One piece for a short chain, or one whose stamps
    do not increase strictly. They do not depend on the workers (results identical to one)."""
    n = len(chain)
    bounds = _bounds(chain, PIECE_FRAMES)
    if bounds is None:
        return [(0, 0, n, n)]
    return [(max(0, a - PIECE_MARGIN), a, b, min(n, b + PIECE_MARGIN)) for a, b in pairwise(bounds)]


def kept_part(lifted: ChainLift, first: int, end: int) -> ChainLift:
    """What lifting a chain gave for its items ``first`` to ``end`` (a piece's kept range)."""
    rows = np.cumsum([f is None for f in lifted.failures])  # lifted rows up to each item, inclusive
    r0 = int(rows[first - 1]) if first > 0 else 0
    r1 = int(rows[end - 1]) if end > 0 else 0
    return ChainLift(lifted.failures[first:end], lifted.lifted.take(np.arange(r0, r1, dtype=np.intp)),
                     None if lifted.results is None else lifted.results[r0:r1])


def chain_groups(chains: list[list[Item]], workers: int) -> list[list[int]]:
    """The chains (indices) split into groups lifted in step (:func:`lift_chains`), one per worker
    of a pool: ``n`` groups, ``n`` the larger of ``workers`` (at most one per chain) and what
    groups of :data:`GROUP_CHAINS` chains need; the longest chain first, each chain to the group
    of fewest items that has room (the longest-processing-time rule). The workers carry equal
    work, each group as large as it can be (a round's fixed costs are shared by every person of
    the group; the 36-track bag on 2 workers, tools/bench_lift.py: 497 poses/s and 24.2 CPU s
    with 3 groups per worker of equal chain counts, 526 and 22.8 with one group per worker of
    equal items). Chains in step need not be seen together: a group's chains are lifted frame by
    frame of each chain (:func:`lift_chains`), people who follow one another in time as those
    seen together. Within a group, chains in the order of their first message; the groups
    with most items first."""
    n_groups = max(min(len(chains), workers), -(-len(chains) // GROUP_CHAINS), 1)
    groups: list[list[int]] = [[] for _ in range(n_groups)]
    items = [0] * n_groups
    for c in sorted(range(len(chains)), key=lambda c: (-len(chains[c]), chains[c][0].msg_index)):
        g = min((g for g in range(n_groups) if len(groups[g]) < GROUP_CHAINS), key=lambda g: (items[g], g))
        groups[g].append(c)
        items[g] += len(chains[c])
    groups = [sorted(g, key=lambda c: chains[c][0].msg_index) for g in groups if g]
    return sorted(groups, key=lambda g: -sum(len(chains[c]) for c in g))


def lift_chains(lifter: Lifter, chains: list[list[Item]], settings: FrameSettings, smoothing_s: float = 0.0,
                depth: BagDepth | None = None) -> list[list[LiftedSkeleton | SkipSkeleton]]:
    """Lift independent chains in step, each through its own frame pipeline (steps 2 and 3: the
    per-track policy, the placement, the expiry at the node's stamps; with ``depth``, each
    message's people placed on its depth image, :class:`~pose_lifter.offline.depth.DepthFrames`);
    with ``smoothing_s > 0``
    each chain's poses are then refined over its whole track (:func:`refine_chain`), and the
    policy's causal smoothing of noisy tracks is off (:attr:`TrackPolicy.smoothed_later`).
    Returns per chain, per item, the lifted skeleton or why not.

    With a lifter that reads ahead (``Lifter.reads_ahead``), each item carries its track's next
    frames for the offline prior (:func:`~pose_lifter.messages.frame.with_frames_ahead`). Message
    by message, the chains' items of that message are expired as their chain requires, then
    lifted together, each in its chain's pipeline (:func:`lift_together`: the prior's networks in
    one pass, the runs of alternations in one compiled pass per round). A chain's outcomes are
    those of lifting it alone: the chains share only the lifter, whose prior's poses and runs are
    bit for bit those computed alone. So the chains are in step by their own frames, the k-th
    item of each chain with the k-th of the others, whether they were seen together or one after
    another (people who come and go one at a time are lifted as a crowd). With ``depth`` the
    people of one message are placed on its image in one pass, so the chains are in step by
    message, unless each message holds one person and the images are read by number
    (:attr:`~pose_lifter.offline.depth.BagDepth.located`): then by their own frames too,
    :data:`~pose_lifter.offline.depth.HELD_IMAGES` chains at a time (a step reads no more of the
    images' chunks than the reader keeps: each chunk is decompressed once). Without ``depth``
    and with ``smoothing_s > 0`` a long chain is lifted as its :func:`segments`, each through its
    own pipeline from its lead-in, and stitched (the lead-ins' outcomes dropped; the offline update
    and the smoothing then run over the stitched chain): a segment's poses are not bit for bit the
    unsegmented chain's (a warm start keeps the reading of an ambiguous 2D it started from), but
    as accurate; ``smoothing_s`` 0 gives the node's causal poses, so it lifts every chain whole."""
    # a long chain's segments are lifted as chains of their own, in step with the others (not with
    # depth, whose path keeps the chain's own poses, nor for the node's causal poses: smoothing_s 0)
    whole = depth is not None or smoothing_s <= 0
    runs = [(c, a, k, b) for c, chain in enumerate(chains)
            for a, k, b in ([(0, 0, len(chain))] if whole else segments(chain))]
    pipelines = [FramePipeline(lifter, settings) for _ in runs]
    for p in pipelines:  # the centred smoothing replaces the causal smoothing of noisy tracks
        p.policy.smoothed_later = smoothing_s > 0
        p.follow_fused(depth is not None and smoothing_s <= 0)  # answered at once, as the node
    ahead = [with_frames_ahead([(it.stamp_ns, it.input) for it in chain], lifter.frames_ahead)
             for chain in chains]
    inputs = [ahead[c][a:b] for c, a, _, b in runs]
    done: list[list[LiftedSkeleton | SkipSkeleton]] = [[] for _ in runs]
    # the fit's own pose_camera per outcome (the centred smoothing's start)
    fitted: list[list[NDArray[np.float64] | None]] = [[] for _ in runs]
    steps: dict[tuple[int, int], list[tuple[int, int, Item]]] = {}
    # with depth, by the chains' own frames only where that places each person alone on its image
    # as by message (one person a message: the placement of the people of one image is one pass)
    # and the images can be read in any order (by number)
    by_frame = depth is None or (depth.located is not None and len(
        {it.msg_index for chain in chains for it in chain}) == sum(len(chain) for chain in chains))
    # read by frame, the chains go in step HELD_IMAGES at a time: a step then reads no more chunks
    # than the reader keeps, so each chunk is decompressed once, not again for each of its images
    block = HELD_IMAGES if depth is not None and by_frame else len(runs)
    for r, (c, a, _, b) in enumerate(runs):
        for k, item in enumerate(chains[c][a:b]):
            key = (r // block, k) if by_frame else (0, item.msg_index)
            steps.setdefault(key, []).append((r, k, item))
    images = depth.frames() if depth is not None else None
    try:
        for key in sorted(steps):
            for step in _held(steps[key]) if images is not None else [steps[key]]:
                for r, _, item in step:
                    if item.expire_ns is not None:
                        pipelines[r].end_frame(item.expire_ns)
                msgs = sorted({x.msg_index for *_, x in step}) if images is not None else []
                of_msg = {i: _own(images.image(i)) for i in msgs} if images is not None else {}
                together = lift_together([(pipelines[r], inputs[r][k], item.stamp_ns, item.intrinsics)
                                          for r, k, item in step],
                                         None if images is None else [of_msg[x.msg_index] for *_, x in step])
                for (r, _, _), lifted in zip(step, together, strict=True):
                    done[r].append(lifted)
                    # the centred smoothing starts from the fit's own pose; with the measurement update,
                    # from the published one (which has read each frame's 2D; docs/tuning.md)
                    fitted[r].append(lifted.fit_pose_camera if isinstance(lifted, LiftedSkeleton)
                                     and not lifter.options.measurement_update else None)
    finally:
        if images is not None:
            images.close()
    # each chain's outcomes: its segments' from their first kept item on
    out: list[list[LiftedSkeleton | SkipSkeleton]] = [[] for _ in chains]
    fits: list[list[NDArray[np.float64] | None]] = [[] for _ in chains]
    later: list[list[LaterFrame]] = [[] for _ in chains]
    first_run: dict[int, int] = {}
    for r, (c, a, k, _) in enumerate(runs):
        first_run.setdefault(c, r)
        out[c] += done[r][k - a:]
        fits[c] += fitted[r][k - a:]
        if smoothing_s > 0:  # the frames kept for the offline update, of the kept items only
            first = chains[c][k].stamp_ns
            later[c] += [f for frames in pipelines[r].policy.kept_later().values() for f in frames
                         if f.stamp_ns >= first]
    if smoothing_s > 0:
        return [refine_chain(chain, out[c], fits[c], later[c], pipelines[first_run[c]], smoothing_s)
                for c, chain in enumerate(chains)]
    return out


def _own(image: DepthImage) -> DepthImage:
    """A message's own array of its depth image (a view: two messages paired with one image are
    still placed each on its own, :func:`~pose_lifter.messages.frame.place_lifted`)."""
    return None if image is None else image.view()


def _held(step: list[tuple[int, int, Item]]) -> list[list[tuple[int, int, Item]]]:
    """A step's items in message order, cut into parts of at most :data:`HELD_IMAGES` messages (the
    depth images held at once)."""
    parts: list[list[tuple[int, int, Item]]] = []
    seen: set[int] = set()
    for x in sorted(step, key=lambda x: x[2].msg_index):
        if not parts or (x[2].msg_index not in seen and len(seen) == HELD_IMAGES):
            parts.append([])
            seen = set()
        parts[-1].append(x)
        seen.add(x[2].msg_index)
    return parts


def refine_chain(chain: list[Item], outcomes: list[LiftedSkeleton | SkipSkeleton],
                 fits: list[NDArray[np.float64] | None], kept: Sequence[LaterFrame], pipeline: FramePipeline,
                 smoothing_s: float) -> list[LiftedSkeleton | SkipSkeleton]:
    """A lifted chain refined over its whole track (:class:`~pose_lifter.core.track.later.Refiner`
    without a horizon, the lagged node's with one): the offline measurement update of its hybrid
    frames (``kept``: what the pipelines' policies kept of them, :attr:`TrackPolicy.smoothed_later`,
    in order; ``pipeline``: one of them, for the settings and the lifter), each
    pose placed as its frame, then a centred Gaussian window of ``smoothing_s`` seconds over the
    metric joints (segments split at gaps over ``track_timeout``). The refinement starts from the
    fit's own poses (``fits[i]``; None: from the result's pose, the fit's or, with
    ``measurement_update``, the published one): without the update the causal output smoothing
    of the live node is replaced, not compounded. Each result's ``pose_camera`` becomes the
    refined joints centred (:func:`~pose_lifter.messages.lagged.refined_skeletons`)."""
    rows = [i for i, d in enumerate(outcomes) if isinstance(d, LiftedSkeleton)]
    lifted = [d for d in outcomes if isinstance(d, LiftedSkeleton)]
    if len(rows) < 2:
        return outcomes
    settings, opts, leg = pipeline.settings, pipeline.lifter.options, pipeline.settings.lower_leg_length
    later: dict[tuple[int, int], LaterFrame] = {}  # by (stamp, k): the input clock may replay a stamp
    seen: Counter[int] = Counter()
    for f in kept:
        later[(f.stamp_ns, seen[f.stamp_ns])] = f
        seen[f.stamp_ns] += 1
    placed: list[Placement | None] = [None] * len(rows)
    by_camera: dict[Intrinsics, list[int]] = {}  # the rows seen with each camera's intrinsics
    for r, i in enumerate(rows):
        by_camera.setdefault(chain[i].intrinsics, []).append(r)
    for intrinsics, members in by_camera.items():
        for r, p in zip(members, placements([lifted[r].result for r in members], leg, intrinsics,
                                            settings.default_distance), strict=True):
            placed[r] = p
    refiner = Refiner(None, smoothing_s, settings.track_timeout, opts.measurement_depth,
                      opts.measurement_gate)
    seen.clear()
    for r, (i, s) in enumerate(zip(rows, lifted, strict=True)):
        stamp = chain[i].stamp_ns
        fit = fits[i]
        refiner.add(0, stamp, s.result.pose_camera if fit is None else fit, later.get((stamp, seen[stamp])),
                    placed[r])
        seen[stamp] += 1
    out = list(outcomes)
    again_of = refined_skeletons(lifted, refiner.poses(0), leg, [chain[i].intrinsics for i in rows],
                                 settings.default_distance)
    for i, again in zip(rows, again_of, strict=True):
        if again is not None:  # else what it was lifted with is kept
            out[i] = again
    return _smoothed_fused(chain, out, smoothing_s, settings.track_timeout)


def _smoothed_fused(chain: list[Item], outcomes: list[LiftedSkeleton | SkipSkeleton], smoothing_s: float,
                    gap_s: float) -> list[LiftedSkeleton | SkipSkeleton]:
    """The chain's skeletons placed on a depth image with their fused joints averaged over the
    centred window (:func:`~pose_lifter.core.depth.smooth.smooth_fused`: each frame's reading
    errors averaged out); the others as given."""
    placed = [(i, d, d.depth) for i, d in enumerate(outcomes)
              if isinstance(d, LiftedSkeleton) and d.depth is not None and d.std_m is not None]
    if len(placed) < 2:
        return outcomes
    rows, fused = [i for i, _, _ in placed], [d for _, d, _ in placed]
    factor = window_std_factor(np.array([s.result.weights > 0 for s in fused]),
                               np.array([np.isfinite(r.depth_m) for _, _, r in placed]),
                               SMOOTHED_STD_FACTOR)
    joints, std = smooth_fused(np.array([s.joints_m for s in fused]), np.array([s.std_m for s in fused]),
                               np.array([chain[i].stamp_ns for i in rows], dtype=np.int64),
                               np.ones(len(rows), dtype=bool), smoothing_s, gap_s, factor)
    out = list(outcomes)
    for i, s, j, sd in zip(rows, fused, joints, std, strict=True):
        out[i] = replace(s, joints_m=j, std_m=sd)
    return out


@dataclass(frozen=True)
class ChainWork:
    """What the worker processes of :func:`lift_messages` lift: handed to each worker by the pool
    initialiser (:func:`_worker_init`; inherited through fork, not pickled), so a task is only the
    index of a group of chains (:func:`chain_groups`), and only the outcomes come back (the
    parent holds the items), as columns (:class:`ChainLift`; the whole results too when
    ``keep_results``)."""

    lifter: Lifter
    settings: FrameSettings
    smoothing_s: float
    chains: list[list[Item]]
    groups: list[list[int]]
    keep_results: bool
    depth: BagDepth | None = None

    def run(self, index: int) -> list[ChainLift]:
        group = [self.chains[c] for c in self.groups[index]]
        return [ChainLift.of(outcomes, self.keep_results)
                for outcomes in lift_chains(self.lifter, group, self.settings, self.smoothing_s, self.depth)]


#: The work of this worker process (set by :func:`_worker_init`; None in the parent).
_work: ChainWork | None = None


def _worker_init(work: ChainWork, parent: int) -> None:
    """Keep the worker's work, with a worker's signals
    (:func:`~pose_lifter.offline.workers.quiet_worker`): a worker writes nothing, and a handler it
    inherited from the parent (which turns SIGTERM into an exception) would leave it alive, the
    executor's worker loop catching what a task raises."""
    global _work
    _work = work
    quiet_worker(parent)


def _worker_chain(index: int) -> list[ChainLift]:
    assert _work is not None, "called outside a worker of lift_messages"
    return _work.run(index)


def lift_parallel(work: ChainWork, workers: int, bar: Any) -> list[ChainLift]:
    """Lift ``work.groups`` of ``work.chains`` on ``workers`` forked processes: per chain, what
    lifting it gave."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    out: list[ChainLift | None] = [None] * len(work.chains)
    # never more processes than groups or cores (1000 workers for 5 tracks forked 1000)
    n_proc = min(workers, len(work.groups), os.cpu_count() or 1)
    # the workers inherit every object of this process (the bag's messages too): frozen, the
    # garbage collector of a worker does not walk them, so their pages are not copied
    gc.freeze()
    try:
        ex = ProcessPoolExecutor(n_proc, mp_context=multiprocessing.get_context("fork"),
                                 initializer=_worker_init, initargs=(work, os.getpid()))
        try:
            outcomes_of = ex.map(_worker_chain, range(len(work.groups)))
            for group, per_chain in zip(work.groups, outcomes_of, strict=True):
                for c, lifted in zip(group, per_chain, strict=True):
                    out[c] = lifted
                    bar.update(len(work.chains[c]))
        except BaseException:  # Ctrl-C or a failure: stop the workers now, not after their chains
            stop_workers(ex)
            raise
        ex.shutdown()
    finally:
        gc.unfreeze()
    return [x for x in out if x is not None]
