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
Starts: every frame starts from the prior's pose (with the warm start's camera when tracked),
``hybrid_alternations`` alternations per run; the depth-mirrored hypothesis is scored on cold
solves (on warm ones it won no frame: the prior re-initialises the depth on every frame).
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

Where it lives: this module checks the input once, normalises it, picks the starts and maps the
winner back (one output check); a run of alternations is :mod:`.runs`, the hybrid and learned
modes' prior terms, starts and outlier pass are :mod:`.hybrid`, the steps :mod:`.camera` and
:mod:`.pose_step`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._fast import mean_rows, row_norms
from .alpha.lifted_admm import QStepFn
from .bases import PoseBases, default_bases_path
from .errors import InvalidInputError, OptionsError, SolverError, TooFewJointsError
from .hybrid import hybrid_runs, lift_learned
from .options import LifterOptions, Mode
from .pose_model import LiftedConstraints, PoseModel
from .prior import DEFAULT_TEMPORAL_PRIOR_PATH, PosePrior
from .results import Camera, LiftResult, Normalisation, WarmStart
from .runs import Run, Runs
from .skeleton import (
    ANTHROPOMETRIC_PROPORTIONS,
    LEFT_LIMBS,
    LIMB_GROUP_OF,
    N_JOINTS,
    RIGHT_LIMBS,
    limb_lengths,
)
from .validation import check_keypoints

__all__ = ["KERNEL_MODES", "Lifter", "TrackContext", "compile_kernels"]

#: The modes whose default paths :func:`compile_kernels` runs: between them, every compiled kernel
#: a default lift calls (``learned`` calls none of its own).
KERNEL_MODES: tuple[Mode, ...] = ("hybrid", "paper")
_LEFT_LIMBS = np.array(LEFT_LIMBS)
_RIGHT_LIMBS = np.array(RIGHT_LIMBS)
_GROUP_OF = np.array(LIMB_GROUP_OF)




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
            #: the mean log length of the model's own limbs (:meth:`limb_radii`)
            self._log_limb_mean = float(np.mean(np.log(np.sqrt(self._model.limb_sq))))
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
        self._runs = Runs(self.model, self._options, self._qstep_fn)

    @property
    def runs(self) -> Runs:
        """The alternation runs of the current model and options."""
        return self._runs

    # ------------------------------------------------------------------ helpers
    def _weights(self, points: NDArray[np.float64], confidence: NDArray[np.float64] | None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        x, conf = check_keypoints(points, confidence)
        w = np.where(conf >= self._options.confidence_threshold, np.clip(conf, 0.0, 1.0), 0.0)
        # a joint with non-finite coordinates is missing, whatever its confidence
        bad = ~np.all(np.isfinite(x), axis=1)
        has_bad = bool(bad.any())
        if has_bad:
            w[bad] = 0.0
        n_vis = int(np.count_nonzero(w > 0))
        if n_vis < self._options.min_visible_joints:
            raise TooFewJointsError(
                f"{n_vis} joints visible (confidence >= {self._options.confidence_threshold}); "
                f"at least {self._options.min_visible_joints} needed"
            )
        return (np.where(bad[:, None], 0.0, x) if has_bad else x), w

    def _normalise(self, x: NDArray[np.float64], w: NDArray[np.float64]) -> Normalisation:
        total = np.add.reduce(w)  # w.sum()
        centre = w @ x / total
        d = x - centre
        spread = math.sqrt(w @ np.add.reduce(d * d, axis=1) / total)
        if not math.isfinite(spread) or spread <= 1e-9 * max(1.0, abs(centre[0]), abs(centre[1])):
            raise InvalidInputError("the visible keypoints are (almost) all at one point")
        return Normalisation(centre, spread / self._mean_spread)

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
            past = (pp, pv & np.isfinite(pp).all(axis=-1))
        if fill is not None:
            fp, fv = np.asarray(fill[0], dtype=np.float64), np.asarray(fill[1], dtype=bool)
            if fp.shape != (N_JOINTS, 2) or fv.shape != (N_JOINTS,):
                raise InvalidInputError(f"fill must be (({N_JOINTS}, 2), ({N_JOINTS},)), got {fp.shape} "
                                        f"and {fv.shape}")
            # only for the joints this frame lacks: one the outlier pass flags stays missing
            fill = (fp, fv & np.isfinite(fp).all(axis=-1) & ~(w > 0))
        if mode == "learned":
            return lift_learned(self, x, w, norm, past)
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
            tw = np.array(temporal_weight, dtype=np.float64)
            if tw.shape != (N_JOINTS,):
                tw = np.broadcast_to(tw, (N_JOINTS,)).copy()
            if not ((tw >= 0.0) & (tw <= 1e3)).all():
                raise InvalidInputError(f"temporal_weight must be in [0, 1000], got {temporal_weight!r}")
            runs, total, n_starts, w, prior_pose = hybrid_runs(
                self, x, xn, w * data_weight, norm, warm, cam0, limb_proportions, tw, past, gated, fill)
            w = w / data_weight
        else:
            runs, total, n_starts = self._paper_runs(xn, w, warm, cam0)
            prior_pose = None
        idx, run = min(runs, key=lambda r: r[1].objective)
        return self._result(x, w, norm, idx, run, n_starts, total, prior_pose)

    def _paper_runs(self, xn: NDArray[np.float64], w: NDArray[np.float64], warm: WarmStart | None,
                    cam0: Camera | None) -> tuple[list[tuple[int, Run]], int, int]:
        """The paper's starts: the warm start and its mirrored copy, or the screened multi-start.
        Returns ``(runs as (start index, run), total alternations, starts tried)``."""
        if warm is not None:
            runs = [(-1, self._runs.run(xn, w, warm.alpha, cam0))]
            if self._options.warm_flip:
                runs.append((-2, self._runs.mirrored_run(xn, w, runs[0][1], None)))
            return runs, sum(r.n_iter for _, r in runs), len(runs)
        starts = self.bases.with_starts(self._options.n_starts)
        # a short first pose step only when it screens (some starts are then dropped)
        screen = self._options.screen_pose_max_iter if len(starts) > self._options.n_refine else None
        runs = [(i, self._runs.run(xn, w, a, None, max_alternations=1, pose_max_iter=screen))
                for i, a in enumerate(starts)]
        n_screened = len(runs)
        if len(runs) > 1:  # screen: continue only the most promising starts
            runs.sort(key=lambda r: r[1].objective)
            runs = runs[: self._options.n_refine]
        runs = [(i, self._runs.run(xn, w, r.pose.alpha, None, start=r)) for i, r in runs]
        # a continued run's n_iter counts its screening alternation too
        return runs, n_screened - len(runs) + sum(r.n_iter for _, r in runs), len(starts)

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
        pairs = 0.5 * (lengths[_LEFT_LIMBS] + lengths[_RIGHT_LIMBS])
        return np.asarray(pairs[_GROUP_OF])

    def limb_radii(self, proportions: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Limb-constraint radii (8,) with the ratios of ``proportions`` and the geometric-mean
        size of the model's own limbs (so the person keeps the bases' scale); None when the
        proportions are unusable (non-finite or not positive)."""
        p = np.asarray(proportions, dtype=np.float64)
        if p.shape != (8,) or not np.isfinite(p).all() or (p <= 0).any():
            return None
        lp = np.log(p)
        return np.ascontiguousarray(p * np.exp(self._log_limb_mean - np.add.reduce(lp) / lp.size))  # np.mean

    def _result(self, x: NDArray[np.float64], w: NDArray[np.float64], norm: Normalisation, idx: int,
                run: Run, n_starts: int, total: int, prior_pose: NDArray[np.float64] | None) -> LiftResult:
        """The winning run mapped back to input units, checked finite."""
        cam_n = run.camera.camera
        cam = Camera(cam_n.rotation, cam_n.scale * norm.spread, norm.centre + norm.spread * cam_n.translation)
        pose = run.pose.pose
        pose_c = pose - mean_rows(pose)
        reproj = row_norms(x - cam.project(pose))[w > 0]
        result = LiftResult(
            pose=pose,
            pose_camera=pose_c @ cam.rotation.T,
            camera=cam,
            alpha=run.pose.alpha,
            objective=run.objective,
            reprojection_error=float(np.add.reduce(reproj) / reproj.size),  # reproj.mean()
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
            if not np.isfinite(arr).all():
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


def compile_kernels() -> float:
    """Compile the solver kernels (numba, see ``core._jit``) into the cache of the place this
    package is imported from, or load them from it: a warm-up lift (:meth:`Lifter.warm_up`) in
    each of :data:`KERNEL_MODES` with the packaged bases and prior. The cache lives beside the
    sources, so an editable source tree and an installed copy each need it once (the Makefile runs
    it after installing either); a user's first lift then starts as fast as the second. Returns
    the seconds it took (~25-60 s of CPU to compile, ~1 s to load)."""
    from .measurement import compile_kernels as compile_measurement  # the tracks' output update

    start = time.perf_counter()
    for mode in KERNEL_MODES:
        Lifter(None, LifterOptions(mode=mode)).warm_up()
    compile_measurement()
    return time.perf_counter() - start
