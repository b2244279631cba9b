"""The hybrid and learned modes of the lifter: the learned prior's pose as L1 rows of the paper's
objective, the hybrid starts, mirrored hypothesis and outlier pass, and the prior alone.

The hybrid objective (see :mod:`pose_lifter.core.lift.lifter`) adds to the paper's
``sum_j p_j |P_j,xy - M0 y_j - t|_1 + sum_j q_j |P_j,z - m3 (y_j - mean_i y_i)|_1`` where ``P``
(12, 3) is the prior's pose for this image (:class:`pose_lifter.core.solve.pose_step.PriorRows`).
:class:`PriorFit` holds what these modes solve with (the options, the priors, the pose model and
its runs); the lifter makes one per setting.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..model.pose_model import PoseModel
from ..model.prior import PosePrior
from ..model.skeleton import N_JOINTS, RIGHT_LOWER_LEG, body_frame, limb_lengths, normalise_pose_flat
from ..numeric.fast import mean_rows, median_rows, row_norms
from ..numeric.jit import njit
from ..options import LifterOptions
from ..results import Camera, Frames, LiftResult, Normalisation, StartKind, TrackContext, WarmStart
from ..solve.pose_step import PriorRows
from .batch import PriorCall, Steps, gather
from .runs import Runs
from .starts import StartRun, Starts

__all__ = ["OUTLIER_MEDIAN_FACTOR", "PriorFit", "TargetStatus"]

#: The hybrid outlier pass flags a joint only beyond this many times the median disagreement of
#: the frame's visible joints as well as beyond ``outlier_threshold`` (under heavy Gaussian noise
#: every joint disagrees a little: the median sets the scale).
OUTLIER_MEDIAN_FACTOR = 3.0


_NO_POSE = np.zeros((N_JOINTS, 3))
_NO_WEIGHTS = np.zeros(N_JOINTS)


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
    """The prior rows' target (12, 3) of :meth:`PriorFit.rows`: the prior's ``pose`` (12, 3, input
    units) in the normalised frame (``(x - centre) / spread``, depth ``/ spread``), and with
    ``blend`` the previous frame's pose ``P`` (12, 3, same frame), its image positions moved by
    the median over the ``visible`` joints of the target's minus its own (numpy's median: the
    middle of the sorted values, or the mean of the two middle ones), blended in by
    ``temporal_weight`` ``t`` (12,) as ``(target + t P) / (1 + t)`` (when some ``t > 0``):
    numpy's operations of the code it replaces, one by one. Returns ``(target, status)``, the
    status a :class:`TargetStatus` value (an int: a compiled function boxes no enum member)."""
    nj = pose.shape[0]
    target = np.empty((nj, 3))
    for j in range(nj):
        target[j, 0] = (pose[j, 0] - centre[0]) / spread
        target[j, 1] = (pose[j, 1] - centre[1]) / spread
        target[j, 2] = pose[j, 2] / spread
    for j in range(nj):
        for a in range(3):
            if not math.isfinite(target[j, a]):
                return target, TargetStatus.NOT_FINITE.value
    if not blend:
        return target, TargetStatus.OK.value
    weighted = False
    for j in range(nj):
        weighted = weighted or temporal_weight[j] > 0
    if not weighted:
        return target, TargetStatus.OK.value
    n = 0
    for j in range(nj):
        n += visible[j]
    if n == 0:
        return target, TargetStatus.NO_JOINT.value
    d0 = np.empty(n)
    d1 = np.empty(n)
    k = 0
    for j in range(nj):
        if visible[j]:
            d0[k] = target[j, 0] - previous[j, 0]
            d1[k] = target[j, 1] - previous[j, 1]
            k += 1
    d0.sort()
    d1.sort()
    m = n // 2
    m0 = d0[m] if n % 2 else (d0[m - 1] + d0[m]) / 2.0
    m1 = d1[m] if n % 2 else (d1[m - 1] + d1[m]) / 2.0
    for j in range(nj):
        t = temporal_weight[j]
        target[j, 0] = (target[j, 0] + t * (previous[j, 0] + m0)) / (1.0 + t)
        target[j, 1] = (target[j, 1] + t * (previous[j, 1] + m1)) / (1.0 + t)
        target[j, 2] = (target[j, 2] + t * previous[j, 2]) / (1.0 + t)
    return target, TargetStatus.OK.value


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

class PriorFit:
    """The hybrid and learned modes' solve with one setting of the lifter.

    Parameters
    ----------
    options : LifterOptions
    prior : PosePrior
        The single-frame learned prior.
    temporal_prior : PosePrior or None
        The causal temporal prior of tracked frames (None: off).
    model : PoseModel
    runs : Runs
        The alternation runs of ``model`` and ``options``.
    """

    def __init__(self, options: LifterOptions, prior: PosePrior, temporal_prior: PosePrior | None,
                 model: PoseModel, runs: Runs) -> None:
        self.options, self.prior, self.temporal_prior = options, prior, temporal_prior
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
        return np.ascontiguousarray(p * np.exp(self._log_limb_mean - np.add.reduce(lp) / lp.size))  # np.mean

    def predict(self, x: NDArray[np.float64], visible: NDArray[np.bool_], past: Frames | None,
                future: Frames | None = None) -> Steps[tuple[NDArray[np.float64], PosePrior]]:
        """The prior's pose (12, 3) in input units for this frame, and the prior that gave it: the
        temporal prior when the lift has ``past`` frames, else ``prior`` (its window filled as
        :meth:`prior_input` says).

        A solve (:mod:`pose_lifter.core.lift.batch`): the pose is yielded as a
        :class:`~pose_lifter.core.lift.batch.PriorCall`, so the poses of a frame's people go through
        the network in one pass.

        Raises
        ------
        InvalidInputError
            The prior refuses the input.
        """
        prior, pts, vis = self.prior_input(x, visible, past, future)
        (pose,) = yield [PriorCall(prior, pts, vis, self.options.prior_flip)]
        if isinstance(pose, Exception):
            raise pose
        assert isinstance(pose, np.ndarray)
        return pose, prior

    def prior_input(self, x: NDArray[np.float64], visible: NDArray[np.bool_], past: Frames | None,
                    future: Frames | None = None) -> tuple[PosePrior, NDArray[np.float64], NDArray[np.bool_]]:
        """The prior :meth:`predict` runs and its input (what
        :class:`~pose_lifter.core.lift.batch.PriorCall` takes): this frame (12, 2), (12,), or a window
        (W, 12, 2), (W, 12).

        A window holds ``W - 1 - F`` frames before this one and ``F`` after it (``F`` the prior's
        :attr:`~pose_lifter.core.model.prior.PosePrior.future_frames`): the last of ``past`` and the
        first of ``future``, the missing ones padded with the oldest past frame given and the
        latest future frame given (or this frame). The temporal prior runs when ``past`` has a
        frame; otherwise a windowed ``prior`` gets this frame in every place."""
        prior = self.prior
        has_past = past is not None and len(past[0]) > 0
        if has_past and self.temporal_prior is not None:
            prior = self.temporal_prior
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

    def rows(self, x: NDArray[np.float64], w: NDArray[np.float64], norm: Normalisation, track: TrackContext,
             previous: NDArray[np.float64] | None) -> Steps[tuple[PriorRows, NDArray[np.float64]]]:
        """The prior's pose for the joints with ``w > 0`` as rows of the hybrid objective, in the
        normalised frame of ``norm``, blended with the previous frame's pose ``previous`` (12, 3,
        same frame) by the track's ``temporal_weight`` (12,); limb radii from its
        ``limb_proportions`` (``options.prior_limbs``). Returns the rows and the prior's pose in
        input units. Joints without weight take the track's ``fill`` position where it allows
        (see :class:`TrackContext`) in the prior's input. A solve (:meth:`predict`)."""
        vis = w > 0
        fill = track.fill
        if fill is not None:
            add = fill[1] & ~vis
            if add.any():
                x = np.where(add[:, None], fill[0], x)
                vis = vis | add
        pose, used = yield from self.predict(x, vis, track.past, track.future)
        tw = track.temporal_weight
        blend = previous is not None
        target, status = _target_kernel(
            pose, norm.centre, float(norm.spread), _NO_POSE if previous is None else previous,
            np.ascontiguousarray(tw, dtype=np.float64) if blend else _NO_WEIGHTS, w > 0, blend)
        if status == TargetStatus.NOT_FINITE:
            raise InvalidInputError("the learned prior gave non-finite values for this input")
        if status == TargetStatus.NO_JOINT:
            raise IndexError("no visible joint to blend the previous frame's pose by")
        o = self.options
        weights = _prior_weights(used, o.prior_weight_xy, o.prior_weight_z)
        radii = None
        if o.prior_limbs and track.limb_proportions is not None:
            radii = self.limb_radii(track.limb_proportions)
        return PriorRows(np.ascontiguousarray(target), weights, radii), pose

    def starts(self, x: NDArray[np.float64], xn: NDArray[np.float64], w: NDArray[np.float64],
               norm: Normalisation, warm: WarmStart | None, cam0: Camera | None, track: TrackContext
               ) -> Steps[Starts]:
        """The hybrid mode's starts, mirrored hypothesis and outlier pass (module docstring) on the
        2D ``x`` (12, 2, input units; ``xn`` normalised by ``norm``) with weights ``w`` (12,), the
        warm start and its camera ``cam0`` (normalised) and the track's context (its
        ``temporal_weight`` an array (12,)). A solve (:mod:`pose_lifter.core.lift.batch`): an outlier
        pass's two runs go in one round; the prior's poses are yielded too (:meth:`predict`)."""
        o, runs = self.options, self.runs
        previous = None
        if warm is not None and cam0 is not None:  # the previous frame's pose, this frame's units
            prev = self.model.pose(warm.alpha)
            previous = np.empty((N_JOINTS, 3))
            previous[:, :2] = cam0.project(prev)
            previous[:, 2] = cam0.scale * (prev - mean_rows(prev)) @ cam0.rotation[2]
        prior, prior_pose = yield from self.rows(x, w, norm, track, previous)
        a_prior = runs.start_alpha(prior.target)
        # every frame starts from the prior's pose (with the previous frame's camera when tracked):
        # the prior re-initialises the depth on every frame, so a track cannot stay in a wrong basin
        n_alt = o.hybrid_alternations
        first = yield from runs.run_steps(xn, w, a_prior, cam0, n_alt, prior=prior)
        tried = [StartRun(StartKind.PRIOR, -1, first)]
        if o.warm_flip and warm is None:
            flip = yield from runs.mirrored_run_steps(xn, w, first, prior, n_alt)
            tried.append(StartRun(StartKind.MIRRORED, -1, flip))
        total = sum(r.run.n_iter for r in tried)
        n_starts = len(tried)
        threshold = o.outlier_threshold_gated if track.gated else o.outlier_threshold
        for _ in range(o.outlier_passes if threshold > 0 else 0):
            best = min(tried, key=lambda r: r.run.objective)
            run = best.run
            cam = run.camera.camera
            # a joint disagrees with the image when it is far from the fit's projection or from
            # the prior's image position (the prior is trained with confident outliers)
            resid = np.maximum(row_norms(xn - cam.project(run.pose.pose)),
                               row_norms(xn - prior.target[:, :2]))
            vis = w > 0
            limit = max(threshold, OUTLIER_MEDIAN_FACTOR * float(median_rows(resid[vis])))
            out = vis & (resid > limit)
            if not out.any() or int(np.count_nonzero(vis & ~out)) < o.min_visible_joints:
                break
            w = w.copy()
            w[out] = 0.0
            prior, prior_pose = yield from self.rows(x, w, norm, track, previous)
            # continue the fit, and start again from the prior's new pose: the lower objective
            cont, fresh = yield from gather([
                runs.run_steps(xn, w, run.pose.alpha, cam, n_alt, prior=prior),
                runs.run_steps(xn, w, runs.start_alpha(prior.target), None, n_alt, prior=prior)])
            tried = [StartRun(best.kind, best.index, cont), StartRun(StartKind.PRIOR, -1, fresh)]
            total += cont.n_iter + fresh.n_iter
        return Starts(tried, total, n_starts, w, prior_pose)

    def learned(self, x: NDArray[np.float64], w: NDArray[np.float64], norm: Normalisation,
                past: Frames | None = None, future: Frames | None = None) -> Steps[LiftResult]:
        """The prior's pose alone (``mode="learned"``) as a :class:`LiftResult`: the pose in its
        own body frame (right lower leg = 1) with the camera that maps it onto the prior's image
        positions; ``alpha`` its minimum-norm coefficients, ``objective`` the L1 reprojection
        error of the visible joints in the normalised units. A solve (:meth:`predict`)."""
        pose_in, _ = yield from self.predict(x, w > 0, past, future)
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
            objective=float(w @ np.abs(x - cam.project(body)).sum(axis=1)) / norm.spread,
            reprojection_error=float(reproj[vis].mean()), limb_violation=float(lv.max()), n_iter=0,
            converged=True, n_starts=1, start_index=-1, weights=w, total_alternations=0, prior_pose=pose_in,
            start=StartKind.LEARNED)
