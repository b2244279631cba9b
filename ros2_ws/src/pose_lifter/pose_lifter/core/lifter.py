"""The lifter: alternation of camera and pose steps, multi-start and warm start (paper Sec. 3.3).

One solve minimises, over the coefficients ``alpha`` and a scaled-orthographic camera
``(M0, t)``::

    F = sum_j w_j rho(x_j - M0 y_j - t) + theta ||alpha||_1,   y = mu + B alpha,
    subject to ||C_i y||^2 = L_i (i = 1..8)

by alternating the camera step and the pose step from a start pose until the relative
decrease of ``F`` falls below ``alternation_tol`` or ``max_alternations`` is reached. Cold
solves try ``n_starts`` starts (the mean pose, then k-means centres of the training poses)
and keep the lowest ``F``; a warm start (previous frame of the same person) replaces them.

Modes (``options.mode``). ``"paper"`` is the above. ``"learned"`` returns the learned prior's pose
(:mod:`.prior`) alone. ``"hybrid"`` (the default) keeps the prior in the objective::

    F = sum_j w_j |x_j - M0 y_j - t|_1 + theta ||alpha||_1
        + sum_j p_j |P_j,xy - M0 y_j - t|_1 + sum_j q_j |P_j,z - m3 (y_j - mean_i y_i)|_1,
    subject to ||C_i y||^2 = L_i,   y = mu + B alpha,   m3 = s r1 x r2,

where ``P`` (12, 3) is the prior's pose for this image (its image positions and relative depths,
missing joints included) and ``p_j = prior_weight_xy / e_j,xy``, ``q_j = prior_weight_z / e_j,z``
with ``e`` the prior's per-joint error relative to its mean (``PosePrior.abs_error``). The pose
step minimises ``F`` exactly as the paper's (the prior terms are further L1 rows of its ADM,
:class:`.pose_step.PriorRows`); the camera step minimises all but the depth term (the camera ADM of the
paper on the 2D plus the prior's image positions) and every alternation keeps the lowest ``F``.
Starts: every frame starts from the prior's pose (with the warm start's camera when tracked; the
warm pose competes only with ``warm_competes``), ``hybrid_alternations`` alternations per run;
the depth-mirrored hypothesis is scored on cold solves (and warm ones with ``hybrid_flip_warm``).
Then up to ``outlier_passes`` outlier passes: visible joints farther than ``outlier_threshold``
(and ``OUTLIER_MEDIAN_FACTOR`` times the frame's median) from the fit's projection or from the
prior's image position get weight 0, the prior is re-run without them and the fit is continued
and restarted from the prior's new pose (the lower objective kept), so a confidently wrong
detection does not drag the depth. Tracked frames come screened by the per-track policy
(:mod:`.tracking`: a joint that jumped is missing; a missing joint's prior target takes the previous
frame's pose, ``temporal_weight`` per joint).

Input normalisation: the 2D points are centred on the weighted centroid of the visible joints
and divided by their RMS spread over that of the mean pose, so ``theta`` and the tolerances
mean the same at any image size. Results are mapped back to input units.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._fast import median_rows
from ._jit import njit
from .alpha.lifted_admm import QStepFn
from .bases import PoseBases, default_bases_path
from .camera import camera_step_trusted
from .errors import InvalidInputError, OptionsError, SolverError, TooFewJointsError
from .options import LifterOptions
from .pose_model import LiftedConstraints, PoseModel
from .pose_step import PriorRows, pose_step
from .prior import DEFAULT_TEMPORAL_PRIOR_PATH, PosePrior
from .results import Alternation, Camera, CameraResult, LiftResult, PoseResult, SolveInfo, WarmStart
from .skeleton import (
    ANTHROPOMETRIC_PROPORTIONS,
    LEFT_LIMBS,
    LIMB_GROUP_OF,
    N_JOINTS,
    RIGHT_LIMBS,
    RIGHT_LOWER_LEG,
    body_frame,
    limb_lengths,
    normalise_pose_flat,
)
from .validation import check_keypoints

__all__ = ["OUTLIER_MEDIAN_FACTOR", "Lifter", "TrackContext"]

#: Relative cut-off of the bases' singular values in the minimum-norm coefficients of a start
#: pose (:func:`_mirror_kernel`, a pseudo-inverse): the packaged bases' smallest singular value is
#: 2.5e-7 of the largest (the next 2.6e-2); dividing by it gave the prior's poses (not in the
#: bases' span) coefficients with ||alpha||_1 ~ 2e5: their pose was right but ``theta ||alpha||_1``
#: dominated the objective. It also moves the paper's mirrored warm start slightly.
PINV_RCOND = 1e-3

#: The hybrid outlier pass flags a joint only beyond this many times the median disagreement of
#: the frame's visible joints as well as beyond ``outlier_threshold`` (under heavy Gaussian noise
#: every joint disagrees a little: the median sets the scale).
OUTLIER_MEDIAN_FACTOR = 3.0



@dataclass(frozen=True)
class _Normalisation:
    centre: NDArray[np.float64]
    spread: float


@dataclass(frozen=True)
class TrackContext:
    """What a track knows about this frame of its person (:class:`pose_lifter.core.tracking.TrackPolicy`
    fills it; every field is optional). Used by the hybrid mode; the learned mode reads ``past``.

    Attributes
    ----------
    limb_proportions : ndarray, shape (8,), optional
        The person's limb proportions (the track's estimate over its frames), used for the limb
        constraints with ``options.prior_limbs``.
    data_weight : float
        Factor on the 2D term's weights, in (0, 1] (the track's estimate of its detector's noise).
    temporal_weight : float or ndarray, shape (12,)
        With a warm start: weight ``w`` (per joint, or one for all) of the warm start's pose ``Y``
        in the prior term's target ``(P + w Y) / (1 + w)``, ``Y``'s image positions moved by the
        median motion of the visible joints since it (0: none; the policy sets it from the track's
        2D noise, up to ``options.temporal_weight``, and to ``options.missing_temporal_weight`` for
        joints missing in this frame).
    past : (ndarray (k, 12, 2), ndarray of bool (k, 12)), optional
        The track's previous frames (oldest first, evenly spaced up to this one) and which of
        their joints were used: the input of a temporal prior (``PosePrior.window > 1``; missing
        history is padded with the oldest frame given, or this one). Ignored by a single-frame
        prior.
    gated : bool
        The frame was screened by the per-track outlier gate; the outlier pass then uses
        ``options.outlier_threshold_gated`` instead of ``options.outlier_threshold``.
    fill : (ndarray (12, 2), ndarray of bool (12,)), optional
        Predicted image positions of the joints (input units) and which of them may stand in for
        a joint this frame lacks (missing: low confidence or non-finite) in the learned prior's
        input; the 2D fit still ignores such a joint. A joint the outlier pass flags is not
        filled: it disagreed with the fit or the prior on this frame (filled or not, the held-out
        figures agreed within 0.2 mm).
    """

    limb_proportions: NDArray[np.float64] | None = None
    data_weight: float = 1.0
    temporal_weight: float | NDArray[np.float64] = 0.0
    past: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None
    gated: bool = False
    fill: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None


_NO_TRACK = TrackContext()


@dataclass(frozen=True)
class _Run:
    """A run of alternations from one start: its best alternation's steps and objective, the ADM
    multipliers it ended with (``options.warm_duals``) and its alternations' history."""

    pose: PoseResult
    camera: CameraResult
    objective: float
    n_iter: int
    converged: bool
    history: tuple[Alternation, ...] = ()


@njit
def _mirror_kernel(pose: NDArray[np.float64], rot: NDArray[np.float64], mean: NDArray[np.float64],
                   u: NDArray[np.float64], sig: NDArray[np.float64], v: NDArray[np.float64], flip: bool = True
                   ) -> tuple[NDArray[np.float64], bool]:
    """``V ((U^T (normalise_pose(mirror(pose)) - mu)) / S)`` for one pose (12, 3): the pose in
    the camera frame (``rot`` (3, 3)) with its depth reflected, normalised into its own body
    frame (:func:`normalise_pose_flat`), then minimum-norm coefficients through the bases' SVD.
    ``flip`` False: the pose as it is (the hybrid mode's start from the prior's pose).
    Returns ``(alpha (k,), ok)``; ``ok`` is False for a degenerate leg or body frame."""
    n = pose.shape[0]
    cp = np.empty((n, 3))
    for j in range(n):
        for a in range(3):
            cp[j, a] = pose[j, 0] * rot[a, 0] + pose[j, 1] * rot[a, 1] + pose[j, 2] * rot[a, 2]
        if flip:
            cp[j, 2] = -cp[j, 2]
    body, ok = normalise_pose_flat(cp)
    k = v.shape[0]
    alpha = np.zeros(k)
    if not ok:
        return alpha, False
    for i in range(3 * n):
        body[i] -= mean[i]
    for j in range(sig.size):
        if sig[j] <= PINV_RCOND * sig[0]:  # the pseudo-inverse: (numerically) null directions add nothing
            continue
        c = 0.0
        for i in range(3 * n):
            c += u[i, j] * body[i]
        c /= sig[j]
        ok = ok and math.isfinite(c)
        for i in range(k):
            alpha[i] += v[i, j] * c
    return alpha, ok


class Lifter:
    """Lift 2D keypoints (12 model joints) to a 3D pose and a weak-perspective camera.

    Parameters
    ----------
    bases : PoseBases or None
        None loads the packaged basis file of ``options.mode``
        (:func:`pose_lifter.core.bases.default_bases_path`).
    options : LifterOptions or None
    prior, temporal_prior : PosePrior or None
        The learned priors (None: loaded from ``options.prior_file`` /
        ``options.temporal_prior_file`` on first use).
    """

    def __init__(self, bases: PoseBases | None = None, options: LifterOptions | None = None,
                 prior: PosePrior | None = None, temporal_prior: PosePrior | None = None) -> None:
        self._options = options if options is not None else LifterOptions()
        self.bases = bases if bases is not None else PoseBases.load(default_bases_path(self._options.mode))
        self._prior: PosePrior | None = prior
        self._prior_key: str | None = None if prior is None else self._options.prior_file
        self._temporal: PosePrior | None = temporal_prior
        self._temporal_key: str | None = None if temporal_prior is None else self._options.temporal_prior_file
        self._prior_rel: dict[int, tuple[PosePrior, NDArray[np.float64]]] = {}
        self._model: PoseModel | None = None
        self._model_key: str | None = None
        mp = self.bases.mean_pose
        self._mean_spread = float(np.sqrt(np.mean(np.sum((mp[:, :2] - mp[:, :2].mean(0)) ** 2, axis=1))))
        self._build()

    @property
    def options(self) -> LifterOptions:
        """Current options; assign a new :class:`LifterOptions` to change them."""
        return self._options

    @options.setter
    def options(self, value: LifterOptions) -> None:
        value.validate()
        self._options = value
        self._build()

    @property
    def prior(self) -> PosePrior:
        """The learned prior (loaded from ``options.prior_file`` on first use)."""
        if self._prior is None or self._prior_key != self._options.prior_file:
            self._prior = PosePrior.load(self._options.prior_file or None)
            self._prior_key = self._options.prior_file
        return self._prior

    @property
    def temporal_prior(self) -> PosePrior | None:
        """The causal temporal prior used on tracked frames (``options.temporal_prior``; loaded from
        ``options.temporal_prior_file`` on first use), or None when it is off."""
        if not self._options.temporal_prior:
            return None
        if self._temporal is None or self._temporal_key != self._options.temporal_prior_file:
            self._temporal = PosePrior.load(self._options.temporal_prior_file or DEFAULT_TEMPORAL_PRIOR_PATH)
            self._temporal_key = self._options.temporal_prior_file
        return self._temporal

    def _prior_relative_weights(self, prior: PosePrior) -> NDArray[np.float64]:
        """(12, 2): per joint, the inverse of ``prior``'s error relative to its mean, for the
        image-position rows (x and y averaged) and the depth row."""
        entry = self._prior_rel.get(id(prior))
        if entry is None or entry[0] is not prior:  # (an id can be reused after a reload)
            e = prior.abs_error
            exy = e[:, :2].mean(axis=1)
            entry = self._prior_rel[id(prior)] = (prior, np.column_stack([exy.mean() / exy,
                                                                          e[:, 2].mean() / e[:, 2]]))
        return entry[1]

    @property
    def model(self) -> PoseModel:
        """Precomputed pose-step data of the current bases and limb targets."""
        assert self._model is not None
        return self._model

    def _build(self) -> None:
        key = self._options.limb_proportions
        if self._model is None or self._model_key != key:
            props = self.bases.limb_proportions if key == "bases" else ANTHROPOMETRIC_PROPORTIONS
            self._model = PoseModel.build(self.bases, props)
            self._model_key = key
        self._qstep_fn: QStepFn | None = None
        if self._options.mode != "paper":
            _ = self.prior, self.temporal_prior  # load (and validate) the priors now, not on the first frame
            if self._options.mode == "hybrid" and (self._options.alpha_solver != "riemannian"
                                                   or not self._options.method.limbs
                                                   or self.model.limb_coordinates is None):
                raise OptionsError("mode 'hybrid' needs alpha_solver='riemannian', a variant with limb "
                                   "constraints and bases with >= 24 independent directions")
        if self._options.pose_solver == "cvxpy":
            from .reference import reference_qstep

            def _q(w: NDArray[np.float64], cons: LiftedConstraints, p: NDArray[np.float64],
                   g: NDArray[np.float64], delta: float) -> NDArray[np.float64]:
                return np.asarray(reference_qstep(w, cons.omegas, p, g, delta))

            self._qstep_fn = _q

    # ------------------------------------------------------------------ helpers
    def _weights(self, points: NDArray[np.float64], confidence: NDArray[np.float64] | None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        x, conf = check_keypoints(points, confidence)
        w = np.where(conf >= self._options.confidence_threshold, np.clip(conf, 0.0, 1.0), 0.0)
        # a joint with non-finite coordinates is missing, whatever its confidence
        bad = ~np.all(np.isfinite(x), axis=1)
        w[bad] = 0.0
        n_vis = int(np.count_nonzero(w > 0))
        if n_vis < self._options.min_visible_joints:
            raise TooFewJointsError(
                f"{n_vis} joints visible (confidence >= {self._options.confidence_threshold}); "
                f"at least {self._options.min_visible_joints} needed"
            )
        x = np.where(bad[:, None], 0.0, x)
        return x, w

    def _normalise(self, x: NDArray[np.float64], w: NDArray[np.float64]) -> _Normalisation:
        centre = w @ x / w.sum()
        spread = float(np.sqrt(w @ np.sum((x - centre) ** 2, axis=1) / w.sum()))
        if not np.isfinite(spread) or spread <= 1e-9 * max(1.0, float(np.abs(centre).max())):
            raise InvalidInputError("the visible keypoints are (almost) all at one point")
        return _Normalisation(centre, spread / self._mean_spread)

    @staticmethod
    def _camera_data(xn: NDArray[np.float64], w: NDArray[np.float64], prior: PriorRows | None
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
        """The camera step's 2D points and weights for a run: with a prior term, the prior's
        image positions are further (pose joint, 2D point) pairs of the L1 fit (then the pose is
        stacked twice, the returned flag). Built once per run, not per alternation."""
        if prior is not None and np.any(prior.weights[:, 0] > 0):
            return (np.ascontiguousarray(np.vstack([xn, prior.target[:, :2]])),
                    np.ascontiguousarray(np.concatenate([w, prior.weights[:, 0]])), True)
        return xn, w, False

    def _camera(self, data: tuple[NDArray[np.float64], NDArray[np.float64], bool], pose: NDArray[np.float64],
                init: Camera | None, last: CameraResult | None = None) -> CameraResult:
        o = self._options
        xn, w, doubled = data
        if doubled:
            pose = np.concatenate([pose, pose])
        if o.camera_solver == "cvxpy":
            from .reference import reference_camera

            cam, obj = reference_camera(xn, pose, w, o.method.loss,
                                        rotation_init=None if init is None else init.rotation)
            return CameraResult(objective=float(obj), n_iter=1, converged=True, camera=cam)
        duals = last.duals if last is not None and o.warm_duals else None
        # inputs checked once per lift (finite, shapes, >= min_visible_joints weights)
        return camera_step_trusted(xn, pose, w, o.method.loss, init, o.camera_max_iter, o.camera_tol, o.tau,
                                   duals)

    def _pose(self, xn: NDArray[np.float64], cam: Camera, w: NDArray[np.float64],
              alpha0: NDArray[np.float64], last: PoseResult | None = None,
              max_iter: int | None = None, prior: PriorRows | None = None) -> PoseResult:
        o = self._options
        return pose_step(
            xn, cam.projection, cam.translation, w, self.model, o.method, o.theta, alpha0,
            max_iter=max_iter if max_iter is not None else (o.pose_max_iter if prior is None
                                                             else o.hybrid_pose_max_iter),
            tol=o.pose_tol, eta=o.eta,
            eta_growth=o.eta_growth, delta=o.delta,
            inner_max_iter=o.inner_max_iter, inner_tol=o.inner_tol, alpha_step=o.alpha_step,
            alpha_solver=o.alpha_solver, qstep_fn=self._qstep_fn,
            duals=last.duals if last is not None and o.warm_duals else None,
            newton_tol=o.newton_tol, alpha_prox=o.alpha_prox, prior=prior,
        )

    def _run(self, xn: NDArray[np.float64], w: NDArray[np.float64], alpha0: NDArray[np.float64],
             cam0: Camera | None, max_alternations: int | None = None, start: _Run | None = None,
             pose_max_iter: int | None = None, prior: PriorRows | None = None) -> _Run:
        """Alternate camera and pose steps from ``alpha0`` (and optionally a camera), or
        continue a previous run ``start``. With ``options.warm_duals`` the ADM multipliers of both
        steps are carried from one alternation to the next. The run keeps its lowest-objective
        alternation (the hybrid objective adds the prior's depth rows to the camera step's)."""
        o = self._options
        n_alt = o.max_alternations if max_alternations is None else max_alternations
        data = self._camera_data(xn, w, prior)
        last_pose: PoseResult | None
        if start is not None:
            alpha, cam, best, prev = start.pose.alpha, start.camera, start, start.objective
            it0, last_pose, history = start.n_iter, start.pose, list(start.history)
        else:
            alpha = alpha0
            cam = self._camera(data, self.model.pose(alpha), cam0)
            best, prev, it0, last_pose, history = None, np.inf, 0, None, []
        converged = False
        it = it0
        th = o.theta if o.method.sparsity else 0.0
        for it in range(it0 + 1, n_alt + 1):
            pres = self._pose(xn, cam.camera, w, alpha, last_pose, pose_max_iter, prior)
            alpha, last_pose = pres.alpha, pres
            cam = self._camera(data, pres.pose, cam.camera, cam)
            obj = cam.objective + th * float(np.sum(np.abs(alpha)))
            if prior is not None:
                obj += prior.depth_term(pres.pose, cam.camera.projection)
            history.append(Alternation(obj, SolveInfo(cam.objective, cam.n_iter, cam.converged),
                                       SolveInfo(pres.objective, pres.n_iter, pres.converged)))
            if best is None or obj < best.objective:
                best = _Run(pres, cam, obj, it, False, tuple(history))
            if prev - obj <= o.alternation_tol * max(abs(prev), 1e-12) and np.isfinite(prev):
                converged = True
                break
            prev = obj
        assert best is not None
        return _Run(best.pose, best.camera, best.objective, it, converged, tuple(history))

    def _mirrored_alpha(self, run: _Run) -> NDArray[np.float64]:
        """Coefficients of the depth-mirrored pose of a run (same projection, depth reflected),
        re-expressed in its own body frame (:func:`normalise_pose`); minimum-norm coefficients
        through the bases' SVD."""
        m = self.model
        alpha, ok = _mirror_kernel(np.ascontiguousarray(run.pose.pose), run.camera.camera.rotation, m.mean,
                                   m.u, m.sig, m.v)
        if not ok:
            raise InvalidInputError("a pose has a degenerate right lower leg")
        return alpha

    # ------------------------------------------------------------------ public
    def warm_up(self) -> float:
        """Run the solver once (a cold and a warm lift of the mean pose seen from the side) so
        that compiled kernels (numba, see ``core._jit``) are compiled or loaded from their cache
        now rather than on the first real frame. Returns the seconds it took."""
        t0 = time.perf_counter()
        mean = self.bases.mean_pose
        side = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # a profile view, y down
        points = 100.0 * mean @ side.T + np.array([320.0, 240.0])
        first = self.lift(points)
        self.lift(points + 1.0, warm=first.warm_start())
        return time.perf_counter() - t0

    def lift(
        self,
        points_2d: NDArray[np.float64],
        confidence: NDArray[np.float64] | None = None,
        warm: WarmStart | None = None,
        track: TrackContext | None = None,
    ) -> LiftResult:
        """Lift one skeleton.

        Parameters
        ----------
        points_2d : ndarray, shape (12, 2)
            Image coordinates of the 12 model joints (any consistent unit, e.g. pixels;
            image y pointing down gives a camera frame with y down, z forward).
        confidence : ndarray, shape (12,), optional
            Per-joint confidence; below ``options.confidence_threshold`` = missing.
            Non-finite coordinates also count as missing.
        warm : WarmStart, optional
            Previous solution of the same person: a single start from it replaces the
            multi-start (hybrid: its camera starts the prior's pose; see
            ``TrackContext.temporal_weight``).
        track : TrackContext, optional
            What the person's track knows of this frame (hybrid and learned modes; the per-track
            policy, :class:`pose_lifter.core.tracking.TrackPolicy`, fills it).

        Returns
        -------
        LiftResult

        Raises
        ------
        InvalidInputError, TooFewJointsError
            Bad input (shapes, too few visible joints, a bad ``track`` field).
        SolverError
            The solve diverged on valid input.
        """
        tc = _NO_TRACK if track is None else track
        limb_proportions, data_weight = tc.limb_proportions, tc.data_weight
        temporal_weight, past, gated, fill = tc.temporal_weight, tc.past, tc.gated, tc.fill
        x, w = self._weights(points_2d, confidence)
        norm = self._normalise(x, w)
        mode = self._options.mode
        if past is not None:
            pp, pv = np.asarray(past[0], dtype=np.float64), np.asarray(past[1], dtype=bool)
            if pp.ndim != 3 or pp.shape[1:] != (N_JOINTS, 2) or pv.shape != pp.shape[:2]:
                raise InvalidInputError(f"past must be ((k, {N_JOINTS}, 2), (k, {N_JOINTS})), got "
                                        f"{pp.shape} and {pv.shape}")
            past = (pp, pv & np.all(np.isfinite(pp), axis=-1))
        if fill is not None:
            fp, fv = np.asarray(fill[0], dtype=np.float64), np.asarray(fill[1], dtype=bool)
            if fp.shape != (N_JOINTS, 2) or fv.shape != (N_JOINTS,):
                raise InvalidInputError(f"fill must be (({N_JOINTS}, 2), ({N_JOINTS},)), got {fp.shape} "
                                        f"and {fv.shape}")
            # only for the joints this frame lacks: one the outlier pass flags stays missing
            fill = (fp, fv & np.all(np.isfinite(fp), axis=-1) & ~(w > 0))
        if mode == "learned":
            return self._lift_learned(x, w, norm, past)
        xn = (x - norm.centre) / norm.spread
        cam0: Camera | None = None
        if warm is not None:
            if warm.alpha.shape != (self.bases.n_bases,):
                raise InvalidInputError("warm start alpha does not match the bases")
            cam0 = Camera(warm.camera.rotation, warm.camera.scale / norm.spread,
                          (warm.camera.translation - norm.centre) / norm.spread)
        if mode == "hybrid":
            if not 0.0 < data_weight <= 1.0:
                raise InvalidInputError(f"data_weight must be in (0, 1], got {data_weight!r}")
            tw = np.broadcast_to(np.asarray(temporal_weight, dtype=np.float64), (N_JOINTS,)).copy()
            if not np.all((tw >= 0.0) & (tw <= 1e3)):
                raise InvalidInputError(f"temporal_weight must be in [0, 1000], got {temporal_weight!r}")
            runs, total, n_starts, w, prior_pose = self._hybrid_runs(x, xn, w * data_weight, norm, warm,
                                                                      cam0, limb_proportions, tw, past,
                                                                      gated, fill)
            w = w / data_weight
        else:
            runs, total, n_starts = self._paper_runs(xn, w, warm, cam0)
            prior_pose = None
        idx, run = min(runs, key=lambda r: r[1].objective)
        return self._result(x, w, norm, idx, run, n_starts, total, prior_pose)

    def _paper_runs(self, xn: NDArray[np.float64], w: NDArray[np.float64], warm: WarmStart | None,
                    cam0: Camera | None) -> tuple[list[tuple[int, _Run]], int, int]:
        """The paper's starts: the warm start and its mirrored copy, or the screened multi-start.
        Returns ``(runs as (start index, run), total alternations, starts tried)``."""
        if warm is not None:
            runs = [(-1, self._run(xn, w, warm.alpha, cam0))]
            if self._options.warm_flip:
                runs.append((-2, self._mirrored_run(xn, w, runs[0][1], None)))
            return runs, sum(r.n_iter for _, r in runs), len(runs)
        starts = self.bases.with_starts(self._options.n_starts)
        # a short first pose step only when it screens (some starts are then dropped)
        screen = self._options.screen_pose_max_iter if len(starts) > self._options.n_refine else None
        runs = [(i, self._run(xn, w, a, None, max_alternations=1, pose_max_iter=screen))
                for i, a in enumerate(starts)]
        n_screened = len(runs)
        if len(runs) > 1:  # screen: continue only the most promising starts
            runs.sort(key=lambda r: r[1].objective)
            runs = runs[: self._options.n_refine]
        runs = [(i, self._run(xn, w, r.pose.alpha, None, start=r)) for i, r in runs]
        # a continued run's n_iter counts its screening alternation too
        return runs, n_screened - len(runs) + sum(r.n_iter for _, r in runs), len(starts)

    def _mirrored_run(self, xn: NDArray[np.float64], w: NDArray[np.float64], run: _Run,
                      prior: PriorRows | None, max_alternations: int | None = None) -> _Run:
        """The depth-mirrored copy of ``run`` as a start: screened by one alternation and continued
        when it already beats ``run`` (``warm_flip_screen``), or run to convergence."""
        mirrored = self._mirrored_alpha(run)
        if self._options.warm_flip_screen:
            # hybrid: a short screening pose step, as for the paper's cold starts
            short = None if prior is None else self._options.screen_pose_max_iter
            flip = self._run(xn, w, mirrored, None, max_alternations=1, prior=prior, pose_max_iter=short)
            if flip.objective < run.objective:
                flip = self._run(xn, w, flip.pose.alpha, None, max_alternations, start=flip, prior=prior)
            return flip
        return self._run(xn, w, mirrored, None, max_alternations, prior=prior)

    def _prior_rows(self, x: NDArray[np.float64], w: NDArray[np.float64], norm: _Normalisation,
                    limb_proportions: NDArray[np.float64] | None = None,
                    previous: NDArray[np.float64] | None = None,
                    temporal_weight: NDArray[np.float64] | None = None,
                    past: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None,
                    fill: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None
                    ) -> tuple[PriorRows, NDArray[np.float64]]:
        """The prior's pose for the joints with ``w > 0`` as rows of the hybrid objective, in the
        normalised frame of ``norm``, blended with the previous frame's pose ``previous`` (12, 3,
        same frame) by ``temporal_weight``; limb radii from ``limb_proportions`` (a
        track's estimate, ``options.prior_limbs``). Returns the rows and the prior's pose in
        input units. Joints without weight take ``fill``'s position where it allows (see
        :meth:`lift`) in the prior's input."""
        vis = w > 0
        if fill is not None:
            add = fill[1] & ~vis
            if np.any(add):
                x = np.where(add[:, None], fill[0], x)
                vis = vis | add
        pose, used = self._predict_prior(x, vis, past)
        target = np.empty((N_JOINTS, 3))
        target[:, :2] = (pose[:, :2] - norm.centre) / norm.spread
        target[:, 2] = pose[:, 2] / norm.spread
        if not np.all(np.isfinite(target)):
            raise InvalidInputError("the learned prior gave non-finite values for this input")
        if previous is not None and temporal_weight is not None and np.any(temporal_weight > 0):
            prev = previous.copy()
            vis = w > 0
            # the person's image motion since the previous frame (the median over visible joints)
            prev[:, :2] += median_rows(target[vis, :2] - prev[vis, :2])
            tw = temporal_weight[:, None]
            target = (target + tw * prev) / (1.0 + tw)
        rel = self._prior_relative_weights(used)
        o = self._options
        weights = np.column_stack([o.prior_weight_xy * rel[:, 0], o.prior_weight_z * rel[:, 1]])
        radii = None
        if o.prior_limbs and limb_proportions is not None:
            radii = self.limb_radii(limb_proportions)
        return PriorRows(np.ascontiguousarray(target), np.ascontiguousarray(weights), radii), pose

    def _predict_prior(self, x: NDArray[np.float64], visible: NDArray[np.bool_],
                       past: tuple[NDArray[np.float64], NDArray[np.bool_]] | None
                       ) -> tuple[NDArray[np.float64], PosePrior]:
        """The prior's pose (12, 3) in input units for this frame, and the prior that gave it: the
        temporal prior when the lift has ``past`` frames (padded to its window with the oldest
        one given), else ``prior`` (a windowed ``prior`` gets this frame repeated)."""
        prior = self.prior
        temporal = self.temporal_prior
        if past is not None and len(past[0]) > 0 and temporal is not None:
            prior = temporal
        if prior.window == 1:
            return prior.predict(x, visible), prior
        k = prior.window - 1
        pts = np.empty((prior.window, N_JOINTS, 2))
        vis = np.empty((prior.window, N_JOINTS), dtype=bool)
        n_past = 0 if past is None else len(past[0])
        for i in range(k):
            j = max(n_past - k + i, 0)
            if past is not None and n_past > 0:
                pts[i], vis[i] = past[0][j], past[1][j]
            else:
                pts[i], vis[i] = x, visible
        pts[k], vis[k] = x, visible
        return prior.predict(np.where(vis[..., None], pts, 0.0), vis), prior

    def input_scale(self, points: NDArray[np.float64], weights: NDArray[np.float64]) -> float:
        """The unit of the lifter's normalised 2D for these points (12, 2) and weights (12,): their
        weighted RMS spread over the mean pose's (see the module docstring)."""
        x = np.where((weights > 0)[:, None], np.asarray(points, dtype=np.float64), 0.0)
        return self._normalise(x, np.asarray(weights, dtype=np.float64)).spread

    @staticmethod
    def limb_proportions_of(pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """A person's limb proportions from a 3D pose (12, 3): the 8 limb lengths with each
        left/right pair averaged (bones are symmetric; it halves the noise of an estimate),
        shape (8,), in the pose's units."""
        lengths = limb_lengths(pose)
        pairs = 0.5 * (lengths[list(LEFT_LIMBS)] + lengths[list(RIGHT_LIMBS)])
        return np.asarray(pairs[list(LIMB_GROUP_OF)])

    def limb_radii(self, proportions: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Limb-constraint radii (8,) with the ratios of ``proportions`` and the geometric-mean
        size of the model's own limbs (so the person keeps the bases' scale); None when the
        proportions are unusable (non-finite or not positive)."""
        p = np.asarray(proportions, dtype=np.float64)
        if p.shape != (8,) or not np.all(np.isfinite(p)) or np.any(p <= 0):
            return None
        own = np.sqrt(self.model.limb_sq)
        return np.ascontiguousarray(p * np.exp(np.mean(np.log(own)) - np.mean(np.log(p))))

    def _start_alpha(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Minimum-norm coefficients of a camera-frame pose (12, 3) in its own body frame (zeros,
        the mean pose, for a degenerate pose)."""
        m = self.model
        alpha, ok = _mirror_kernel(np.ascontiguousarray(pose), np.eye(3), m.mean, m.u, m.sig, m.v, False)
        return alpha if ok else np.zeros(self.bases.n_bases)

    def _hybrid_runs(self, x: NDArray[np.float64], xn: NDArray[np.float64], w: NDArray[np.float64],
                     norm: _Normalisation, warm: WarmStart | None, cam0: Camera | None,
                     limb_proportions: NDArray[np.float64] | None, temporal_weight: NDArray[np.float64],
                     past: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None, gated: bool = False,
                     fill: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None
                     ) -> tuple[list[tuple[int, _Run]], int, int, NDArray[np.float64], NDArray[np.float64]]:
        """The hybrid mode's starts, mirrored hypothesis and outlier pass (module docstring).
        Returns ``(runs, total alternations, starts tried, weights after the outlier pass, the
        prior's pose in input units)``."""
        o = self._options
        previous = None
        if warm is not None and cam0 is not None:  # the previous frame's pose, this frame's units
            prev = self.model.pose(warm.alpha)
            previous = np.column_stack([cam0.project(prev),
                                        cam0.scale * (prev - prev.mean(axis=0)) @ cam0.rotation[2]])
        prior, prior_pose = self._prior_rows(x, w, norm, limb_proportions, previous, temporal_weight, past,
                                             fill)
        a_prior = self._start_alpha(prior.target)
        # every frame starts from the prior's pose (with the previous frame's camera when tracked):
        # the prior re-initialises the depth on every frame, so a track cannot stay in a wrong basin
        n_alt = o.hybrid_alternations
        runs: list[tuple[int, _Run]] = [(-3, self._run(xn, w, a_prior, cam0, n_alt, prior=prior))]
        if warm is not None and o.warm_competes:
            wr = self._run(xn, w, warm.alpha, cam0, max_alternations=1, prior=prior,
                           pose_max_iter=o.screen_pose_max_iter)
            if wr.objective < runs[0][1].objective:
                wr = self._run(xn, w, wr.pose.alpha, None, n_alt, start=wr, prior=prior)
            runs.append((-1, wr))
        if o.warm_flip and (warm is None or o.hybrid_flip_warm):
            best = min(runs, key=lambda r: r[1].objective)[1]
            runs.append((-2, self._mirrored_run(xn, w, best, prior, n_alt)))
        total = sum(r.n_iter for _, r in runs)
        n_starts = len(runs)
        threshold = o.outlier_threshold_gated if gated else o.outlier_threshold
        for _ in range(o.outlier_passes if threshold > 0 else 0):
            idx, run = min(runs, key=lambda r: r[1].objective)
            cam = run.camera.camera
            # a joint disagrees with the image when it is far from the fit's projection or from
            # the prior's image position (the prior is trained with confident outliers)
            resid = np.maximum(np.linalg.norm(xn - cam.project(run.pose.pose), axis=1),
                               np.linalg.norm(xn - prior.target[:, :2], axis=1))
            vis = w > 0
            limit = max(threshold, OUTLIER_MEDIAN_FACTOR * float(median_rows(resid[vis])))
            out = vis & (resid > limit)
            if not np.any(out) or int(np.count_nonzero(vis & ~out)) < o.min_visible_joints:
                break
            w = w.copy()
            w[out] = 0.0
            prior, prior_pose = self._prior_rows(x, w, norm, limb_proportions, previous, temporal_weight,
                                                 past, fill)
            # continue the fit, and start again from the prior's new pose: the lower objective
            cont = self._run(xn, w, run.pose.alpha, cam, n_alt, prior=prior)
            fresh = self._run(xn, w, self._start_alpha(prior.target), None, n_alt, prior=prior)
            runs = [(idx, cont), (-3, fresh)]
            total += cont.n_iter + fresh.n_iter
        return runs, total, n_starts, w, prior_pose

    def _lift_learned(self, x: NDArray[np.float64], w: NDArray[np.float64], norm: _Normalisation,
                      past: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None) -> LiftResult:
        """The prior's pose alone (``mode="learned"``) as a :class:`LiftResult`: the pose in its
        own body frame (right lower leg = 1) with the camera that maps it onto the prior's image
        positions; ``alpha`` its minimum-norm coefficients, ``objective`` the L1 reprojection
        error of the visible joints in the normalised units."""
        pose_in, _ = self._predict_prior(x, w > 0, past)
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
        alpha = self._start_alpha(centred)
        lv = np.abs(limb_lengths(body) - np.sqrt(self.model.limb_sq))
        return LiftResult(
            pose=body, pose_camera=body @ cam.rotation.T, camera=cam, alpha=alpha,
            objective=float(w @ np.abs(x - cam.project(body)).sum(axis=1)) / norm.spread,
            reprojection_error=float(reproj[vis].mean()), limb_violation=float(lv.max()), n_iter=0,
            converged=True, n_starts=1, start_index=-4, weights=w, total_alternations=0, prior_pose=pose_in)

    def _result(self, x: NDArray[np.float64], w: NDArray[np.float64], norm: _Normalisation, idx: int,
                run: _Run, n_starts: int, total: int, prior_pose: NDArray[np.float64] | None) -> LiftResult:
        """The winning run mapped back to input units, checked finite."""
        cam_n = run.camera.camera
        cam = Camera(cam_n.rotation, cam_n.scale * norm.spread, norm.centre + norm.spread * cam_n.translation)
        pose = run.pose.pose
        pose_c = pose - pose.mean(axis=0)
        reproj = np.linalg.norm(x - cam.project(pose), axis=1)
        vis = w > 0
        result = LiftResult(
            pose=pose,
            pose_camera=pose_c @ cam.rotation.T,
            camera=cam,
            alpha=run.pose.alpha,
            objective=run.objective,
            reprojection_error=float(reproj[vis].mean()),
            limb_violation=run.pose.limb_violation,
            n_iter=run.n_iter,
            converged=run.converged,
            n_starts=n_starts,
            start_index=idx,
            weights=w,
            total_alternations=total,
            prior_pose=prior_pose,
            history=run.history,
        )
        for arr in (result.pose, result.alpha, result.camera.rotation, result.camera.translation):
            if not np.all(np.isfinite(arr)):
                raise SolverError("the solve produced non-finite values for this input")
        return result

    def lift_many(
        self,
        points_2d: NDArray[np.float64],
        confidence: NDArray[np.float64] | None = None,
        warm_start: bool = True,
    ) -> Sequence[LiftResult]:
        """Lift one person's frames in order, shape (T, 12, 2) (confidence (T, 12)).

        With ``warm_start`` each frame starts from the previous result (cold multi-start on
        the first frame and after a frame that could not be lifted, which is re-raised).
        """
        pts = np.asarray(points_2d, dtype=np.float64)
        if pts.ndim != 3:
            raise InvalidInputError(f"points_2d must be (T, {N_JOINTS}, 2), got {pts.shape}")
        conf = None if confidence is None else np.asarray(confidence, dtype=np.float64)
        out: list[LiftResult] = []
        warm: WarmStart | None = None
        for i in range(pts.shape[0]):
            res = self.lift(pts[i], None if conf is None else conf[i], warm)
            out.append(res)
            warm = res.warm_start() if warm_start else None
        return out
