"""A run of camera/pose alternations written in Python around the steps: the compiled run's
reference (:func:`pose_lifter.core.solve.run_kernel._run_kernel`, checked against it in
``tests/core/solve/test_run_kernel.py``) and the run of the settings the kernel does not take,
the cvxpy reference steps and the paper's inner ADM on bases whose limb map is not onto
(:meth:`pose_lifter.core.lift.runs.Runs.run_all`). The same objective terms and stopping rule
as the kernel (:func:`~pose_lifter.core.solve.run_kernel._run_objective`,
:func:`~pose_lifter.core.solve.run_kernel._alternation_stops`)."""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from ..model.pose_model import PoseModel
from ..options import LifterOptions
from ..results import Alternation, Camera, CameraResult, PoseResult, SolveInfo
from ..solve.pose_step import PriorRows, prior_operands
from ..solve.run_kernel import _alternation_stops, _run_objective

__all__ = ["AlternationSteps", "ColdStart", "ContinuedRun", "LoopRun", "alternation_loop"]


class AlternationSteps(Protocol):
    """What the loop runs: a lifter's camera and pose steps (:class:`pose_lifter.core.lift.runs.Runs`)."""

    model: PoseModel
    options: LifterOptions

    def camera(self, data: tuple[NDArray[np.float64], NDArray[np.float64], bool], pose: NDArray[np.float64],
               init: Camera | None, prior: PriorRows | None = None) -> CameraResult: ...

    def pose(self, xn: NDArray[np.float64], cam: Camera, w: NDArray[np.float64], alpha0: NDArray[np.float64],
             max_iter: int | None = None, prior: PriorRows | None = None) -> PoseResult: ...


class ColdStart(NamedTuple):
    """A new run's start: coefficients and, optionally, a camera (else the camera step's own)."""

    alpha0: NDArray[np.float64]  #: (k,)
    cam0: Camera | None


class ContinuedRun(Protocol):
    """A run to continue (:class:`pose_lifter.core.lift.runs.Run`, :class:`LoopRun`)."""

    @property
    def pose(self) -> PoseResult: ...
    @property
    def camera(self) -> CameraResult: ...
    @property
    def objective(self) -> float: ...
    @property
    def n_iter(self) -> int: ...
    @property
    def history(self) -> tuple[Alternation, ...]: ...


class LoopRun(NamedTuple):
    """A run of the loop: its best alternation's steps and ``F``, the alternations done (their
    last index) and whether the stopping rule ended it, and every alternation's record."""

    pose: PoseResult
    camera: CameraResult
    objective: float
    n_iter: int
    converged: bool
    history: tuple[Alternation, ...]


def alternation_loop(steps: AlternationSteps, xn: NDArray[np.float64], w: NDArray[np.float64],
                     data: tuple[NDArray[np.float64], NDArray[np.float64], bool],
                     start: ColdStart | ContinuedRun, n_alt: int, pose_max_iter: int | None,
                     prior: PriorRows | None) -> LoopRun:
    """Alternations up to ``n_alt`` of ``steps`` on the normalised 2D ``xn`` (12, 2), weights
    ``w`` (12,) and the camera step's ``data`` (``Runs.camera_data``), minimising the run's
    objective ``F`` (the camera step's objective + ``theta ||alpha||_1`` + the prior's depth rows,
    the compiled run's): from ``start``, a :class:`ColdStart` (a camera step for ``alpha0``'s
    pose first) or a previous run to continue (its best alternation, objective and history).
    Keeps the lowest-``F`` alternation; stops when ``F`` no longer falls by ``alternation_tol``
    relative (converged) or at the cap."""
    o = steps.options
    best: ContinuedRun | None
    if isinstance(start, ColdStart):
        alpha = start.alpha0
        cam = steps.camera(data, steps.model.pose(alpha), start.cam0, prior)
        best, prev, it0, history = None, np.inf, 0, []
    else:
        alpha, cam, best, prev = start.pose.alpha, start.camera, start, start.objective
        it0, history = start.n_iter, list(start.history)
    converged = False
    it = it0
    th = o.theta if o.method.sparsity else 0.0
    xp, pw, _ = prior_operands(steps.model, prior)
    for it in range(it0 + 1, n_alt + 1):
        pres = steps.pose(xn, cam.camera, w, alpha, pose_max_iter, prior)
        alpha = pres.alpha
        cam = steps.camera(data, pres.pose, cam.camera, prior)
        obj = _run_objective(cam.objective, alpha, th, np.ascontiguousarray(pres.pose).reshape(-1),
                             np.ascontiguousarray(cam.camera.projection), xp, pw)
        history.append(Alternation(obj, SolveInfo(cam.objective, cam.n_iter, cam.converged),
                                   SolveInfo(pres.objective, pres.n_iter, pres.converged)))
        if best is None or obj < best.objective:
            best = LoopRun(pres, cam, obj, it, False, tuple(history))
        if _alternation_stops(float(prev), obj, o.alternation_tol):
            converged = True
            break
        prev = obj
    assert best is not None
    return LoopRun(best.pose, best.camera, best.objective, it, converged, tuple(history))
