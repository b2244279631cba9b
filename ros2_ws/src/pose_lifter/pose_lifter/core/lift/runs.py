"""Runs: camera/pose alternations from one start (paper Sec. 3.3), continued or mirrored.

A run minimises the lifter's objective ``F`` (see :mod:`pose_lifter.core.lift.lifter`) from a start
pose by alternating the camera step (:func:`pose_lifter.core.solve.camera.camera_step_trusted`) and the
pose step (:func:`pose_lifter.core.solve.pose_step.pose_step`) until the relative decrease of ``F`` falls
below ``alternation_tol`` or the alternation cap is reached, and keeps its lowest-``F``
alternation. A run can be continued (a screened start), and its depth-mirrored copy (the
weak-perspective ambiguity: the same 2D, reflected depth) started. The runs of a stage, every row's,
are one call (:meth:`Runs.run_all`).

With the default solvers a run is one compiled kernel (:mod:`pose_lifter.core.solve.run_kernel`;
a stage's runs in one :func:`~pose_lifter.core.solve.run_kernel.run_calls`), with or without
limbs; the cvxpy references and bases whose limb map is not onto (the paper's inner ADM as the
alpha-step) run the Python loop of :mod:`pose_lifter.core.reference.runs`, the kernel's
reference, on the same objective terms and stopping rule.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, SolverError, diverged_as_solver_error
from ..model.pose_model import PoseModel
from ..model.skeleton import N_JOINTS, normalise_pose_flat
from ..numeric.jit import njit
from ..numeric.records import StepSettings
from ..options import LifterOptions
from ..reference.runs import ColdStart, alternation_loop
from ..results import Alternation, Camera, CameraResult, Failure, PoseResult, SolveInfo
from ..solve.alpha.lifted_admm import QStepFn
from ..solve.camera import camera_step_trusted, initial_camera
from ..solve.pose_step import PriorRows, compiled_pose_step, pose_step, prior_operands
from ..solve.run_kernel import RunCall, RunOut, RunStatus, _stack_camera_data, run_calls
from ..solve.settings import step_settings

__all__ = ["PINV_RCOND", "Run", "RunSpec", "Runs"]

#: Relative cut-off of the bases' singular values in the minimum-norm coefficients of a start
#: pose (:func:`_mirror_kernel`, a pseudo-inverse): the packaged bases' smallest singular value is
#: 2.5e-7 of the largest (the next 2.6e-2); dividing by it gave the prior's poses (not in the
#: bases' span) coefficients with ||alpha||_1 ~ 2e5: their pose was right but ``theta ||alpha||_1``
#: dominated the objective. It also moves the paper's mirrored warm start slightly.
PINV_RCOND = 1e-3
_EYE3 = np.eye(3)


@dataclass(frozen=True)
class Run:
    """A run of alternations from one start: its best alternation's steps and objective and its
    alternations' history."""

    pose: PoseResult
    camera: CameraResult
    objective: float
    n_iter: int
    converged: bool
    history: tuple[Alternation, ...] = ()


@dataclass(frozen=True)
class RunSpec:
    """One run of a stage (:meth:`Runs.run_all`): the arguments of :meth:`Runs.run`."""

    xn: NDArray[np.float64]  #: (12, 2) the normalised 2D
    w: NDArray[np.float64]  #: (12,) its weights
    alpha0: NDArray[np.float64]  #: (k,) the start's coefficients
    cam0: Camera | None  #: the start's camera (None: the first camera step's own start)
    max_alternations: int | None = None
    start: Run | None = None  #: a run to continue
    pose_max_iter: int | None = None
    prior: PriorRows | None = None


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

class Runs:
    """Runs of one lifter's current model and options (rebuilt when they change).

    Parameters
    ----------
    model : PoseModel
    options : LifterOptions
    qstep_fn : callable, optional
        The cvxpy reference Q-step (``options.pose_solver == "cvxpy"``).
    """

    def __init__(self, model: PoseModel, options: LifterOptions, qstep_fn: QStepFn | None = None) -> None:
        self.model, self.options, self.qstep_fn = model, options, qstep_fn
        o = options
        #: whether a run is the compiled kernel (:mod:`pose_lifter.core.solve.run_kernel`): both steps'
        #: ADMs and a compiled alpha-step (the linear one without limbs, the Riemannian one on an
        #: onto limb map); otherwise the Python loop (:mod:`pose_lifter.core.reference.runs`: the
        #: cvxpy references, the paper's inner ADM on smaller bases; the tests set it False to run
        #: the loop on the kernel's problems as its reference)
        self.compiled = (o.camera_solver == "admm" and o.pose_solver == "admm"
                         and compiled_pose_step(o, model, qstep_fn))
        #: the steps' settings as the kernel takes them (made on the first compiled run)
        self._settings: StepSettings | None = None
        #: threads over which a stage's runs are split (:func:`pose_lifter.core.solve.run_kernel.run_calls`)
        self.threads = 1

    @property
    def settings(self) -> StepSettings:
        """The steps' settings as the compiled kernel takes them."""
        if self._settings is None:
            self._settings = step_settings(self.options)
        return self._settings

    def camera_data(self, xn: NDArray[np.float64], w: NDArray[np.float64], prior: PriorRows | None
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
        """The camera step's 2D points and weights for a run: with a prior term, the prior's
        image positions are further (pose joint, 2D point) pairs of the L1 fit (then the pose is
        stacked twice, the returned flag; :func:`pose_lifter.core.solve.run_kernel._stack_camera_data`).
        Built once per run, not per alternation."""
        xp, pw, _ = prior_operands(self.model, prior)
        cx, cw, doubled = _stack_camera_data(np.ascontiguousarray(xn, dtype=np.float64),
                                             np.ascontiguousarray(w, dtype=np.float64), xp, pw)
        return cx, cw, bool(doubled)

    def pose_max_iter(self, prior: PriorRows | None) -> int:
        """The pose step's iteration cap in a run: ``pose_max_iter``, or ``hybrid_pose_max_iter``
        with a prior term."""
        o = self.options
        return o.pose_max_iter if prior is None else o.hybrid_pose_max_iter

    def camera_max_iter(self, prior: PriorRows | None) -> int:
        """The camera step's iteration cap in a run: ``camera_max_iter``, or
        ``hybrid_camera_max_iter`` with a prior term."""
        o = self.options
        return o.camera_max_iter if prior is None else o.hybrid_camera_max_iter

    def camera(self, data: tuple[NDArray[np.float64], NDArray[np.float64], bool], pose: NDArray[np.float64],
               init: Camera | None, prior: PriorRows | None = None) -> CameraResult:
        """One camera step of a run on its :meth:`camera_data` for ``pose`` (12, 3) (stacked twice
        with a prior term), from ``init`` (None: the step's own least-squares start), at most
        :meth:`camera_max_iter` iterations for the run's ``prior`` term."""
        o = self.options
        xn, w, doubled = data
        if doubled:
            pose = np.concatenate([pose, pose])
        if o.camera_solver == "cvxpy":
            from ..reference import reference_camera

            cam, obj = reference_camera(xn, pose, w, o.method.loss,
                                        rotation_init=None if init is None else init.rotation)
            return CameraResult(objective=float(obj), n_iter=1, converged=True, camera=cam)
        # inputs checked once per lift (finite, shapes, >= min_visible_joints weights)
        return camera_step_trusted(xn, pose, w, o, init, max_iter=self.camera_max_iter(prior))

    def pose(self, xn: NDArray[np.float64], cam: Camera, w: NDArray[np.float64],
              alpha0: NDArray[np.float64], max_iter: int | None = None, prior: PriorRows | None = None
              ) -> PoseResult:
        """One pose step of a run for the camera ``cam`` on the normalised 2D ``xn`` (12, 2) and
        weights ``w`` (12,), from ``alpha0`` (k,); ``max_iter`` None: the mode's cap
        (``pose_max_iter``, or ``hybrid_pose_max_iter`` with a prior term)."""
        if max_iter is None:
            max_iter = self.pose_max_iter(prior)
        return pose_step(xn, cam.projection, cam.translation, w, self.model, alpha0, self.options,
                         max_iter=max_iter, prior=prior, qstep_fn=self.qstep_fn)

    def run(self, xn: NDArray[np.float64], w: NDArray[np.float64], alpha0: NDArray[np.float64],
            cam0: Camera | None, max_alternations: int | None = None, start: Run | None = None,
            pose_max_iter: int | None = None, prior: PriorRows | None = None) -> Run:
        """Alternate camera and pose steps from ``alpha0`` (and optionally a camera), or
        continue a previous run ``start``. The run keeps its lowest-objective
        alternation (the hybrid objective adds the prior's depth rows to the camera step's).
        :meth:`run_all` of one run; raises its failure's error."""
        (run,) = self.run_all([RunSpec(xn, w, alpha0, cam0, max_alternations, start, pose_max_iter, prior)])
        if isinstance(run, Failure):
            raise run.error()
        return run

    def run_all(self, specs: Sequence[RunSpec]) -> list[Run | Failure]:
        """The runs of ``specs`` (:meth:`run` each), in order, or the failure of each that failed:
        the compiled runs in one :func:`~pose_lifter.core.solve.run_kernel.run_calls` (over
        :attr:`threads` threads); the other solvers' runs one by one in the Python loop
        (:func:`pose_lifter.core.reference.runs.alternation_loop`)."""
        if not self.compiled:
            return [self._loop_run(sp) for sp in specs]
        o = self.options
        out: dict[int, Run | Failure] = {}
        calls: list[RunCall] = []
        which: list[int] = []
        for i, sp in enumerate(specs):
            n_alt = o.max_alternations if sp.max_alternations is None else sp.max_alternations
            try:
                calls.append(self._compiled_call(sp.w, sp.xn, sp.alpha0, sp.cam0, n_alt, sp.start,
                                                 sp.pose_max_iter, sp.prior))
                which.append(i)
            except Exception as err:
                out[i] = Failure.of(err)
        if calls:
            done = run_calls(calls, self.model.kernel_arrays, self.settings, self.threads)
            for i, d in zip(which, done, strict=True):
                out[i] = self._run_of(d, specs[i].start)
        return [out[i] for i in range(len(specs))]

    def _loop_run(self, sp: RunSpec) -> Run | Failure:
        """A run of ``sp`` in the Python loop, or its failure."""
        o = self.options
        n_alt = o.max_alternations if sp.max_alternations is None else sp.max_alternations
        try:
            start = ColdStart(sp.alpha0, sp.cam0) if sp.start is None else sp.start
            data = self.camera_data(sp.xn, sp.w, sp.prior)
            return Run(*alternation_loop(self, sp.xn, sp.w, data, start, n_alt, sp.pose_max_iter, sp.prior))
        except Exception as err:
            return Failure.of(err)

    def _run_of(self, out: RunOut | Exception, start: Run | None) -> Run | Failure:
        """The :class:`Run` of a compiled run's outcome, or the failure it stands for (numpy's
        ``LinAlgError`` of a diverged run as :class:`SolverError`)."""
        try:
            if isinstance(out, Exception):
                with diverged_as_solver_error("run"):
                    raise out
            return self._compiled_run(out, start)
        except Exception as err:
            return Failure.of(err)

    def _compiled_call(self, w: NDArray[np.float64], xn: NDArray[np.float64], alpha0: NDArray[np.float64],
                       cam0: Camera | None, n_alt: int, start: Run | None, pose_max_iter: int | None,
                       prior: PriorRows | None) -> RunCall:
        """The operands of a compiled run
        (:func:`pose_lifter.core.solve.run_kernel._run_kernel`; the kernel stacks the camera step's
        data itself, :meth:`camera_data` is needed here only for a new run's cold camera)."""
        m = self.model
        xp, pw, rad = prior_operands(m, prior)
        if pose_max_iter is None:
            pose_max_iter = self.pose_max_iter(prior)
        if start is not None:
            cam = start.camera.camera
            alpha, y0 = start.pose.alpha, m.mean
            m_init, t_init = cam.projection, cam.translation
            obj0, it0 = start.objective, start.n_iter
        else:
            alpha, y0 = alpha0, m.mean + m.components @ alpha0
            if cam0 is None:
                cx, cw, doubled = self.camera_data(xn, w, prior)
                y = y0.reshape(N_JOINTS, 3)
                m_init, t_init = initial_camera(cx, np.concatenate([y, y]) if doubled else y, cw)
            else:
                m_init, t_init = cam0.projection, cam0.translation
            obj0, it0 = np.inf, 0
        cam_init = np.empty((2, 4))  # [M | t]
        cam_init[:, :3] = m_init
        cam_init[:, 3] = t_init
        return RunCall(np.ascontiguousarray(xn, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64),
                       xp, pw, rad, np.ascontiguousarray(alpha, dtype=np.float64), y0, cam_init, float(obj0),
                       int(it0), int(n_alt), int(pose_max_iter), self.camera_max_iter(prior))

    @staticmethod
    def _compiled_run(out: RunOut, start: Run | None) -> Run:
        """The :class:`Run` of a compiled run's output (its steps' results carry no multipliers)."""
        if out.status != RunStatus.OK:
            raise SolverError("camera step diverged (non-finite camera); check the inputs"
                              if out.status == RunStatus.CAMERA_DIVERGED
                              else "pose step diverged (non-finite coefficients)")
        history = [] if start is None else list(start.history)
        done = out.done
        for (obj, cobj, pobj), (cit, cconv, pit, pconv) in zip(out.objs[:done].tolist(),
                                                              out.counts[:done].tolist(), strict=True):
            history.append(Alternation(obj, SolveInfo(cobj, cit, bool(cconv)),
                                       SolveInfo(pobj, pit, bool(pconv))))
        it, converged = int(out.it), bool(out.converged)
        if out.best_it < 0:
            assert start is not None
            return Run(start.pose, start.camera, start.objective, it, converged, tuple(history))
        pres = PoseResult(objective=out.pose_objective, n_iter=out.pose_iter, converged=out.pose_converged,
                          alpha=out.alpha, pose=out.pose.reshape(N_JOINTS, 3),
                          limb_violation=out.limb_violation, alpha_iter=out.alpha_iter)
        cam = Camera(out.rotation, out.scale, out.translation)
        cres = CameraResult(objective=out.camera_objective, n_iter=out.camera_iter,
                            converged=out.camera_converged, camera=cam)
        return Run(pres, cres, float(out.best_obj), it, converged, tuple(history))

    def mirrored_alpha(self, run: Run) -> NDArray[np.float64]:
        """Coefficients of the depth-mirrored pose of a run (same projection, depth reflected),
        re-expressed in its own body frame (:func:`normalise_pose`); minimum-norm coefficients
        through the bases' SVD."""
        m = self.model
        # flip passed, not defaulted: the signature start_alpha compiles (one cached kernel to load)
        alpha, ok = _mirror_kernel(np.ascontiguousarray(run.pose.pose), run.camera.camera.rotation, m.mean,
                                   m.u, m.sig, m.v, True)
        if not ok:
            raise InvalidInputError("a pose has a degenerate right lower leg")
        return alpha


    def mirrored_runs(self, items: Sequence[tuple[NDArray[np.float64], NDArray[np.float64], Run,
                                                  PriorRows | None]],
                      max_alternations: int | None = None) -> list[Run | Failure]:
        """The mirrored hypotheses: for each ``(xn, w, run, prior)``, the depth-mirrored copy of
        ``run`` as a start, screened by one alternation and continued when it already beats ``run``
        (``warm_flip_screen``), or run to convergence; the failure where it failed. The screens of
        every item in one call (:meth:`run_all`), the continued runs in a second."""
        o = self.options
        out: dict[int, Run | Failure] = {}
        specs: list[RunSpec] = []
        which: list[int] = []
        for i, (xn, w, run, prior) in enumerate(items):
            try:
                mirrored = self.mirrored_alpha(run)
            except Exception as err:
                out[i] = Failure.of(err)
                continue
            if o.warm_flip_screen:
                # hybrid: a short screening pose step, as for the paper's cold starts
                short = None if prior is None else o.screen_pose_max_iter
                specs.append(RunSpec(xn, w, mirrored, None, 1, prior=prior, pose_max_iter=short))
            else:
                specs.append(RunSpec(xn, w, mirrored, None, max_alternations, prior=prior))
            which.append(i)
        more: list[RunSpec] = []
        continued: list[int] = []
        for i, flip in zip(which, self.run_all(specs), strict=True):
            out[i] = flip
            xn, w, run, prior = items[i]
            if o.warm_flip_screen and isinstance(flip, Run) and flip.objective < run.objective:
                more.append(RunSpec(xn, w, flip.pose.alpha, None, max_alternations, start=flip, prior=prior))
                continued.append(i)
        for i, flip in zip(continued, self.run_all(more), strict=True):
            out[i] = flip
        return [out[i] for i in range(len(items))]

    def start_alpha(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Minimum-norm coefficients of a camera-frame pose (12, 3) in its own body frame (zeros,
        the mean pose, for a degenerate pose)."""
        m = self.model
        alpha, ok = _mirror_kernel(np.ascontiguousarray(pose), _EYE3, m.mean, m.u, m.sig, m.v, False)
        return alpha if ok else np.zeros(self.model.n_bases)
