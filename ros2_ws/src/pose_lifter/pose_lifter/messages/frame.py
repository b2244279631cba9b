"""The per-skeleton pipeline, once: checks -> per-track policy -> metric placement.

The node (:mod:`pose_lifter.ros.node`) and the offline lift (:mod:`pose_lifter.offline.lift`)
lift a ``Skeleton2DArray`` through this module and nothing else, so a bag lifted offline is
what the node publishes for it. One frame:

1. :meth:`FramePipeline.check` (stateless): a frame whose ``header.frame_id`` or ``layout``
   is over its cap is skipped unanswered (:attr:`CheckedFrame.answered` False: no output, no
   expiry); an unknown layout skips the whole frame (answered, empty); of a crowd of more than
   ``max_skeletons`` liftable skeletons only the ``max_skeletons`` largest in the image are
   lifted (:func:`largest_first`), the others skipped; each skeleton is checked against the
   caps before its keypoints are read (:func:`admitted_track`: keypoint count, duplicate track
   id), read into the paper's joints with the layout looked up once for the frame
   (:func:`~pose_lifter.messages.layouts.frame_joints`: malformed keypoints refused), then
   checked as joints (:func:`skeleton_input`: confidences clipped into [0, 1], no confident
   keypoint, absurd coordinates).
2. :func:`lift_together` (the skeletons together, each through its pipeline's track policy,
   :func:`~pose_lifter.core.track.policy.lift_tracks`): the core's
   :class:`~pose_lifter.core.track.policy.TrackPolicy` (warm starts, re-initialisation,
   out-of-order stamps refused), then :func:`place_lifted` (the people seen by one camera
   placed together, :func:`~pose_lifter.core.track.placement.place_results`; with the frame's
   depth image, fused with it, :func:`pose_lifter.core.depth.fuse_depth`) and :func:`check_output`
   (nothing non-finite leaves).
3. :meth:`FramePipeline.end_frame`: tracks unseen for ``track_timeout`` are forgotten.

Every refusal is a :class:`SkipSkeleton` with a short kind (the node counts and warns them; the
offline lift counts them as failures). No rclpy, no file I/O: messages are read by attribute
name (rclpy and rosbags classes alike). :meth:`FramePipeline.frame` runs the three steps on one
frame; the offline lift runs step 1 for the whole bag and step 2 per track, in parallel, with
step 3 per track at the same stamps (see :func:`expiry_stamps`): the outputs are the same.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.fuse import DepthReadings
from pose_lifter.core.depth.track_filter import TrackFilter
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.results import LiftResult, LiftStatus
from pose_lifter.core.track.policy import (
    FramesAhead,
    OutOfOrderFrameError,
    TrackedLift,
    TrackFrame,
    TrackOutcome,
    TrackPolicy,
    lift_tracks,
)
from pose_lifter.core.track.state import swap_back
from pose_lifter.messages.layouts import frame_joints
from pose_lifter.messages.settings import FrameSettings

__all__ = [
    "CheckedFrame",
    "DepthImage",
    "FramePipeline",
    "FrameSettings",
    "Intrinsics",
    "LiftedSkeleton",
    "SkeletonInput",
    "SkipSkeleton",
    "admitted_track",
    "check_output",
    "frame_over_cap",
    "lift_together",
    "place_lifted",
    "place_skeletons",
    "skeleton_input",
    "with_frames_ahead",
]

#: Camera intrinsics ((fx, fy), (cx, cy)) in pixels, or None (the default distance).
Intrinsics = tuple[tuple[float, float], tuple[float, float]] | None
#: A frame's depth image (:mod:`pose_lifter.messages.depth`): float32 (H, W) metres along the
#: optical axis, NaN where there is no reading, or uint16 millimetres, 0 where there is none
#: (:data:`~pose_lifter.core.depth.reading.DepthArray`); None: no depth (the monocular placement).
DepthImage = NDArray[np.float32] | NDArray[np.uint16] | None

_NO_CLIP: Final[Callable[[str], Any]] = lambda text: None  # noqa: E731
_DEFAULTS: Final[FrameSettings] = FrameSettings()


class SkipSkeleton(Exception):
    """A skeleton (or a whole frame) is left out of the answer.

    Parameters
    ----------
    kind : str
        Short category, counted in the node's statistics line (e.g. ``"duplicate track id"``).
    text : str
        Why (input-derived text: logged cut, see :mod:`pose_lifter.ros.checks`).
    track_id : int, optional
        The skeleton's track id (None for a whole frame).
    """

    def __init__(self, kind: str, text: str, track_id: int | None = None) -> None:
        super().__init__(text)
        self.kind = kind
        self.track_id = track_id


@dataclass(frozen=True)
class SkeletonInput:
    """One skeleton, checked and ready to lift.

    Attributes
    ----------
    track_id : int
    points : ndarray, shape (12, 2)
        Pixels (missing joints 0).
    confidence : ndarray, shape (12,)
        Clipped into [0, 1].
    ahead : FramesAhead, optional
        The track's next frames, when the lift knows them (an offline lift whose temporal prior
        reads them; :func:`pose_lifter.core.track.policy.lift_tracks`).
    """

    track_id: int
    points: NDArray[np.float64]
    confidence: NDArray[np.float64]
    ahead: FramesAhead | None = None


@dataclass(frozen=True)
class LiftedSkeleton:
    """One lifted skeleton: the lift, its metric joints and how it was solved.

    Attributes
    ----------
    input : SkeletonInput
    result : LiftResult
        In model units (``pose_camera`` in the camera frame, centred).
    joints_m : ndarray, shape (12, 3)
        Metres, camera optical frame (finite).
    warm_started : bool
    solve_time : float
        Seconds of the policy's solve.
    fit_pose_camera : ndarray, shape (12, 3), optional
        The fit's own ``pose_camera`` when the track's output smoothing replaced the result's
        (:class:`~pose_lifter.core.track.policy.TrackedLift`), else None.
    swapped : ndarray of bool, shape (2,), optional
        The arms' and the legs' left/right labels its track swapped back on this frame
        (:class:`~pose_lifter.core.track.policy.TrackedLift`; None: none).
    std_m : ndarray, shape (12, 3), optional
        Each joint's standard deviation along x, y, z of the camera frame, metres (finite,
        non-negative; published as ``Skeleton3D.joint_std``:
        :func:`~pose_lifter.core.depth.place.place_people`'s); None: unknown (published empty).
    depth : DepthReadings, optional
        The depth readings of its joints ((12,) arrays) when it was placed on a depth image: a
        pose refined over later frames is placed again with them (:mod:`pose_lifter.messages.lagged`).
    """

    input: SkeletonInput
    result: LiftResult
    joints_m: NDArray[np.float64]
    warm_started: bool
    solve_time: float
    fit_pose_camera: NDArray[np.float64] | None = None
    swapped: NDArray[np.bool_] | None = None
    std_m: NDArray[np.float64] | None = None
    depth: DepthReadings | None = None

    @property
    def track_id(self) -> int:
        return self.input.track_id

    def labelled_2d(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The input's 2D (12, 2) and confidence (12,) with the left/right labels its track gave
        them (:func:`labelled_2d`): what the lift read, labelled as the 3D joints are."""
        return labelled_2d(self.input.points, self.input.confidence, self.swapped)

    def timed(self, solve_time: float) -> LiftedSkeleton:
        """This skeleton with ``solve_time`` (seconds)."""
        return replace(self, solve_time=solve_time)


def labelled_2d(points: NDArray[np.float64], confidence: NDArray[np.float64],
                swapped: NDArray[np.bool_] | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A skeleton's 2D (12, 2) and confidence (12,) with the arms' and the legs' left/right labels
    exchanged where its track swapped them back (``swapped`` (2,); None: as given): the labels of
    its lifted 3D joints, for the outputs that carry the 2D too (REP-155 ``skeleton2d``)."""
    if swapped is None or not np.any(swapped):
        return points, confidence
    return swap_back(points, swapped), swap_back(confidence, swapped)


@dataclass(frozen=True)
class CheckedFrame:
    """One frame after :meth:`FramePipeline.check`.

    Attributes
    ----------
    answered : bool
        False: the frame is over a cap and skipped unanswered (no output, no expiry).
    skeletons : tuple of SkeletonInput or SkipSkeleton
        Per input skeleton, in order: ready to lift, or why not (without those a crowd cap left out).
    skipped : tuple of SkipSkeleton
        Refusals of the frame itself (over a cap, unknown layout, too many skeletons).
    n_left_out : int
        Skeletons of the frame not in ``skeletons`` (unknown layout, left out by ``max_skeletons``).
    """

    answered: bool
    skeletons: tuple[SkeletonInput | SkipSkeleton, ...] = ()
    skipped: tuple[SkipSkeleton, ...] = ()
    n_left_out: int = 0


#: A frame with more than ``max_skeletons`` skeletons: at most this many times ``max_skeletons``
#: of them are read and ranked (:func:`largest_first`); the rest are left out unread.
CROWD_SCAN: Final[int] = 4


def largest_first(inputs: Sequence[SkeletonInput], confidence_threshold: float) -> NDArray[np.intp]:
    """Indices of ``inputs`` from the largest person in the image to the smallest: the diagonal of
    the box of the joints at or above ``confidence_threshold`` (pixels), ties broken by their mean
    confidence, then by the order in the frame (a stable sort). The nearest people, whose 2D is
    the most precise, are the ones a crowd cap keeps."""
    size = np.zeros(len(inputs))
    conf = np.zeros(len(inputs))
    for i, x in enumerate(inputs):
        vis = x.confidence >= confidence_threshold
        pts = x.points[vis]
        size[i] = float(np.hypot(*(pts.max(axis=0) - pts.min(axis=0))))
        conf[i] = float(x.confidence[vis].mean())
    return np.lexsort((-conf, -size))


def frame_over_cap(msg: Any, settings: FrameSettings) -> SkipSkeleton | None:
    """The refusal of a frame whose strings would be copied into outputs or logs beyond the caps
    (the frame is then skipped, unanswered); None when it is within them."""
    n_frame, n_layout = len(msg.header.frame_id), len(msg.layout)
    if n_frame > settings.max_frame_id_length:
        return SkipSkeleton("frame_id too long", f"frame skipped, unanswered: header.frame_id of {n_frame} "
                            f"characters, more than max_frame_id_length={settings.max_frame_id_length}")
    if n_layout > settings.max_layout_length:
        return SkipSkeleton("layout too long", f"frame skipped, unanswered: layout name of {n_layout} "
                            f"characters, more than max_layout_length={settings.max_layout_length}")
    return None


def admitted_track(skel: Any, settings: FrameSettings, seen: set[int]) -> int:
    """The track id of one ``Skeleton2D`` of a frame, before its keypoints are read, or
    :class:`SkipSkeleton`: more keypoints than ``max_keypoints``, or a track id already in
    ``seen`` (this frame's; the skeleton's id is added; untracked skeletons, -1, may repeat)."""
    track_id = int(skel.track_id)
    xyc = getattr(skel, "xyc", None)  # a decoded bag message: the keypoints as one array
    n_keypoints = len(xyc) if xyc is not None else len(skel.keypoints)
    if n_keypoints > settings.max_keypoints:
        raise SkipSkeleton("too many keypoints", f"track {track_id}: {n_keypoints} keypoints, "
                           f"more than max_keypoints={settings.max_keypoints}", track_id)
    if track_id >= 0:
        if track_id in seen:
            raise SkipSkeleton("duplicate track id",
                               f"duplicate track id {track_id} in one frame: later copy skipped", track_id)
        seen.add(track_id)
    return track_id


def skeleton_input(track_id: int, points: NDArray[np.float64], confidence: NDArray[np.float64],
                   settings: FrameSettings, confidence_threshold: float,
                   on_clipped: Callable[[str], Any] = _NO_CLIP) -> SkeletonInput:
    """One skeleton's paper joints (``points`` (12, 2) pixels, ``confidence`` (12,), as
    :func:`~pose_lifter.messages.layouts.frame_joints` reads them) checked, or :class:`SkipSkeleton`.

    Refused: no keypoint at or above ``confidence_threshold``, visible keypoints beyond
    ``max_coordinate`` pixels. Confidences outside [0, 1] are clipped into it and
    ``on_clipped(warning)`` is called (before the checks that follow may skip the skeleton).
    """
    outside = (confidence < 0.0) | (confidence > 1.0)
    if outside.any():  # they weigh the solve: clipped into [0, 1], with a warning
        worst = float(confidence[outside][np.argmax(np.abs(confidence[outside]))])
        on_clipped(f"track {track_id}: {int(outside.sum())} confidences outside [0, 1] "
                   f"(e.g. {worst:.3g}) clipped into it")
        confidence = np.clip(confidence, 0.0, 1.0)
    visible = confidence >= confidence_threshold
    if not visible.any():
        raise SkipSkeleton("no confident keypoints",
                           f"track {track_id}: no keypoint above the confidence threshold", track_id)
    limit = settings.max_coordinate
    if np.abs(points[visible]).max() > limit:
        raise SkipSkeleton("absurd coordinates",
                           f"track {track_id}: keypoints beyond {limit:g} px (max_coordinate)", track_id)
    return SkeletonInput(track_id, points, confidence)


def check_output(track_id: int, result: LiftResult, joints_m: NDArray[np.float64]) -> None:
    """The one check of what leaves the pipeline: the metric joints and the lift's camera,
    objective and reprojection error must be finite, else :class:`SkipSkeleton`."""
    cam = result.camera
    finite = (math.isfinite(float(cam.scale)) and math.isfinite(float(result.objective))
              and math.isfinite(float(result.reprojection_error))
              and all(np.isfinite(np.asarray(a, dtype=np.float64)).all()
                      for a in (joints_m, cam.rotation, cam.translation)))
    if not finite:
        raise SkipSkeleton("non-finite result", f"track {track_id}: the solve returned non-finite values",
                           track_id)


def _track_id_of(skel: Any) -> int | None:
    """A skeleton's track id, or None where it is not an integer (a malformed message)."""
    try:
        return int(skel.track_id)
    except Exception:
        return None


def _refusal(err: Exception, track_id: int | None) -> SkipSkeleton:
    """``err`` as a :class:`SkipSkeleton`: the core's errors by their type name, anything else
    as ``"unexpected"`` (a bug must not cost the other skeletons of a frame)."""
    if isinstance(err, SkipSkeleton):
        return err
    if isinstance(err, OutOfOrderFrameError):
        return SkipSkeleton("out-of-order stamp", str(err), track_id)
    if isinstance(err, PoseLifterError):
        return SkipSkeleton(type(err).__name__, str(err), track_id)
    return SkipSkeleton("unexpected", f"unexpected error: {err!r}", track_id)


#: The refusal's kind (:attr:`SkipSkeleton.kind`) of each way a lift ends without a result: the
#: name of the error the core raises for it alone, as :func:`_refusal` names it.
_KIND_OF_STATUS: Final[dict[LiftStatus, str]] = {
    LiftStatus.INVALID_INPUT: "InvalidInputError",
    LiftStatus.TOO_FEW_JOINTS: "TooFewJointsError",
    LiftStatus.DIVERGED: "SolverError",
    LiftStatus.OUT_OF_ORDER: "out-of-order stamp",
    LiftStatus.FAILED: "unexpected",
}


def _outcome_refusal(outcome: TrackOutcome, track_id: int) -> SkipSkeleton:
    """A track's frame lifted without a result as a :class:`SkipSkeleton`: its status's kind and
    its reason (a bug, ``FAILED``, as ``"unexpected"``)."""
    text = f"unexpected error: {outcome.reason}" if outcome.status == LiftStatus.FAILED else outcome.reason
    return SkipSkeleton(_KIND_OF_STATUS[outcome.status], text, track_id)


def lift_together(frames: Sequence[tuple[FramePipeline, SkeletonInput, int, Intrinsics]],
                  depths: Sequence[DepthImage] | None = None) -> list[LiftedSkeleton | SkipSkeleton]:
    """Step 2 for several people at once, ``(pipeline, skeleton, stamp, intrinsics)`` each (their
    pipelines may share a lifter) and, with ``depths``, each one's frame's depth image (None:
    none): their frames through their tracks' policies
    (:func:`~pose_lifter.core.track.policy.lift_tracks`: the rows handed to the lifter as one batch,
    and once more for the frames it re-initialises; each stage of the lift one compiled pass over
    the batch); then the people seen by one camera placed in one pass
    (:func:`place_lifted`). Each person gets what they get lifted alone (their track is theirs;
    the kernel solves each run on its own operands, the network's rows do not mix). Their
    ``solve_time`` is the whole lift's time divided among them."""
    if not frames:
        return []
    start = time.perf_counter()
    done = lift_tracks([
        TrackFrame(pipeline.policy, inp.track_id, stamp, inp.points, inp.confidence, intrinsics, inp.ahead)
        for pipeline, inp, stamp, intrinsics in frames])
    out: list[LiftedSkeleton | SkipSkeleton | None] = []
    solved: list[tuple[int, FramePipeline, Intrinsics, SkeletonInput, TrackedLift]] = []
    for k, ((pipeline, inp, _, intrinsics), d) in enumerate(zip(frames, done, strict=True)):
        if d.result is None:  # a refusal, or anything else (a bug) costs only its skeleton
            out.append(_outcome_refusal(d, inp.track_id))
        else:
            out.append(None)  # placed below
            solved.append((k, pipeline, intrinsics, inp, d.result))
    placed = place_lifted([(p.settings, i, x, d) for _, p, i, x, d in solved],
                          None if depths is None else [depths[k] for k, *_ in solved])
    followed = [lifted if p.track_filter is None else _followed(p.track_filter, frames[k][2], lifted)
                for (k, p, *_), lifted in zip(solved, placed, strict=True)]
    share = (time.perf_counter() - start) / len(frames)
    for (k, *_), lifted in zip(solved, followed, strict=True):
        out[k] = lifted if isinstance(lifted, SkipSkeleton) else lifted.timed(share)
    return [x for x in out if x is not None]


def _followed(track_filter: TrackFilter, stamp_ns: int, lifted: LiftedSkeleton | SkipSkeleton
              ) -> LiftedSkeleton | SkipSkeleton:
    """A tracked skeleton placed on a depth image with its fused joints moved by its track's filter
    (:meth:`FramePipeline.follow_fused`); anything else as given."""
    if (isinstance(lifted, LiftedSkeleton) and lifted.depth is not None and lifted.std_m is not None
            and lifted.input.track_id >= 0):
        return replace(lifted, joints_m=track_filter.update(lifted.input.track_id, stamp_ns, lifted.joints_m,
                                                            lifted.std_m))
    return lifted


def place_lifted(solved: Sequence[tuple[FrameSettings, Intrinsics, SkeletonInput, TrackedLift]],
                 depths: Sequence[DepthImage] | None = None) -> list[LiftedSkeleton | SkipSkeleton]:
    """The lifted skeletons of skeletons through their tracks' policies, each with its pipeline's
    settings and its camera's intrinsics (and, in ``depths``, its frame's depth image or None):
    those that share them placed in one :func:`~pose_lifter.core.depth.place.place_people` pass
    (with a depth image and intrinsics, fused with it; each joint with its standard deviation),
    then :func:`check_output` per skeleton. A group the pass refuses (a camera scale not > 0, or
    anything unexpected) is placed skeleton by skeleton, so a refusal costs only its own skeleton;
    a group whose fusion fails (or gives a skeleton no valid output) is placed without depth."""
    out: list[LiftedSkeleton | SkipSkeleton | None] = [None] * len(solved)
    groups: dict[tuple[float, float, Intrinsics, int], list[int]] = {}
    images: dict[int, NDArray[np.float32] | NDArray[np.uint16]] = {}
    for k, (st, intrinsics, _, _) in enumerate(solved):
        depth = depths[k] if depths is not None else None
        key = id(depth) if depth is not None and intrinsics is not None else 0
        if key:
            images[key] = depth  # type: ignore[assignment]  # not None where key is set
        groups.setdefault((st.lower_leg_length, st.default_distance, intrinsics, key), []).append(k)
    for (leg, distance, intrinsics, key), members in groups.items():
        people = [(solved[k][2], solved[k][3]) for k in members]
        points = np.array([labelled_2d(inp.points, inp.confidence, t.swapped)[0] for inp, t in people])
        results = [t.result for _, t in people]
        try:
            placed: list[_Place] | None = place_skeletons(points, results, leg, distance, intrinsics,
                                                           images.get(key))
        except Exception:  # placed one by one below, where a refusal costs only its own skeleton
            placed = None
        for m, k in enumerate(members):
            inp, tracked = people[m]
            try:
                joints, std, readings = (placed[m] if placed is not None else place_skeletons(
                    points[m:m + 1], results[m:m + 1], leg, distance, intrinsics, None)[0])
                check_output(inp.track_id, tracked.result, joints)
            except Exception as err:
                out[k] = _refusal(err, inp.track_id)
                continue
            out[k] = LiftedSkeleton(inp, tracked.result, joints, tracked.warm_started, 0.0,
                                    tracked.fit_pose_camera, tracked.swapped, std, readings)
    return [x for x in out if x is not None]


_Place = tuple[NDArray[np.float64], NDArray[np.float64], DepthReadings | None]


def place_skeletons(points: NDArray[np.float64], results: Sequence[LiftResult], leg: float, distance: float,
                    intrinsics: Intrinsics, depth: DepthImage, poses: NDArray[np.float64] | None = None,
                    readings: Sequence[DepthReadings | None] | None = None) -> list[_Place]:
    """Per person ``(joints (12, 3), std (12, 3), readings or None)`` of
    :func:`~pose_lifter.core.depth.place.place_people` for ``n`` people of one camera (their 2D
    ``points`` (n, 12, 2) with the labels their tracks gave the 3D joints, :func:`labelled_2d`;
    ``poses`` default the results'), with the frame's ``depth`` or each person's earlier
    ``readings`` (all or none); with depth, a person whose fused joints are not finite (or a fusion
    that fails) is placed without. Raises as the monocular placement."""
    from pose_lifter.core.depth.place import place_people  # numpy work: loaded with the first lift

    people = range(len(results))
    got = [r for r in readings or () if r is not None]
    stacked = (DepthReadings(np.array([r.depth_m for r in got]), np.array([r.var for r in got]))
               if got and len(got) == len(people) else None)
    mono = place_people(results, points, intrinsics, leg, distance, poses=poses)
    out: list[_Place] = [(mono.joints_m[m], mono.std_m[m], None) for m in range(len(people))]
    if intrinsics is None or (depth is None and stacked is None):
        return out
    try:
        fused = place_people(results, points, intrinsics, leg, distance, poses=poses, depth=depth,
                             readings=stacked)
    except Exception:  # a failed fusion (bad input, or a bug) costs the people their depth, not their lift
        return out
    for m in range(len(people)):
        if np.isfinite(fused.joints_m[m]).all() and np.isfinite(fused.std_m[m]).all() and fused.readings:
            out[m] = (fused.joints_m[m], fused.std_m[m],
                      DepthReadings(fused.readings.depth_m[m], fused.readings.var[m]))
    return out


def with_frames_ahead(track: Sequence[tuple[int, SkeletonInput]], n: int) -> list[SkeletonInput]:
    """The inputs of one track's frames (``(stamp_ns, input)`` in time order), each with its
    track's next frames (``SkeletonInput.ahead``: at most ``n`` of those after it; the last frame
    an empty one); as given when ``n`` is 0 or there is one frame."""
    if not n or len(track) < 2:
        return [x for _, x in track]
    stamps = np.array([s for s, _ in track], dtype=np.int64)
    points = np.array([x.points for _, x in track], dtype=np.float64)
    confidence = np.array([x.confidence for _, x in track], dtype=np.float64)
    return [replace(x, ahead=FramesAhead(stamps[i + 1:i + 1 + n], points[i + 1:i + 1 + n],
                                         confidence[i + 1:i + 1 + n]))
            for i, (_, x) in enumerate(track)]


class FramePipeline:
    """Checks, the per-track policy and the placement around one :class:`Lifter`.

    Parameters
    ----------
    lifter : Lifter
    settings : FrameSettings
    """

    def __init__(self, lifter: Lifter, settings: FrameSettings = _DEFAULTS) -> None:
        self.settings = settings
        self.policy = TrackPolicy(lifter, settings.track_timeout, settings.warm_start, settings.reinit_ratio)
        #: each track's fused joints followed by its filter (None: not, :meth:`follow_fused`)
        self.track_filter: TrackFilter | None = None

    def follow_fused(self, on: bool) -> None:
        """Whether the skeletons placed on a depth image are answered through their track's filter
        (:class:`~pose_lifter.core.depth.track_filter.TrackFilter`): on where the pipeline's answers
        are final as lifted (the node without ``output_lag``, ``pose-lifter lift --smoothing 0``),
        off where they are refined over later frames (the lag's window, the offline smoothing)."""
        self.track_filter = TrackFilter(self.settings.track_timeout) if on else None

    @property
    def lifter(self) -> Lifter:
        return self.policy.lifter

    def configure(self, lifter: Lifter, settings: FrameSettings) -> None:
        """Change the lifter or the settings; the tracks are kept (see :meth:`TrackPolicy.configure`)."""
        self.settings = settings
        self.policy.configure(lifter, settings.track_timeout, settings.warm_start, settings.reinit_ratio)
        if self.track_filter is not None:
            self.track_filter.gap_s = settings.track_timeout

    def check(self, msg: Any, on_clipped: Callable[[str], Any] = _NO_CLIP) -> CheckedFrame:
        """Step 1 of a ``Skeleton2DArray`` (see the module doc); never raises for bad input."""
        st = self.settings
        over_cap = frame_over_cap(msg, st)
        if over_cap is not None:
            return CheckedFrame(False, skipped=(over_cap,))
        skeletons: Sequence[Any] = msg.skeletons
        n_scanned = min(len(skeletons), CROWD_SCAN * st.max_skeletons)
        seen: set[int] = set()
        admitted: list[int | SkipSkeleton] = []
        for skel in skeletons[:n_scanned]:  # the caps, before any keypoint is read
            try:
                admitted.append(admitted_track(skel, st, seen))
            except Exception as err:
                admitted.append(_refusal(err, _track_id_of(skel)))
        try:  # the layout looked up once, each admitted skeleton mapped to the paper's joints
            joints = iter(frame_joints([skel for skel, a in zip(skeletons[:n_scanned], admitted, strict=True)
                                        if isinstance(a, int)], str(msg.layout)))
        except Exception as err:  # e.g. an unknown layout: the whole frame is unusable
            skip = _refusal(err, None)
            skip = SkipSkeleton(skip.kind, f"frame skipped: {skip}")
            return CheckedFrame(True, skipped=(skip,), n_left_out=len(skeletons))
        threshold = self.lifter.options.confidence_threshold
        out: list[SkeletonInput | SkipSkeleton] = []
        for track_id in admitted:
            if isinstance(track_id, SkipSkeleton):
                out.append(track_id)
                continue
            read = next(joints)
            try:
                if isinstance(read, Exception):
                    raise read
                out.append(skeleton_input(track_id, *read, st, threshold, on_clipped))
            except Exception as err:
                out.append(_refusal(err, track_id))
        inputs = [(i, x) for i, x in enumerate(out) if isinstance(x, SkeletonInput)]
        n_left_out = len(skeletons) - n_scanned
        if len(inputs) > st.max_skeletons:  # a crowd: the largest people are lifted
            kept = set(largest_first([x for _, x in inputs], threshold)[:st.max_skeletons].tolist())
            dropped = {i for k, (i, _) in enumerate(inputs) if k not in kept}
            n_left_out += len(dropped)
            out = [x for i, x in enumerate(out) if i not in dropped]
        skipped: tuple[SkipSkeleton, ...] = ()
        if n_left_out:
            skipped = (SkipSkeleton("too many skeletons", f"{len(skeletons)} skeletons in one frame, "
                                    f"lifting the {st.max_skeletons} largest (max_skeletons)"),)
        return CheckedFrame(True, tuple(out), skipped, n_left_out)

    def end_frame(self, stamp_ns: int) -> None:
        """Step 3: forget the tracks unseen for more than ``track_timeout`` before ``stamp_ns``."""
        self.policy.expire(stamp_ns)
        if self.track_filter is not None:
            self.track_filter.forget(stamp_ns - round(self.settings.track_timeout * 1e9))

    def clear(self) -> None:
        """Forget every track (e.g. after a change of bases: old coefficients are meaningless)."""
        self.policy.clear()
        if self.track_filter is not None:
            self.track_filter.clear()

    def frame(self, checked: CheckedFrame, stamp_ns: int, intrinsics: Intrinsics, depth: DepthImage = None
              ) -> list[LiftedSkeleton | SkipSkeleton]:
        """Steps 2 and 3 of a checked frame: per skeleton of ``checked.skeletons``, in order, the
        lifted skeleton or why not (an unanswered frame lifts and expires nothing). The people
        are lifted together (:func:`lift_together`), and placed on the frame's ``depth`` image
        when there is one."""
        if not checked.answered:
            return []
        inputs = [x for x in checked.skeletons if not isinstance(x, SkipSkeleton)]
        lifted = iter(lift_together([(self, x, stamp_ns, intrinsics) for x in inputs],
                                    None if depth is None else [depth] * len(inputs)))
        out = [x if isinstance(x, SkipSkeleton) else next(lifted) for x in checked.skeletons]
        self.end_frame(stamp_ns)
        return out
