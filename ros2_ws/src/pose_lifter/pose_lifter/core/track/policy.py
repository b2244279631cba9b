"""The per-track policy: one rule for how a tracked person's frames are lifted, used by the ROS node
and by the offline lift alike (so a bag lifted offline gives what the node would publish).

For each frame of a track (``track_id >= 0``; negative ids are untracked, every frame cold):

* a stamp older than the track's last one by at most ``track_timeout`` is out of order: the frame
  is refused (:class:`OutOfOrderFrameError`) and the track kept; older still means the input clock
  jumped back (a looping bag): the track is forgotten and the frame lifted cold;
* within ``track_timeout`` of the last frame the solve is warm-started from it (paper mode: its
  pose and camera; hybrid mode: its camera, the prior's pose starting every frame);
* re-initialisation: when a warm solve's objective exceeds ``reinit_ratio`` times the median of the
  track's last 15 objectives, the frame is also solved cold and the lower objective kept
  (the fit has degraded: a wrong depth basin or a lost person);
* a frame that cannot be lifted drops the track's warm start (the next frame starts cold);
* per-track limb lengths (bones do not change within a person): the median of the learned prior's
  limb proportions over the track's last LIMB_FRAMES frames, once it has MIN_LIMB_FRAMES
  of them, is passed to the lifter for its limb constraints (hybrid mode,
  ``LifterOptions.prior_limbs``, on by default), after :data:`pose_lifter.core.track.state.LIMB_CALIBRATION`;
* hybrid mode with the camera's intrinsics: a frame that follows its track is lifted from its 2D
  corrected for perspective by the track's last pose (:mod:`.placement`);
* hybrid mode, left/right labels (``LifterOptions.label_swaps``): before the gate, an arm's or a
  leg's left and right labels that the track puts far better swapped (its joints much nearer
  where the track puts the other side's) are swapped back for this frame, on at most
  SWAP_MAX_FRAMES frames in a row (:mod:`pose_lifter.core.track.screening`); the lift, the track
  and the published pose then read the 2D with the labels as the track has them;
* hybrid mode, temporal outlier gate (``LifterOptions.outlier_gate``): a visible joint farther
  than ``outlier_gate`` leg lengths from where the track's last frame had it (relative to the
  median motion of the joints) is treated as missing for this frame, before the prior sees it (a
  detection that jumped; a person's joints move far less in one frame); such a joint, like any
  missing one, takes the previous frame's pose into its prior target with
  ``LifterOptions.missing_temporal_weight`` (the track carries it over) and, when the track used
  it on one of its last ``LifterOptions.fill_missing_frames`` frames, enters the learned prior's
  input where the track predicts it (:mod:`pose_lifter.core.track.screening`; the 2D fit
  still ignores it). Not when it would leave fewer than ``min_visible_joints`` or gate more than
  GATE_MAX_FRACTION of the visible joints (the prediction, not the detector, is then wrong), and a
  joint is gated on at most GATE_MAX_FRAMES frames in a row (so the track re-acquires a joint it
  lost).
* hybrid mode, causal output smoothing (:class:`pose_lifter.core.track.smoothing.CausalSmoother`): the
  published pose is the prior's pose on this frame plus the fit's correction of it (fit minus
  prior) averaged over the track's frames (``LifterOptions.correction_smoothing``, exponential);
  on a disturbed track (joints the lift did not use) the
  prior's part is also followed by a constant-velocity (alpha-beta) filter whose gain falls to
  ``LifterOptions.disturbed_smoothing_gain``. Only the output: the track's warm start, limb and
  noise estimates and gate keep the fit's own pose, so no smoothing feeds back into the next
  frame's fit. Every step reads only this and earlier frames (no look-ahead: the node and the
  offline lift publish the same).
* a temporal prior of a frame inside its window (``PosePrior.future_frames > 0``: an offline
  lift's, which knows each track's next frames) reads the track's next frames too: the caller
  gives them (:class:`FramesAhead`); the live node's priors are causal.

The frames of several tracks are lifted together (:func:`lift_tracks`): the policy hands every
frame's row to its lifter once (:meth:`~pose_lifter.core.lift.lifter.Lifter.lift_people`, one batch
per lifter), and once more the rows of the frames it re-initialises (their cold lifts). Each frame
ends with a :class:`TrackOutcome`: its status and reason, and its :class:`TrackedLift` when lifted.

Tracks unseen for longer than ``track_timeout`` (input stamps) are forgotten by :meth:`expire`.
A track's state and the rules that read it are :mod:`pose_lifter.core.track.state`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TypeAlias, cast

import numpy as np
from numpy.typing import NDArray

from ..errors import PoseLifterError
from ..lift.batch import LiftRow
from ..lift.lifter import KERNEL_MODES, Lifter
from ..model.skeleton import N_JOINTS
from ..options import LifterOptions
from ..results import (
    Failure,
    LiftOutcome,
    LiftResult,
    LiftStatus,
    Outcome,
    TrackContext,
    WarmStart,
    project_each,
    with_camera_poses,
)
from .defaults import DEFAULT_REINIT_RATIO, DEFAULT_TRACK_TIMEOUT_S
from .later import LaterFrame
from .later import compile_kernels as compile_later_kernels
from .measurement import compile_kernels as compile_measurement_kernels
from .placement import CameraIntrinsics, perspective_corrected_rows
from .records import FramesAhead, OutOfOrderFrameError, TrackedLift
from .screening import Screened, ToScreen, next_frames, screen_frames
from .screening import compile_kernels as compile_screening_kernels
from .smoothing import CausalSmoother, priors_in_camera, smooth_tracks
from .state import Track, image_spans, swap_back, tracks_limb_proportions
from .state import compile_kernels as compile_track_kernels

__all__ = [
    "DEFAULT_REINIT_RATIO",
    "DEFAULT_TRACK_TIMEOUT_S",
    "FramesAhead",
    "OutOfOrderFrameError",
    "TrackFrame",
    "TrackOutcome",
    "TrackPolicy",
    "TrackedLift",
    "compile_kernels",
    "lift_tracks",
]


#: Output smoothing (:class:`~pose_lifter.core.track.smoothing.CausalSmoother`): the fraction of unused
#: joints (missing, gated or dropped by the outlier pass) over the track's last
#: :data:`~pose_lifter.core.track.state.DISTURBANCE_FRAMES` frames is its disturbance; at
#: DISTURBANCE_FULL and above the prior's alpha-beta gain is ``disturbed_smoothing_gain``, at 0 it
#: is 1 (no filter), linear between.
DISTURBANCE_FULL = 0.2


@dataclass(frozen=True)
class TrackFrame:
    """One person's frame for :func:`lift_tracks`: :meth:`TrackPolicy.lift`'s arguments and the
    policy of its track."""

    policy: TrackPolicy
    track_id: int
    stamp_ns: int
    points: NDArray[np.float64]  #: (12, 2)
    confidence: NDArray[np.float64] | None = None  #: (12,)
    intrinsics: CameraIntrinsics | None = None
    ahead: FramesAhead | None = None


@dataclass
class _Found:
    """A frame with its track (None: untracked or new), warm start (None: cold) and the track's
    limb proportions, then its screening."""

    frame: TrackFrame
    track: Track | None
    warm: WarmStart | None
    limbs: NDArray[np.float64] | None = None
    screened: Screened | None = None
    seen: NDArray[np.float64] | None = None  #: the 2D the lift reads (12, 2)


@dataclass(frozen=True)
class _Pending:
    """A frame between its screening and its lift (:meth:`TrackPolicy._pending`)."""

    frame: TrackFrame
    track: Track | None
    warm: WarmStart | None
    screened: Screened
    seen: NDArray[np.float64]  #: the 2D the lift reads (12, 2)
    context: TrackContext


#: How one frame of :func:`lift_tracks` ended: ``SOLVED`` with its :class:`TrackedLift`, the lift's
#: refusal, ``OUT_OF_ORDER`` (the track is kept), or ``FAILED`` (a bug).
TrackOutcome: TypeAlias = Outcome[TrackedLift]


def lift_tracks(frames: Sequence[TrackFrame]) -> list[TrackOutcome]:
    """Several people's frames (:meth:`TrackPolicy.lift` each, each through its own track's
    policy) together, in order: every frame screened by its track; the rows of all of them lifted
    at once (one :meth:`~pose_lifter.core.lift.lifter.Lifter.lift_people` per lifter); the rows of
    the frames re-initialised lifted again, cold, at once; then each frame entered into its track.
    Returns each frame's :class:`TrackOutcome` (a refused lift drops the track's warm start)."""
    out: dict[int, TrackOutcome] = {}
    pending: list[tuple[int, _Pending]] = []
    for k, found in _before(frames, out):
        try:
            pending.append((k, found.frame.policy._pending(found)))
        except Exception as err:
            out[k] = TrackOutcome.failed(Failure.of(err))
    solved: list[tuple[int, _Pending, LiftResult, bool]] = []
    again: list[tuple[int, _Pending, LiftResult]] = []
    for (k, p), r in zip(pending, _lift_rows([(p, p.warm) for _, p in pending]), strict=True):
        if r.result is None:
            out[k] = _dropped_warm(p, r)
        elif p.frame.policy._reinit(p, r.result):
            again.append((k, p, r.result))
        else:
            solved.append((k, p, r.result, False))
    for (k, p, warm_result), cold in zip(again, _lift_rows([(p, None) for _, p, _ in again]), strict=True):
        if cold.result is None:
            out[k] = _dropped_warm(p, cold)
        elif cold.result.objective < warm_result.objective:
            solved.append((k, p, cold.result, True))
        else:
            solved.append((k, p, warm_result, False))
    _after(solved, out)
    return [out[k] for k in range(len(frames))]


def _lift_rows(items: Sequence[tuple[_Pending, WarmStart | None]]) -> list[LiftOutcome]:
    """The lifts of frames (the 2D each reads), each from its warm start (None: cold), in order: the
    rows of each lifter in one :meth:`~pose_lifter.core.lift.lifter.Lifter.lift_people`."""
    by_lifter: dict[int, list[int]] = {}
    for i, (p, _) in enumerate(items):
        by_lifter.setdefault(id(p.frame.policy.lifter), []).append(i)
    out: dict[int, LiftOutcome] = {}
    for which in by_lifter.values():
        rows = [LiftRow(p.seen, p.screened.confidence, w, p.context) for p, w in (items[i] for i in which)]
        out.update(zip(which, items[which[0]][0].frame.policy.lifter.lift_people(rows), strict=True))
    return [out[i] for i in range(len(items))]


def _before(frames: Sequence[TrackFrame], out: dict[int, TrackOutcome]) -> list[tuple[int, _Found]]:
    """Each frame's track, warm start and limb proportions, then the frames screened together
    (:func:`~pose_lifter.core.track.screening.screen_frames`; a track's second frame in one call
    in a later screening); a frame's refusal (an out-of-order frame) goes to ``out``."""
    found: list[tuple[int, _Found]] = []
    for k, f in enumerate(frames):
        try:
            found.append((k, f.policy._found(f)))
        except Exception as err:
            out[k] = TrackOutcome.failed(Failure.of(err))
    known = [p for _, p in found if p.track is not None]
    limbs = tracks_limb_proportions([cast(Track, p.track) for p in known],
                                    [p.frame.policy.lifter.options.image_limbs for p in known])
    for p, proportions in zip(known, limbs, strict=True):
        p.limbs = proportions
    todo = [p for _, p in found]
    while todo:
        batch: list[_Found] = []
        later: list[_Found] = []
        tracks: set[int] = set()
        for p in todo:
            (later if p.track is not None and id(p.track) in tracks else batch).append(p)
            tracks.add(id(p.track))
        rows = [ToScreen(p.track, p.warm is not None, p.frame.policy.lifter, p.frame.points,
                         p.frame.confidence, p.frame.stamp_ns) for p in batch]
        for p, screened in zip(batch, screen_frames(rows), strict=True):
            p.screened = screened
            if screened.swapped is not None:  # the labels as the track has them, from here on
                p.frame = replace(p.frame, points=swap_back(p.frame.points, screened.swapped))
        todo = later
    _seen([p for _, p in found])
    return found


def _seen(found: Sequence[_Found]) -> None:
    """Sets the 2D each frame's lift reads: corrected for perspective by its track's last pose
    (:func:`~pose_lifter.core.track.placement.perspective_corrected_rows`, as arrays over the
    frames) on a warm-started hybrid frame whose camera intrinsics are known, else its 2D."""
    rows: list[tuple[_Found, tuple[NDArray[np.float64], float, NDArray[np.float64]]]] = []
    for p in found:
        f, p.seen = p.frame, p.frame.points
        if (f.intrinsics is not None and p.track is not None and p.warm is not None
                and p.track.depths is not None and f.policy.lifter.options.mode == "hybrid"
                and np.shape(f.points) == (N_JOINTS, 2)):
            rows.append((p, p.track.depths))
    if not rows:
        return
    focal = [0.5 * (float(fx) + float(fy)) for (fx, fy), _ in (cast(CameraIntrinsics, p.frame.intrinsics)
                                                               for p, _ in rows)]
    seen = perspective_corrected_rows(np.array([p.frame.points for p, _ in rows], dtype=np.float64),
                                      np.array(focal), np.array([d[0] for _, d in rows]),
                                      np.array([d[1] for _, d in rows]), np.array([d[2] for _, d in rows]))
    for (p, _), x in zip(rows, seen, strict=True):
        p.seen = x


def _after(solved: Sequence[tuple[int, _Pending, LiftResult, bool]], out: dict[int, TrackOutcome]) -> None:
    """The lifted frames entered into their tracks and published into ``out`` (hybrid: smoothed,
    as arrays over the frames, and measurement-updated); a frame's failure goes to ``out``."""
    tracked = [(k, p, r, reinit) for k, p, r, reinit in solved if p.frame.track_id >= 0]
    try:
        tracks: Sequence[Track] = _record([(p.frame, p.track, r) for _, p, r, _ in tracked])
    except Exception as err:  # a bug, not a refusal: every frame of the batch reports it
        out.update((k, TrackOutcome.failed(Failure.of(err))) for k, _, _, _ in tracked)
        tracked, tracks = [], []
    by_frame = dict(zip((k for k, _, _, _ in tracked), tracks, strict=True))
    hybrid: list[tuple[int, _Pending, LiftResult, bool, Track]] = []
    for k, p, r, reinit in solved:
        if k in by_frame and p.frame.policy.lifter.options.mode == "hybrid":
            hybrid.append((k, p, r, reinit, by_frame[k]))
        elif k in by_frame or p.frame.track_id < 0:
            out[k] = TrackOutcome.solved(TrackedLift(r, p.warm is not None, reinit,
                                                     swapped=p.screened.swapped))
    # the output's state carries over a re-initialised frame (its jump is smoothed)
    try:
        published = _smoothed([(p, r, t) for _, p, r, _, t in hybrid])
    except Exception as err:  # a bug, not a refusal: every frame of the batch reports it
        out.update((k, TrackOutcome.failed(Failure.of(err))) for k, _, _, _, _ in hybrid)
        return
    for (k, p, r, reinit, track), smoothed in zip(hybrid, published, strict=True):
        follows = p.warm is not None
        try:
            updated = p.frame.policy._measure(track, smoothed or r, p.seen, follows, p.frame)
        except Exception as err:
            out[k] = TrackOutcome.failed(Failure.of(err))
            continue
        o = updated if updated is not None else smoothed
        out[k] = TrackOutcome.solved(TrackedLift(r, follows, reinit, swapped=p.screened.swapped) if o is None
                                     else TrackedLift(o, follows, reinit, r.pose_camera, p.screened.swapped))


def _record(rows: Sequence[tuple[TrackFrame, Track | None, LiftResult]]) -> list[Track]:
    """Each lifted frame entered into its track (made on its first frame): the warm start, stamp,
    objective, the prior's limb proportions, the frame's 2D, where each joint was and its image
    limb lengths, the arrays of all of them computed together."""
    if not rows:
        return []
    results = [r for _, _, r in rows]
    priors = [i for i, r in enumerate(results) if r.prior_pose is not None]
    limbs = {} if not priors else dict(zip(priors, Lifter.limb_proportions_of(
        np.array([results[i].prior_pose for i in priors])), strict=True))
    x = np.array([f.points for f, _, _ in rows], dtype=np.float64)  # the tracks' own copies
    used = np.array([r.weights > 0 for r in results])
    scale = np.array([float(r.camera.scale) for r in results])
    # where each joint was: its detection when the lift used it, else the fit's projection
    where = np.where(used[..., None], x, project_each(np.array([r.pose for r in results]),
                                                     [r.camera for r in results]))
    spans = image_spans(x, used, scale)
    out: list[Track] = []
    for i, (f, track, result) in enumerate(rows):
        if track is None:
            track = f.policy._tracks[f.track_id] = Track(None, f.stamp_ns)
        track.warm = result.warm_start()
        track.depths = (np.array(result.pose_camera[:, 2]), float(scale[i]),
                        np.array(result.camera.translation))
        track.last_stamp_ns = f.stamp_ns
        track.unused = np.where(used[i], 0, track.unused + 1)
        track.add_objective(float(result.objective))
        if i in limbs:
            track.add_limbs(limbs[i])
        track.history.append((f.stamp_ns, x[i], used[i]))
        track.fits.append((f.stamp_ns, where[i], float(scale[i])))
        opts = f.policy.lifter.options
        if opts.mode == "hybrid" and opts.image_limbs:
            track.add_spans(spans[i])
        out.append(track)
    return out


def _smoothed(rows: Sequence[tuple[_Pending, LiftResult, Track]]) -> list[LiftResult | None]:
    """Each hybrid result with its pose replaced by its track's smoothed one (see
    :class:`~pose_lifter.core.track.smoothing.CausalSmoother`; the tracks' smoothers updated as
    arrays, :func:`~pose_lifter.core.track.smoothing.smooth_tracks`), or None where smoothing is
    off or starts again (a cold solve)."""
    out: list[LiftResult | None] = [None] * len(rows)
    go: list[tuple[int, NDArray[np.float64], float, float]] = []
    priors, has_prior = priors_in_camera([r for _, r, _ in rows])
    for i, (p, r, track) in enumerate(rows):
        opts = p.frame.policy.lifter.options
        track.unused_share.append(float(np.count_nonzero(r.weights <= 0)) / N_JOINTS)
        prior = priors[i]
        if not has_prior[i] or (opts.correction_smoothing <= 0 and opts.disturbed_smoothing_gain >= 1):
            track.smoother = None
            continue
        if p.warm is None or track.smoother is None:
            track.smoother = CausalSmoother()
        shares = track.unused_share
        disturbance = sum(shares) / len(shares)
        gain = 1.0 - min(1.0, disturbance / DISTURBANCE_FULL) * (1.0 - opts.disturbed_smoothing_gain)
        go.append((i, prior, opts.correction_smoothing, gain))
    if not go:
        return out
    tracks = [rows[i][2] for i, _, _, _ in go]
    poses = smooth_tracks([cast(CausalSmoother, t.smoother) for t in tracks],
                          np.array([rows[i][1].pose_camera for i, _, _, _ in go]),
                          np.array([prior for _, prior, _, _ in go]),
                          np.array([b for _, _, b, _ in go]), np.array([g for _, _, _, g in go]))
    finite = np.asarray(np.isfinite(poses).all(axis=(1, 2)))
    kept = [k for k in range(len(go)) if finite[k]]
    for k in range(len(go)):
        if not finite[k]:
            tracks[k].smoother = None
    published = with_camera_poses([rows[go[k][0]][1] for k in kept], poses[kept]) if kept else []
    for k, res in zip(kept, published, strict=True):
        out[go[k][0]] = res
    return out


def _dropped_warm(p: _Pending, lifted: LiftOutcome) -> TrackOutcome:
    """A lift without a result: a refusal (any status but ``FAILED``, a bug) drops the track's
    warm start."""
    if lifted.status != LiftStatus.FAILED and p.track is not None:
        p.track.warm = None
    return TrackOutcome(lifted.status, lifted.reason)


class TrackPolicy:
    """Per-track warm starts, re-initialisation and expiry around one :class:`Lifter`.

    Parameters
    ----------
    lifter : Lifter
    track_timeout : float
        Seconds of input time after which a track's warm start is not used (and, in
        :meth:`expire`, the track is forgotten).
    warm_start : bool
        False: every frame cold (the policy still refuses out-of-order frames).
    reinit_ratio : float
        A warm solve whose objective exceeds this times the track's recent median is redone cold
        (``<= 0``: never).
    """

    def __init__(self, lifter: Lifter, track_timeout: float = DEFAULT_TRACK_TIMEOUT_S,
                 warm_start: bool = True, reinit_ratio: float = DEFAULT_REINIT_RATIO) -> None:
        self._tracks: dict[int, Track] = {}
        #: The caller smooths each track over past and future frames (the offline lift): the
        #: measurement update waits for :meth:`kept_later` (after the tracks' frames).
        self.smoothed_later = False
        self._later: dict[int, list[LaterFrame]] = {}  # the frames kept for it, by track id
        self.configure(lifter, track_timeout, warm_start, reinit_ratio)
        compile_measurement_kernels()  # now, not on a track's first frame
        compile_later_kernels()
        compile_track_kernels()
        compile_screening_kernels()

    def configure(self, lifter: Lifter, track_timeout: float, warm_start: bool, reinit_ratio: float) -> None:
        """Change the lifter or the settings; the tracks are kept (forgotten when ``warm_start``
        is turned off)."""
        self.lifter = lifter
        self.track_timeout_ns = round(float(track_timeout) * 1e9)
        self.warm_start = bool(warm_start)
        self.reinit_ratio = float(reinit_ratio)
        if not self.warm_start:
            self._tracks.clear()

    def __len__(self) -> int:
        return len(self._tracks)

    def clear(self) -> None:
        """Forget every track (e.g. after a change of bases: old coefficients are meaningless)."""
        self._tracks.clear()

    def restore(self, track_id: int, warm: WarmStart | None, stamp_ns: int) -> None:
        """Set a track's state (its warm start and last stamp), e.g. carried over from another
        policy; its objective history starts empty."""
        self._tracks[track_id] = Track(warm, stamp_ns)

    def expire(self, stamp_ns: int) -> None:
        """Forget the tracks unseen for more than ``track_timeout`` before ``stamp_ns``."""
        stale = [t for t, s in self._tracks.items() if stamp_ns - s.last_stamp_ns > self.track_timeout_ns]
        for t in stale:
            del self._tracks[t]

    def lift(self, track_id: int, stamp_ns: int, points: NDArray[np.float64],
             confidence: NDArray[np.float64] | None = None,
             intrinsics: CameraIntrinsics | None = None, ahead: FramesAhead | None = None) -> TrackedLift:
        """Lift one frame of a track (model joints, as :meth:`Lifter.lift`): find the track and its
        warm start, screen the frame (gate, noise), tell the lifter what the track knows, solve
        (cold again when the warm solve degraded), record the frame in the track and publish
        (hybrid: smoothed and measurement-updated). :func:`lift_tracks` of this frame alone.

        With ``intrinsics`` ``((fx, fy), (cx, cy))`` (pixels) the lift reads the 2D corrected for
        perspective by the track's last pose (:mod:`.placement`; hybrid mode, a frame that follows
        its track).

        ``ahead``, the track's next frames, is read by a temporal prior with future frames (see
        :func:`~pose_lifter.core.track.screening.next_frames`); a causal prior ignores it.

        Raises
        ------
        OutOfOrderFrameError
            An out-of-order frame of a known track (the track is kept).
        InvalidInputError, TooFewJointsError
            From the lifter; the track's warm start is dropped.
        """
        frame = TrackFrame(self, track_id, stamp_ns, points, confidence, intrinsics, ahead)
        return lift_tracks([frame])[0].unwrap()

    def _found(self, f: TrackFrame) -> _Found:
        """A frame's track and warm start."""
        return _Found(f, *self._find(f.track_id, f.stamp_ns))

    def _pending(self, p: _Found) -> _Pending:
        """A screened frame up to its lift: the 2D the lift reads and the track's context (an
        error of the context drops the warm start)."""
        f, track, warm, frame, seen = p.frame, p.track, p.warm, p.screened, p.seen
        assert frame is not None and seen is not None
        try:
            context = self._context(track, warm, f.stamp_ns, frame, p.limbs, f.points, f.ahead)
        except PoseLifterError:
            if track is not None:
                track.warm = None
            raise
        return _Pending(f, track, warm, frame, seen, context)

    def _reinit(self, p: _Pending, result: LiftResult) -> bool:
        """A warm solve whose objective exceeds ``reinit_ratio`` times the track's recent median
        is solved cold too (the lower kept)."""
        track = p.track
        if p.warm is None or track is None or self.reinit_ratio <= 0 or len(track.objectives) < 3:
            return False
        return result.objective > self.reinit_ratio * track.objective_median()

    def _find(self, track_id: int, stamp_ns: int) -> tuple[Track | None, WarmStart | None]:
        """The frame's track (None: untracked, new, or forgotten because the input clock jumped
        back) and its warm start (None: cold); raises :class:`OutOfOrderFrameError`."""
        track = self._tracks.get(track_id) if track_id >= 0 else None
        if track is None:
            return None, None
        age = stamp_ns - track.last_stamp_ns
        if -self.track_timeout_ns <= age < 0:
            raise OutOfOrderFrameError(
                f"track {track_id}: stamp {-age / 1e9:.3f} s older than its last frame")
        if age < -self.track_timeout_ns:  # the input clock jumped back (e.g. a looping bag)
            del self._tracks[track_id]
            return None, None
        return track, self._warm(track, age)

    def _warm(self, track: Track, age_ns: int) -> WarmStart | None:
        """The track's warm start for a frame ``age_ns`` >= 0 after its last one (None: cold)."""
        return track.warm if age_ns <= self.track_timeout_ns and self.warm_start else None

    def _past(self, track: Track | None, warm: WarmStart | None, stamp_ns: int
              ) -> tuple[NDArray[np.float64], NDArray[np.bool_]] | None:
        """The past frames the learned prior reads (a warm-started frame of the hybrid or learned
        mode; see :meth:`Track.past`)."""
        if track is None or warm is None or self.lifter.options.mode == "paper":
            return None
        temporal = self.lifter.temporal_prior
        prior = temporal or self.lifter.prior
        return track.past(stamp_ns, prior.window - 1 - prior.future_frames)

    def _context(self, track: Track | None, warm: WarmStart | None, stamp_ns: int, frame: Screened,
                 limbs: NDArray[np.float64] | None, points: NDArray[np.float64],
                 ahead: FramesAhead | None = None) -> TrackContext:
        """What the track tells the lifter of this frame (:class:`TrackContext`): its limb
        proportions, the previous pose's weight per joint in the prior's target (a joint the frame
        lacks: ``missing_temporal_weight``, the others 0),
        its past and next frames (temporal prior; ``points`` (12, 2) this frame's 2D) and the
        joints it may fill in."""
        opts = self.lifter.options
        tw = np.zeros(N_JOINTS)
        if warm is not None and frame.visible is not None and opts.missing_temporal_weight > 0:
            # a joint the detector lost on this frame is carried over from the track's last pose
            tw = np.where(frame.visible, tw, np.maximum(tw, opts.missing_temporal_weight))
        past = self._past(track, warm, stamp_ns)
        fill = None
        if frame.predicted is not None and opts.fill_missing_frames > 0:
            assert track is not None
            if track.fit_is_sound():
                fill = (frame.predicted, track.unused < opts.fill_missing_frames)
        future = next_frames(self.lifter, track, ahead, stamp_ns, past, points, frame)
        return TrackContext(limbs, tw, past, frame.gated, fill, future)

    def _measure(self, track: Track, result: LiftResult, points: NDArray[np.float64], follows: bool,
                 frame: TrackFrame) -> LiftResult | None:
        """``result`` (the fit, smoothed) with its pose replaced by the measurement update's
        (:meth:`Track.measured`), or None; with :attr:`smoothed_later` the frame (``frame``:
        its track id and stamp) is kept for the offline update (:meth:`kept_later`) instead."""
        opts = self.lifter.options
        if self.smoothed_later and opts.measurement_update:
            self._later.setdefault(frame.track_id, []).append(
                LaterFrame.of(track, result, points, follows, frame.stamp_ns))
            return None
        return track.measured(result, points, follows, opts.measurement_update, opts.measurement_depth,
                              opts.measurement_gate)

    def kept_later(self) -> dict[int, list[LaterFrame]]:
        """The frames kept for the offline update since the last call (:attr:`smoothed_later`), by
        track id, in the order lifted; then forgotten here."""
        kept, self._later = self._later, {}
        return kept


def compile_kernels() -> float:
    """Compile the core's kernels (numba, see ``core.numeric.jit``) into the cache of the place
    this package is imported from, or load them from it: a warm-up lift
    (:meth:`~pose_lifter.core.lift.lifter.Lifter.warm_up`) in each of
    :data:`~pose_lifter.core.lift.lifter.KERNEL_MODES` with the packaged bases and prior, and the
    tracks' kernels (their screening and the measurement update). The cache lives beside the
    sources, so an editable source tree and an installed copy each need it once (the Makefile runs
    it after installing either); a user's first lift then starts as fast as the second. Returns
    the seconds it took (~25-60 s of CPU to compile, ~1 s to load)."""
    from pose_lifter.core.depth.fuse import compile_kernels as compile_depth_kernels

    start = time.perf_counter()
    for mode in KERNEL_MODES:
        Lifter(None, LifterOptions(mode=mode)).warm_up()
    compile_measurement_kernels()
    compile_later_kernels()
    compile_track_kernels()
    compile_screening_kernels()
    compile_depth_kernels()
    return time.perf_counter() - start
