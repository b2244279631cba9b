"""The hybrid and learned modes of the lifter: the learned prior's pose as L1 rows of the paper's
objective, the hybrid starts, mirrored hypothesis and outlier pass, and the prior alone.

The hybrid objective (see :mod:`pose_lifter.core.lift.lifter`) adds to the paper's
``sum_j p_j |P_j,xy - M0 y_j - t|_1 + sum_j q_j |P_j,z - m3 (y_j - mean_i y_i)|_1`` where ``P``
(12, 3) is the prior's pose for this image (:class:`pose_lifter.core.solve.pose_step.PriorRows`).
:class:`PriorFit` holds what these modes solve with (the options, the priors, the pose model and
its runs); the lifter makes one per setting. Its stages take a batch's rows
(:class:`~pose_lifter.core.lift.batch.Person`) together: the prior's poses of all of them in one
pass of the network (:func:`~pose_lifter.core.lift.batch.prior_calls`), their runs in one compiled
call (:meth:`~pose_lifter.core.lift.runs.Runs.run_all`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..model.pose_model import PoseModel
from ..model.prior import PosePrior
from ..model.skeleton import (
    JOINT_NAMES,
    N_JOINTS,
    RIGHT_LOWER_LEG,
    body_frame,
    limb_lengths,
    normalise_pose_flat,
)
from ..numeric.fast import mean_rows, row_norms
from ..numeric.jit import njit
from ..options import LifterOptions
from ..results import Camera, Failure, Frames, LiftResult, StartKind, project_each
from ..solve.pose_step import PriorRows
from . import batch
from .batch import Person, PriorCall
from .runs import Run, Runs, RunSpec
from .starts import StartRun, Starts

__all__ = ["OUTLIER_MEDIAN_FACTOR", "PriorFit", "TargetStatus"]

#: The hybrid outlier pass flags a joint only beyond this many times the median disagreement of
#: the frame's visible joints as well as beyond ``outlier_threshold`` (under heavy Gaussian noise
#: every joint disagrees a little: the median sets the scale).
OUTLIER_MEDIAN_FACTOR = 3.0


_NO_POSE = np.zeros((N_JOINTS, 3))
_NO_WEIGHTS = np.zeros(N_JOINTS)


def _target(f: _Fitting) -> NDArray[np.float64]:
    """The prior rows' target (12, 3) of a person whose rows are made."""
    assert f.prior is not None
    return f.prior.target


class TargetStatus(IntEnum):
    """How :func:`_target_kernel` ended."""

    OK = 0
    #: The prior's pose is not finite.
    NOT_FINITE = 1
    #: A blend with the previous frame's pose without a visible joint to align it by.
    NO_JOINT = 2


@njit
def _target_kernel(pose: NDArray[np.float64], centre: NDArray[np.float64], spread: float,
                   previous: NDArray[np.float64], temporal_weight: NDArray[np.float64],
                   visible: NDArray[np.bool_], blend: bool) -> tuple[NDArray[np.float64], int]:
    """The prior rows' target (12, 3) of :meth:`PriorFit._prior_rows`: the prior's ``pose`` (12, 3,
    input units) in the normalised frame (``(x - centre) / spread``, depth ``/ spread``), and with
    ``blend`` the previous frame's pose ``P`` (12, 3, same frame), its image positions moved by
    the median over the ``visible`` joints of the target's minus its own, blended in by
    ``temporal_weight`` ``t`` (12,) as ``(target + t P) / (1 + t)`` (when some ``t > 0``).
    Returns ``(target, status)``, the status a :class:`TargetStatus` value (an int: a compiled
    function boxes no enum member)."""
    target = np.empty_like(pose)
    target[:, 0] = (pose[:, 0] - centre[0]) / spread
    target[:, 1] = (pose[:, 1] - centre[1]) / spread
    target[:, 2] = pose[:, 2] / spread
    if not np.isfinite(target).all():
        return target, TargetStatus.NOT_FINITE.value
    if not blend or not (temporal_weight > 0).any():
        return target, TargetStatus.OK.value
    if not visible.any():
        return target, TargetStatus.NO_JOINT.value
    d = (target[:, :2] - previous[:, :2])[visible]
    moved = previous.copy()
    moved[:, 0] += np.median(d[:, 0])
    moved[:, 1] += np.median(d[:, 1])
    t = temporal_weight.reshape(-1, 1)
    return (target + t * moved) / (1.0 + t), TargetStatus.OK.value


def _prior_weights(prior: PosePrior, weight_xy: float, weight_z: float) -> NDArray[np.float64]:
    """The prior rows' weights (12, 2): ``weight_xy`` and ``weight_z`` times the prior's
    :attr:`PosePrior.relative_weights` (kept on the prior per pair of weights: the same for every
    frame; the kernels only read them)."""
    key = (weight_xy, weight_z)
    cache = prior.row_weights
    if key not in cache:
        rel = prior.relative_weights
        cache[key] = np.ascontiguousarray(np.column_stack([weight_xy * rel[:, 0], weight_z * rel[:, 1]]))
    return cache[key]


@dataclass(eq=False)
class _Fitting:
    """A person's hybrid starts while :meth:`PriorFit.starts_people` runs them (``failure``: why
    the person stopped short of a result, after which no stage takes them)."""

    person: Person
    w: NDArray[np.float64]  #: the 2D weights in use (the outlier pass zeroes some)
    previous: NDArray[np.float64] | None  #: the warm start's pose in this frame's units (12, 3)
    prior: PriorRows | None = None
    prior_pose: NDArray[np.float64] | None = None
    tried: list[StartRun] = field(default_factory=list)
    total: int = 0
    n_starts: int = 0
    failure: Failure | None = None


#: The shoulders' joint indices (:meth:`PriorFit.prior_input`).
_SHOULDERS = np.array([JOINT_NAMES.index("left_shoulder"), JOINT_NAMES.index("right_shoulder")])


class PriorFit:
    """The hybrid and learned modes' solve with one setting of the lifter.

    Parameters
    ----------
    options : LifterOptions
    prior : PosePrior
        The single-frame learned prior.
    temporal_prior : PosePrior or None
        The temporal prior of tracked frames (None: off): causal, or in a lift that reads ahead one
        that reads the frames after the one it lifts.
    model : PoseModel
    runs : Runs
        The alternation runs of ``model`` and ``options``.
    cut_body_prior : PosePrior or None
        The prior of the tracked frames whose 2D lacks a shoulder (None: the temporal prior's).
        The packaged temporal priors were trained with the lower body cut out of the image, never
        the top: a body close to the camera, whose shoulders the image's top border cuts, they
        lift badly. On those frames the lift takes the same prior trained with a tenth of its
        samples cut at both ends by the image's borders
        (:attr:`~pose_lifter.core.lift.lifter.Lifter.cut_body_prior`). On the evaluation tool's
        validation tracks at 1.5 m, P-MPJPE with it and with the temporal prior on every frame:
        the node's fused lift 74.9 and 111.2 mm, its monocular one 75.0 and 110.4,
        ``fused-offline`` 72.3 and 119.6; at 3 and 5 m and in the accuracy table's conditions the
        two within 0.1 mm (``learned-t`` ``missing15`` 0.5). The cut bodies' prior on every frame
        gives the offline lift 62.0 at 1.5 m but 0.5-1.3 mm more on the bodies the image shows
        whole (``lowercut`` 1.3), so it takes only the frames that lack a shoulder.
    """

    def __init__(self, options: LifterOptions, prior: PosePrior, temporal_prior: PosePrior | None,
                 model: PoseModel, runs: Runs, cut_body_prior: PosePrior | None = None) -> None:
        self.options, self.prior, self.temporal_prior = options, prior, temporal_prior
        self.cut_body_prior = cut_body_prior
        self.model, self.runs = model, runs
        #: the mean log length of the model's own limbs (:meth:`limb_radii`)
        self._log_limb_mean = float(np.mean(np.log(np.sqrt(model.limb_sq))))

    def limb_radii(self, proportions: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Limb-constraint radii (8,) with the ratios of ``proportions`` and the geometric-mean
        size of the model's own limbs (so the person keeps the bases' scale); None when the
        proportions are unusable (non-finite or not positive)."""
        p = np.asarray(proportions, dtype=np.float64)
        if p.shape != (8,) or not np.isfinite(p).all() or (p <= 0).any():
            return None
        lp = np.log(p)
        return np.ascontiguousarray(p * np.exp(self._log_limb_mean - np.add.reduce(lp) / lp.size))

    def prior_input(self, x: NDArray[np.float64], visible: NDArray[np.bool_], past: Frames | None,
                    future: Frames | None = None) -> tuple[PosePrior, NDArray[np.float64], NDArray[np.bool_]]:
        """The prior a row's pose comes from and its input (what
        :class:`~pose_lifter.core.lift.batch.PriorCall` takes): the temporal prior when the lift has
        ``past`` frames, else the single-frame one; this frame (12, 2), (12,), or a window
        (W, 12, 2), (W, 12).

        A window holds ``W - 1 - F`` frames before this one and ``F`` after it (``F`` the prior's
        :attr:`~pose_lifter.core.model.prior.PosePrior.future_frames`): the last of ``past`` and the
        first of ``future``, the missing ones padded with the oldest past frame given and the
        latest future frame given (or this frame). The temporal prior runs when ``past`` has a
        frame (the ``cut_body_prior`` when there is one and this frame lacks a shoulder);
        otherwise a windowed ``prior`` gets this frame in every place."""
        prior = self.prior
        has_past = past is not None and len(past[0]) > 0
        if has_past and self.temporal_prior is not None:
            prior = self.temporal_prior
            if self.cut_body_prior is not None and not visible[_SHOULDERS].all():
                prior = self.cut_body_prior
        if prior.window == 1:
            return prior, x, visible
        n_future = prior.future_frames
        k = prior.window - 1 - n_future  # this frame's place in the window
        pts = np.empty((prior.window, N_JOINTS, 2))
        vis = np.empty((prior.window, N_JOINTS), dtype=bool)
        pts[k], vis[k] = x, visible
        if has_past:
            assert past is not None
            n_past = len(past[0])
            rows = [max(n_past - k + i, 0) for i in range(k)]
            pts[:k], vis[:k] = past[0][rows], past[1][rows]
        else:
            pts[:k], vis[:k] = x, visible
        if n_future:
            n_given = 0 if future is None else len(future[0])
            if n_given:
                assert future is not None
                rows = [min(i, n_given - 1) for i in range(n_future)]
                pts[k + 1:], vis[k + 1:] = future[0][rows], future[1][rows]
            else:
                pts[k + 1:], vis[k + 1:] = x, visible
        # the prior reads only the visible joints (missing ones are zeros of its input)
        return prior, pts, vis

    def _previous(self, p: Person) -> NDArray[np.float64] | None:
        """The warm start's pose (12, 3) in this frame's normalised units: its image positions by
        the warm camera, its depths relative to the joints' mean; None on a cold frame."""
        warm, cam0 = p.warm, p.cam0
        if warm is None or cam0 is None:
            return None
        prev = self.model.pose(warm.alpha)
        previous = np.empty((N_JOINTS, 3))
        previous[:, :2] = cam0.project(prev)
        previous[:, 2] = cam0.scale * (prev - mean_rows(prev)) @ cam0.rotation[2]
        return previous

    def _prior_stage(self, fits: Sequence[_Fitting], rows: bool = True) -> None:
        """The prior stage: each person's prior pose for the joints their weights keep, the poses of
        all of them in one pass of each prior's network (:func:`~pose_lifter.core.lift.batch.prior_calls`,
        over the runs' threads), and with ``rows`` their prior rows (:meth:`_prior_rows`; the
        learned mode's pose alone reads neither the rows nor the track's ``fill``); a person the
        prior or the rows refuse gets the failure."""
        calls: list[PriorCall] = []
        asked: list[_Fitting] = []
        for f in fits:
            try:
                x, vis = self._filled(f) if rows else (f.person.x, f.w > 0)
                track = f.person.track
                prior, pts, v = self.prior_input(x, vis, track.past, track.future)
                calls.append(PriorCall(prior, pts, v, self.options.prior_flip))
                asked.append(f)
            except Exception as err:
                f.failure = Failure.of(err)
        if not calls:
            return
        poses = batch.prior_calls(calls, self.runs.threads)
        for f, c, pose in zip(asked, calls, poses, strict=True):
            if isinstance(pose, Failure):
                f.failure = pose
                continue
            try:
                f.prior, f.prior_pose = (self._prior_rows(f, pose, c.prior) if rows else None), pose
            except Exception as err:
                f.failure = Failure.of(err)

    @staticmethod
    def _filled(f: _Fitting) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """The 2D (12, 2) and visible joints (12,) the prior reads: the joints with weight, and
        those without that the track's ``fill`` gives a position (see :class:`TrackContext`)."""
        x, vis = f.person.x, f.w > 0
        fill = f.person.track.fill
        if fill is not None:
            add = fill[1] & ~vis
            if add.any():
                x = np.where(add[:, None], fill[0], x)
                vis = vis | add
        return x, vis

    def _prior_rows(self, f: _Fitting, pose: NDArray[np.float64], used: PosePrior) -> PriorRows:
        """The prior's ``pose`` (12, 3, input units) by the prior ``used`` as rows of the hybrid
        objective in the person's normalised frame, blended with the warm start's pose by the
        track's ``temporal_weight`` (12,); limb radii from its ``limb_proportions``
        (``options.prior_limbs``)."""
        track, norm, previous = f.person.track, f.person.norm, f.previous
        tw = track.temporal_weight
        blend = previous is not None
        target, status = _target_kernel(
            pose, norm.centre, float(norm.spread), _NO_POSE if previous is None else previous,
            np.ascontiguousarray(tw, dtype=np.float64) if blend else _NO_WEIGHTS, f.w > 0, blend)
        if status == TargetStatus.NOT_FINITE:
            raise InvalidInputError("the learned prior gave non-finite values for this input")
        if status == TargetStatus.NO_JOINT:
            raise IndexError("no visible joint to blend the previous frame's pose by")
        o = self.options
        weights = _prior_weights(used, o.prior_weight_xy, o.prior_weight_z)
        radii = None
        if o.prior_limbs and track.limb_proportions is not None:
            radii = self.limb_radii(track.limb_proportions)
        return PriorRows(np.ascontiguousarray(target), weights, radii)

    def starts_people(self, people: Sequence[Person]) -> list[Starts | Failure]:
        """The hybrid mode's stages (module docstring) over a batch of people, in order: the prior
        (every person's pose in one pass of the network), the runs from the prior's poses (one
        compiled call), the depth-mirrored hypotheses of the cold frames, and up to
        ``outlier_passes`` outlier passes, each dropping the joints that disagree with the image and
        running the fit again (a prior pass and a compiled call each). Every frame starts from the
        prior's pose (with the warm start's camera when tracked): the prior re-initialises the
        depth on every frame, so a track cannot stay in a wrong basin. Returns each person's
        :class:`Starts`, or the failure that stopped them."""
        o, runs = self.options, self.runs
        fits = [_Fitting(p, p.w, self._previous(p)) for p in people]
        self._prior_stage(fits)
        live = [f for f in fits if f.failure is None]
        firsts = runs.run_all([RunSpec(f.person.xn, f.w, runs.start_alpha(_target(f)), f.person.cam0,
                                       o.hybrid_alternations, prior=f.prior) for f in live])
        for f, run in zip(live, firsts, strict=True):
            self._tried(f, [(StartKind.PRIOR, -1, run)])
        if o.warm_flip:
            self._mirrored_stage([f for f in fits if f.failure is None and f.person.warm is None])
        for f in fits:
            f.total, f.n_starts = sum(r.run.n_iter for r in f.tried), len(f.tried)
        self._outlier_passes(fits)
        return [Starts(f.tried, f.total, f.n_starts, f.w, f.prior_pose) if f.failure is None else f.failure
                for f in fits]

    def _mirrored_stage(self, cold: Sequence[_Fitting]) -> None:
        """The mirrored hypotheses of the cold frames: the depth-mirrored copy of each one's run
        from the prior's pose, tried beside it (:meth:`~pose_lifter.core.lift.runs.Runs.mirrored_runs`)."""
        flips = self.runs.mirrored_runs([(f.person.xn, f.w, f.tried[0].run, f.prior) for f in cold],
                                        self.options.hybrid_alternations)
        for f, run in zip(cold, flips, strict=True):
            self._tried(f, [(f.tried[0].kind, -1, f.tried[0].run), (StartKind.MIRRORED, -1, run)])

    @staticmethod
    def _tried(f: _Fitting, runs: list[tuple[StartKind, int, Run | Failure]]) -> None:
        """``f``'s runs tried become ``runs``, or its failure the first of them that failed."""
        tried = []
        for kind, index, run in runs:
            if isinstance(run, Failure):
                f.failure = run
                return
            tried.append(StartRun(kind, index, run))
        f.tried = tried

    def _outlier_passes(self, fits: Sequence[_Fitting]) -> None:
        """Up to ``outlier_passes`` passes over ``fits`` (module docstring): a person whose best
        run leaves joints disagreeing with the image has them dropped, the prior re-run without
        them (one prior stage), and the fit continued and started again from the prior's new pose
        (one compiled call; the lower objective kept); a person's passes end when none is
        flagged."""
        o, runs = self.options, self.runs
        n_alt = o.hybrid_alternations
        active = [f for f in fits if f.failure is None]
        for k in range(o.outlier_passes):
            flagged = self._drop_outliers([f for f in active if k < self._passes(f)])
            self._prior_stage(flagged)
            flagged = [f for f in flagged if f.failure is None]
            best = [min(f.tried, key=lambda r: r.run.objective) for f in flagged]
            specs = []
            for f, b in zip(flagged, best, strict=True):
                xn = f.person.xn
                specs += [RunSpec(xn, f.w, b.run.pose.alpha, b.run.camera.camera, n_alt, prior=f.prior),
                          RunSpec(xn, f.w, runs.start_alpha(_target(f)), None, n_alt, prior=f.prior)]
            done = runs.run_all(specs)
            for j, (f, b) in enumerate(zip(flagged, best, strict=True)):
                cont, fresh = done[2 * j], done[2 * j + 1]
                self._tried(f, [(b.kind, b.index, cont), (StartKind.PRIOR, -1, fresh)])
                if f.failure is None:
                    f.total += f.tried[0].run.n_iter + f.tried[1].run.n_iter
            active = [f for f in flagged if f.failure is None]
            if not active:
                break

    def _passes(self, f: _Fitting) -> int:
        """The outlier passes a person's frame gets (its threshold: the gated one on a frame the
        track screened; none with a threshold of 0)."""
        o = self.options
        return o.outlier_passes if self._threshold(f) > 0 else 0

    def _threshold(self, f: _Fitting) -> float:
        o = self.options
        return o.outlier_threshold_gated if f.person.track.gated else o.outlier_threshold

    def _drop_outliers(self, fits: Sequence[_Fitting]) -> list[_Fitting]:
        """Zero the weights of the joints of ``fits`` that disagree with the image (far from their
        best run's projection or from the prior's image position, beyond the threshold and
        ``OUTLIER_MEDIAN_FACTOR`` times the median over the visible joints), all people as
        arrays. Returns the people whose weights changed: not those without such a joint or who
        would keep fewer than ``min_visible_joints``."""
        if not fits:
            return []
        runs = [min(f.tried, key=lambda r: r.run.objective).run for f in fits]
        xn = np.array([f.person.xn for f in fits])  # (n, 12, 2)
        fits_2d = project_each(np.array([r.pose.pose for r in runs]), [r.camera.camera for r in runs])
        # a joint disagrees with the image when it is far from the fit's projection or from
        # the prior's image position (the prior is trained with confident outliers)
        prior_2d = np.array([_target(f)[:, :2] for f in fits])
        resid = np.maximum(row_norms(xn - fits_2d), row_norms(xn - prior_2d))
        vis = np.array([f.w for f in fits]) > 0  # (n, 12)
        n_vis = np.count_nonzero(vis, axis=1)
        # the median over each person's visible joints, all people at once: the middle of the
        # sorted values, or the mean of the two middle ones
        ranked = np.sort(np.where(vis, resid, np.inf), axis=1)
        rows, mid = np.arange(len(fits)), n_vis // 2
        upper = ranked[rows, mid]
        median = np.where(n_vis % 2 == 1, upper, (ranked[rows, mid - 1] + upper) / 2.0)
        threshold = np.array([self._threshold(f) for f in fits])
        limit = np.maximum(threshold, OUTLIER_MEDIAN_FACTOR * median)
        out = vis & (resid > limit[:, None])
        drop = out.any(axis=1) & (np.count_nonzero(vis & ~out, axis=1) >= self.options.min_visible_joints)
        flagged = []
        for f, o, d in zip(fits, out, drop.tolist(), strict=True):
            if d:
                f.w = f.w.copy()
                f.w[o] = 0.0
                flagged.append(f)
        return flagged

    def learned_people(self, people: Sequence[Person]) -> list[LiftResult | Failure]:
        """The prior's pose alone (``mode="learned"``) of each person, as a :class:`LiftResult`: the
        poses of all of them in one pass of the network (the prior stage), then each one's pose in
        its own body frame (right lower leg = 1) with the camera that maps it onto the prior's image
        positions; ``alpha`` its minimum-norm coefficients, ``objective`` the L1 reprojection error
        of the visible joints in the normalised units."""
        fits = [_Fitting(p, p.w, None) for p in people]
        self._prior_stage(fits, rows=False)
        out: list[LiftResult | Failure] = []
        for f in fits:
            if f.failure is None:
                assert f.prior_pose is not None
                try:
                    out.append(self._learned(f.person, f.prior_pose))
                    continue
                except Exception as err:
                    f.failure = Failure.of(err)
            out.append(f.failure)
        return out

    def _learned(self, p: Person, pose_in: NDArray[np.float64]) -> LiftResult:
        """A person's :meth:`learned_people` result from the prior's pose (12, 3, input units)."""
        x, w = p.x, p.w
        centred = pose_in - pose_in.mean(axis=0)
        flat, ok = normalise_pose_flat(np.ascontiguousarray(centred))
        if not ok or not np.all(np.isfinite(flat)):
            raise InvalidInputError("the learned prior gave a degenerate pose for this input")
        body = flat.reshape(N_JOINTS, 3)
        rot = body_frame(centred)
        leg = float(limb_lengths(centred)[RIGHT_LOWER_LEG])
        cam = Camera(np.ascontiguousarray(rot.T), leg, pose_in[:, :2].mean(axis=0))
        reproj = np.linalg.norm(x - cam.project(body), axis=1)
        vis = w > 0
        alpha = self.runs.start_alpha(centred)
        lv = np.abs(limb_lengths(body) - np.sqrt(self.model.limb_sq))
        return LiftResult(
            pose=body, pose_camera=body @ cam.rotation.T, camera=cam, alpha=alpha,
            objective=float(w @ np.abs(x - cam.project(body)).sum(axis=1)) / p.norm.spread,
            reprojection_error=float(reproj[vis].mean()), limb_violation=float(lv.max()), n_iter=0,
            converged=True, n_starts=1, start_index=-1, weights=w, total_alternations=0, prior_pose=pose_in,
            start=StartKind.LEARNED)
