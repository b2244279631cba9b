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
(:mod:`pose_lifter.core.model.prior`) alone. ``"hybrid"`` (the default) keeps the prior in the objective::

    F = sum_j w_j |x_j - M0 y_j - t|_1 + theta ||alpha||_1
        + sum_j p_j |P_j,xy - M0 y_j - t|_1 + sum_j q_j |P_j,z - m3 (y_j - mean_i y_i)|_1,
    subject to ||C_i y||^2 = L_i,   y = mu + B alpha,   m3 = s r1 x r2,

where ``P`` (12, 3) is the prior's pose for this image (its image positions and relative depths,
missing joints included) and ``p_j = prior_weight_xy / e_j,xy``, ``q_j = prior_weight_z / e_j,z``
with ``e`` the prior's per-joint error relative to its mean (``PosePrior.abs_error``). The pose
step minimises ``F`` exactly as the paper's (the prior terms are further L1 rows of its ADM,
:class:`pose_lifter.core.solve.pose_step.PriorRows`); the camera step minimises all but the depth
term (the camera ADM of the paper on the 2D plus the prior's image positions) and every
alternation keeps the lowest ``F``.
Starts: every frame starts from the prior's pose (with the warm start's camera when tracked),
``hybrid_alternations`` alternations per run; the depth-mirrored hypothesis is scored on cold
solves (on warm ones it won no frame: the prior re-initialises the depth on every frame).
Then up to ``outlier_passes`` outlier passes: visible joints farther than ``outlier_threshold``
(and ``OUTLIER_MEDIAN_FACTOR`` times the frame's median) from the fit's projection or from the
prior's image position get weight 0, the prior is re-run without them and the fit is continued
and restarted from the prior's new pose (the lower objective kept), so a confidently wrong
detection does not drag the depth. Tracked frames come screened by the per-track policy
(:mod:`pose_lifter.core.track.policy`: a joint that jumped is missing; a missing joint's prior
target takes the previous frame's pose, ``temporal_weight`` per joint).

Input normalisation: the 2D points are centred on the weighted centroid of the visible joints
and divided by their RMS spread over that of the mean pose, so ``theta`` and the tolerances
mean the same at any image size. Results are mapped back to input units.

A lift is a batch (:meth:`Lifter.lift_people`; :meth:`Lifter.lift` is a batch of one). Its stages
run in order over all its rows, each one call of the compiled kernels or of the prior's network
over the rows it concerns: the input checks and normalisation (as arrays over the rows), the
prior, the runs, the mirrored hypotheses, the outlier passes (:mod:`.hybrid`; the paper's
multi-start: :mod:`.starts`), then each row's winning run mapped back to input units (one output
check). Each row ends with a :class:`~pose_lifter.core.results.LiftOutcome`: its
:class:`~pose_lifter.core.results.LiftStatus` and reason, and its result when solved.

Where it lives: this module checks the input, normalises it, runs the mode's stages and maps the
winners back; the bases, pose model and priors are loaded by :mod:`pose_lifter.core.model.loading`,
a batch's rows and the prior's pass are :mod:`.batch`, the paper's starts :mod:`.starts`, the runs
of alternations :mod:`.runs`, the hybrid and learned modes' prior terms, starts and outlier pass
:mod:`.hybrid`, the steps :mod:`pose_lifter.core.solve.camera` and
:mod:`pose_lifter.core.solve.pose_step`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, OptionsError
from ..model.bases import PoseBases
from ..model.loading import LifterData
from ..model.pose_model import LiftedConstraints, PoseModel
from ..model.prior import PosePrior
from ..model.skeleton import LEFT_LIMBS, LIMB_GROUP_OF, N_JOINTS, RIGHT_LIMBS, limb_lengths
from ..numeric.fast import row_norms
from ..options import LifterOptions, Mode
from ..results import (
    Camera,
    Failure,
    Frames,
    LiftOutcome,
    LiftResult,
    LiftStatus,
    Normalisation,
    TrackContext,
    WarmStart,
    project_each,
)
from ..solve.alpha.lifted_admm import QStepFn
from ..validation import check_keypoints, joint_weights, weighted_centroids
from .batch import NO_TRACK, LiftRow, Person
from .hybrid import PriorFit
from .runs import Runs
from .starts import Starts, paper_starts

__all__ = ["KERNEL_MODES", "Lifter"]

#: The modes whose default paths :func:`pose_lifter.core.track.policy.compile_kernels` runs:
#: between them, every compiled kernel a default lift calls (``learned`` calls none of its own).
KERNEL_MODES: tuple[Mode, ...] = ("hybrid", "paper")
_LEFT_LIMBS = np.array(LEFT_LIMBS)
_RIGHT_LIMBS = np.array(RIGHT_LIMBS)
_GROUP_OF = np.array(LIMB_GROUP_OF)


class Lifter:
    """Lift 2D keypoints (12 model joints) to a 3D pose and a weak-perspective camera.

    Parameters
    ----------
    bases : PoseBases or None
        None loads the packaged basis file of ``options.mode``
        (:func:`pose_lifter.core.model.bases.default_bases_path`).
    options : LifterOptions or None
    prior, temporal_prior : PosePrior or None
        The learned priors (None: loaded from ``options.prior_file`` /
        ``options.temporal_prior_file`` on first use).
    reads_ahead : bool
        The lift knows each track's next frames (an offline lift: the tracks' frames are given
        with :class:`~pose_lifter.core.track.records.FramesAhead`): a temporal prior that reads frames
        after the one it lifts is accepted. False (a live lift): such a prior is refused
        (:class:`~pose_lifter.core.errors.PriorFileError` when it loads).
    """

    def __init__(self, bases: PoseBases | None = None, options: LifterOptions | None = None,
                 prior: PosePrior | None = None, temporal_prior: PosePrior | None = None,
                 reads_ahead: bool = False) -> None:
        self._options = options if options is not None else LifterOptions()
        self.reads_ahead = bool(reads_ahead)
        o = self._options
        self._data = (LifterData(bases, prior, temporal_prior, o.prior_file, o.temporal_prior_file)
                      if bases is not None else
                      LifterData.packaged(o.mode, prior, temporal_prior, o.prior_file, o.temporal_prior_file))
        self.bases = self._data.bases
        self._threads = 1
        self._build()

    @property
    def threads(self) -> int:
        """Threads over which each stage's runs are split
        (:func:`pose_lifter.core.solve.run_kernel.run_calls`; the compiled kernel releases the GIL):
        1 by default; the results do not depend on it."""
        return self._threads

    @threads.setter
    def threads(self, value: int) -> None:
        if int(value) < 1:
            raise OptionsError(f"threads must be >= 1, got {value}")
        self._threads = int(value)
        self._runs.threads = self._threads

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
        return self._data.prior(self._options.prior_file)

    @property
    def temporal_prior(self) -> PosePrior | None:
        """The temporal prior used on tracked frames (``options.temporal_prior``; loaded from
        ``options.temporal_prior_file`` on first use; causal unless :attr:`reads_ahead`), or None
        when it is off."""
        if not self._options.temporal_prior:
            return None
        return self._data.temporal_prior(self._options.temporal_prior_file, self.reads_ahead)

    @property
    def cut_body_prior(self) -> PosePrior | None:
        """The prior of the tracked frames whose 2D lacks a shoulder: the temporal prior's partner
        (causal, or offline when the lift reads ahead) trained with bodies cut by the image's
        borders, ``NAME_crop.npz`` beside its file
        (:meth:`~pose_lifter.core.model.loading.LifterData.cut_body_prior`), or None: the temporal
        prior lifts every tracked frame."""
        if not self._options.temporal_prior or self._options.mode == "paper":
            return None
        return self._data.cut_body_prior(self._options.temporal_prior_file, self.reads_ahead)

    @property
    def frames_ahead(self) -> int:
        """Frames after the lifted one that a tracked lift reads (its temporal prior's
        ``future_frames`` when it reads ahead; 0: causal, and always in the paper's mode)."""
        temporal = self.temporal_prior if self.reads_ahead and self._options.mode != "paper" else None
        return 0 if temporal is None else int(temporal.future_frames)

    @property
    def model(self) -> PoseModel:
        """Precomputed pose-step data of the current bases and limb targets."""
        return self._model

    def _build(self) -> None:
        o = self._options
        self._model = self._data.model(o.limb_proportions)
        qstep_fn: QStepFn | None = None
        if o.pose_solver == "cvxpy":
            from ..reference import reference_qstep

            def _q(w: NDArray[np.float64], cons: LiftedConstraints, p: NDArray[np.float64],
                   g: NDArray[np.float64], delta: float) -> NDArray[np.float64]:
                return np.asarray(reference_qstep(w, cons.omegas, p, g, delta))

            qstep_fn = _q
        self._runs = Runs(self._model, o, qstep_fn)
        self._runs.threads = self._threads
        self._prior_fit: PriorFit | None = None
        if o.mode != "paper":
            # the priors are loaded (and validated) now, not on the first frame
            self._prior_fit = PriorFit(o, self.prior, self.temporal_prior, self._model, self._runs,
                                       self.cut_body_prior)
            if o.mode == "hybrid" and (not o.method.limbs or self._model.limb_coordinates is None
                                       or o.pose_solver != "admm"):
                raise OptionsError("mode 'hybrid' needs a variant with limb constraints, bases with "
                                   ">= 24 independent directions and pose_solver 'admm'")

    @property
    def prior_fit(self) -> PriorFit | None:
        """The hybrid and learned modes' solve with the learned prior (None in the paper mode)."""
        return self._prior_fit

    @property
    def runs(self) -> Runs:
        """The alternation runs of the current model and options."""
        return self._runs

    # ------------------------------------------------------------------ helpers
    def _normalised(self, x: NDArray[np.float64], w: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """The 2D normalisation of n people, as arrays (each row what it is alone): their 2D ``x``
        (n, 12, 2) and weights ``w`` (n, 12) give the weighted centres (n, 2) and the weighted RMS
        spreads over the mean pose's (n,; input units per normalised unit), and which rows have a
        spread (finite, not (almost) 0: the visible joints are not all at one point; ``x`` finite)."""
        centre = weighted_centroids(x, w)
        with np.errstate(divide="ignore", invalid="ignore"):  # a row without weight: refused
            total = w.sum(axis=1)
            d = x - centre[:, None, :]
            spread = np.sqrt((w[:, None, :] @ (d * d).sum(axis=2)[:, :, None])[:, 0, 0] / total)
            ok = np.isfinite(spread) & (spread > 1e-9 * np.maximum(1.0, np.abs(centre).max(axis=1)))
        return centre, spread / self._data.mean_spread, ok

    # ------------------------------------------------------------------ public
    def warm_up(self) -> float:
        """Run the solver once (a cold and a warm lift of the mean pose seen from the side) so
        that compiled kernels (numba, see ``core.numeric.jit``) are compiled or loaded from their cache
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
            policy, :class:`pose_lifter.core.track.policy.TrackPolicy`, fills it).

        Returns
        -------
        LiftResult

        Raises
        ------
        InvalidInputError, TooFewJointsError
            Bad input (shapes, too few visible joints, a bad ``track`` field).
        SolverError
            The solve diverged on valid input.
        RuntimeError
            An unexpected error (a bug), named in its message.
        """
        return self.lift_people([LiftRow(points_2d, confidence, warm, track)])[0].unwrap()

    def lift_people(self, rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        """Several people's lifts (:meth:`lift` each) as one batch, in order: each row's
        :class:`~pose_lifter.core.results.LiftOutcome` (its status and reason, its result when
        solved). A row's result is what it gets lifted alone. Should the batch itself fail (a bug:
        each row's refusals are its own), each row is lifted again alone, so the failure costs only
        the rows it belongs to (``FAILED``, the error as the reason)."""
        try:
            return self._stages(rows)
        except Exception as err:
            if len(rows) == 1:
                return [LiftOutcome.failed(Failure.of(err))]
        return [self.lift_people([r])[0] for r in rows]

    def _stages(self, rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        """:meth:`lift_people`'s stages in order: every row's input checked and normalised (as
        arrays over the rows, :meth:`_people`); the mode's stages over the rows that passed (hybrid:
        :meth:`PriorFit.starts_people`, the prior, the runs, the mirrored hypotheses, the outlier
        passes; paper: :func:`~pose_lifter.core.lift.starts.paper_starts`; learned:
        :meth:`PriorFit.learned_people`); each winner mapped back to input units (:meth:`_results`)."""
        out: dict[int, LiftOutcome] = {}
        ready: list[tuple[int, Person]] = []
        for i, p in enumerate(self._people(rows)):
            if isinstance(p, Failure):
                out[i] = LiftOutcome.failed(p)
            else:
                ready.append((i, p))
        fit, mode, people = self._prior_fit, self._options.mode, [p for _, p in ready]
        if fit is not None and mode == "learned":
            for (i, _), r in zip(ready, fit.learned_people(people), strict=True):
                out[i] = LiftOutcome.failed(r) if isinstance(r, Failure) else LiftOutcome.solved(r)
            return [out[i] for i in range(len(rows))]
        starts = (fit.starts_people(people) if fit is not None
                  else paper_starts(self._runs, self.bases, self._options, people))
        won: list[tuple[int, Person, Starts]] = []
        for (i, p), st in zip(ready, starts, strict=True):
            if isinstance(st, Failure):
                out[i] = LiftOutcome.failed(st)
            else:
                won.append((i, p, st))
        if won:
            results = self._results([(p, st) for _, p, st in won])
            out.update((i, lifted) for (i, _, _), lifted in zip(won, results, strict=True))
        return [out[i] for i in range(len(rows))]

    def _people(self, rows: Sequence[LiftRow]) -> list[Person | Failure]:
        """The input checks stage: each row's input checked and normalised for :meth:`_stages`, or
        why it is refused: the confidences below ``confidence_threshold`` and the joints with
        non-finite coordinates missing (weight 0), at least ``min_visible_joints`` left, as arrays
        over the rows; then :meth:`_person` each."""
        out: dict[int, Person | Failure] = {}
        checked: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]] = []
        for i, r in enumerate(rows):
            try:
                checked.append((i, *check_keypoints(r.points, r.confidence)))
            except Exception as err:
                out[i] = Failure.of(err)
        if checked:
            o = self._options
            points = np.array([x for _, x, _ in checked])  # (n, 12, 2)
            conf = np.array([c for _, _, c in checked])  # (n, 12)
            points, weights = joint_weights(points, conf, o.confidence_threshold)
            n_vis = np.count_nonzero(weights > 0, axis=1).tolist()
            centre, spread, ok = self._normalised(points, weights)
            with np.errstate(divide="ignore", invalid="ignore"):  # the rows refused below
                xn = (points - centre[:, None, :]) / spread[:, None, None]
            for k, (i, _, _) in enumerate(checked):
                if n_vis[k] < o.min_visible_joints:
                    out[i] = Failure(LiftStatus.TOO_FEW_JOINTS,
                                     f"{n_vis[k]} joints visible (confidence >= {o.confidence_threshold}); "
                                     f"at least {o.min_visible_joints} needed")
                elif not ok[k]:
                    out[i] = Failure(LiftStatus.INVALID_INPUT,
                                     "the visible keypoints are (almost) all at one point")
                else:
                    try:
                        norm = Normalisation(centre[k], float(spread[k]))
                        out[i] = self._person(rows[i], points[k], weights[k], norm, xn[k])
                    except Exception as err:
                        out[i] = Failure.of(err)
        return [out[i] for i in range(len(rows))]

    def _person(self, row: LiftRow, x: NDArray[np.float64], w: NDArray[np.float64], norm: Normalisation,
                xn: NDArray[np.float64]) -> Person:
        """A person of :meth:`_people` with its 2D ``x`` (12, 2), weights ``w`` (12,), normalisation
        and normalised 2D ``xn`` (12, 2): its track's context checked, its warm start's camera in
        normalised units."""
        tc = self._track_context(NO_TRACK if row.track is None else row.track, w)
        warm, cam0 = row.warm, None
        learned = self._prior_fit is not None and self._options.mode == "learned"
        if warm is not None and not learned:
            if warm.alpha.shape != (self.bases.n_bases,):
                raise InvalidInputError("warm start alpha does not match the bases")
            cam0 = Camera(warm.camera.rotation, warm.camera.scale / norm.spread,
                          (warm.camera.translation - norm.centre) / norm.spread)
        return Person(x, xn, w, norm, warm, cam0, tc)

    def _track_context(self, track: TrackContext, w: NDArray[np.float64]) -> TrackContext:
        """``track`` checked, as the modes read it: ``past`` and ``future`` without non-finite
        joints, ``fill`` only for the joints this frame lacks (weight 0), ``temporal_weight`` an
        array (12,) (the hybrid mode's; the paper mode reads none of it)."""
        past, future, fill = track.past, track.future, track.fill
        if past is not None:
            past = _checked_frames(past)
        if future is not None:
            future = _checked_frames(future)
        if fill is not None:
            fp, fv = np.asarray(fill[0], dtype=np.float64), np.asarray(fill[1], dtype=bool)
            if fp.shape != (N_JOINTS, 2) or fv.shape != (N_JOINTS,):
                raise InvalidInputError(f"fill must be (({N_JOINTS}, 2), ({N_JOINTS},)), got {fp.shape} "
                                        f"and {fv.shape}")
            # only for the joints this frame lacks: one the outlier pass flags stays missing
            fill = (fp, fv & np.isfinite(fp).all(axis=-1) & ~(w > 0))
        if self._options.mode != "hybrid":
            return TrackContext(track.limb_proportions, track.temporal_weight, past, track.gated, fill,
                                future)
        tw = np.array(track.temporal_weight, dtype=np.float64)
        if tw.shape != (N_JOINTS,):
            tw = np.broadcast_to(tw, (N_JOINTS,)).copy()
        if not ((tw >= 0.0) & (tw <= 1e3)).all():
            raise InvalidInputError(f"temporal_weight must be in [0, 1000], got {track.temporal_weight!r}")
        return TrackContext(track.limb_proportions, tw, past, track.gated, fill, future)

    def input_scales(self, points: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
        """The unit of the lifter's normalised 2D for n people's points (n, 12, 2) and weights (n,
        12): their weighted RMS spread over the mean pose's (see the module docstring), (n,); NaN
        where the joints with weight are (almost) all at one point."""
        x = np.where((weights > 0)[..., None], np.asarray(points, dtype=np.float64), 0.0)
        _, spread, ok = self._normalised(x, np.asarray(weights, dtype=np.float64))
        return np.where(ok, spread, np.nan)

    @staticmethod
    def limb_proportions_of(pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """A person's limb proportions from a 3D pose (..., 12, 3): the 8 limb lengths with each
        left/right pair averaged (bones are symmetric; it halves the noise of an estimate),
        shape (..., 8), in the pose's units."""
        lengths = limb_lengths(pose)
        pairs = 0.5 * (lengths[..., _LEFT_LIMBS] + lengths[..., _RIGHT_LIMBS])
        return np.asarray(pairs[..., _GROUP_OF])

    def _results(self, won: Sequence[tuple[Person, Starts]]) -> list[LiftOutcome]:
        """Each person's winning run (of their :class:`Starts`) mapped back to input units and
        checked finite, the people's arrays together."""
        best = [st.best() for _, st in won]
        runs = [b.run for b in best]
        cams = [r.camera.camera for r in runs]
        spread = np.array([p.norm.spread for p, _ in won])
        centre = np.array([p.norm.centre for p, _ in won])  # (n, 2)
        translation = centre + spread[:, None] * np.array([c.translation for c in cams])  # (n, 2)
        rotation = np.array([c.rotation for c in cams])  # (n, 3, 3)
        pose = np.array([r.pose.pose for r in runs])  # (n, 12, 3)
        pose_c = pose - pose.mean(axis=1)[:, None, :]
        pose_camera = pose_c @ rotation.transpose(0, 2, 1)
        cam = [Camera(c.rotation, c.scale * s, t) for c, s, t in zip(cams, spread.tolist(), translation,
                                                                        strict=True)]
        reproj_all = row_norms(np.array([p.x for p, _ in won]) - project_each(pose, cam))  # (n, 12)
        used = np.array([st.weights for _, st in won]) > 0  # (n, 12): the joints the fit used
        reproj_mean = (np.where(used, reproj_all, 0.0).sum(axis=1) / np.count_nonzero(used, axis=1)).tolist()
        alpha = np.array([r.pose.alpha for r in runs])
        finite = (np.isfinite(pose).all(axis=(1, 2)) & np.isfinite(alpha).all(axis=1)
                  & np.isfinite(rotation).all(axis=(1, 2)) & np.isfinite(translation).all(axis=1)).tolist()
        out: list[LiftOutcome] = []
        for k, ((p, st), b, run) in enumerate(zip(won, best, runs, strict=True)):
            if not finite[k]:
                out.append(LiftOutcome(LiftStatus.DIVERGED,
                                       "the solve produced non-finite values for this input"))
                continue
            out.append(LiftOutcome.solved(LiftResult(
                pose=run.pose.pose,
                pose_camera=pose_camera[k],
                camera=cam[k],
                alpha=run.pose.alpha,
                objective=run.objective,
                reprojection_error=reproj_mean[k],
                limb_violation=run.pose.limb_violation,
                n_iter=run.n_iter,
                converged=run.converged,
                n_starts=st.n_starts,
                start_index=b.index,
                weights=st.weights,
                total_alternations=st.total_alternations,
                prior_pose=st.prior_pose,
                history=run.history,
                start=b.kind,
            )))
        return out

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


def _checked_frames(frames: Frames) -> Frames:
    """A track's past or next frames ``(points (k, 12, 2), used (k, 12))`` as the lift reads them:
    float64, a joint with a non-finite coordinate unused; InvalidInputError for other shapes."""
    pp, pv = np.asarray(frames[0], dtype=np.float64), np.asarray(frames[1], dtype=bool)
    if pp.ndim != 3 or pp.shape[1:] != (N_JOINTS, 2) or pv.shape != pp.shape[:2]:
        raise InvalidInputError(f"past and future frames must be ((k, {N_JOINTS}, 2), (k, {N_JOINTS})), "
                                f"got {pp.shape} and {pv.shape}")
    return pp, pv & np.isfinite(pp).all(axis=-1)
