"""Runs: camera/pose alternations from one start (paper Sec. 3.3), continued or mirrored.

A run minimises the lifter's objective ``F`` (see :mod:`pose_lifter.core.lifter`) from a start
pose by alternating the camera step (:func:`pose_lifter.core.camera.camera_step_trusted`) and the
pose step (:func:`pose_lifter.core.pose_step.pose_step`) until the relative decrease of ``F`` falls
below ``alternation_tol`` or the alternation cap is reached, and keeps its lowest-``F``
alternation. A run can be continued (a screened start), and its depth-mirrored copy (the
weak-perspective ambiguity: the same 2D, reflected depth) started.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._jit import njit
from .alpha.lifted_admm import QStepFn
from .alpha.sphere_newton import RIEMANNIAN_MAX_ITER
from .camera import camera_step_trusted, initial_camera
from .errors import InvalidInputError, SolverError, diverged_as_solver_error
from .options import LifterOptions
from .pose_kernel import _sum_abs
from .pose_model import PoseModel
from .pose_step import ETA_MAX, NO_PRIOR, PriorRows, pose_step
from .results import Alternation, Camera, CameraResult, PoseResult, SolveInfo
from .run_kernel import CAMERA_DIVERGED, OK, _run_kernel
from .skeleton import N_JOINTS, normalise_pose_flat

__all__ = ["PINV_RCOND", "Run", "Runs"]

#: Relative cut-off of the bases' singular values in the minimum-norm coefficients of a start
#: pose (:func:`_mirror_kernel`, a pseudo-inverse): the packaged bases' smallest singular value is
#: 2.5e-7 of the largest (the next 2.6e-2); dividing by it gave the prior's poses (not in the
#: bases' span) coefficients with ||alpha||_1 ~ 2e5: their pose was right but ``theta ||alpha||_1``
#: dominated the objective. It also moves the paper's mirrored warm start slightly.
PINV_RCOND = 1e-3
_EYE3 = np.eye(3)


@dataclass(frozen=True)
class Run:
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

class Runs:
    """Runs of one lifter's current model and options (rebuilt when they change).

    Parameters
    ----------
    model : PoseModel
    options : LifterOptions
    qstep_fn : callable, optional
        The cvxpy reference Q-step (``options.pose_solver == "cvxpy"``).
    fused : bool
        Run the alternations as one compiled kernel (:mod:`pose_lifter.core.run_kernel`) where it
        applies (:attr:`fusable`); False: the Python loop of :meth:`run`, its reference.
    """

    def __init__(self, model: PoseModel, options: LifterOptions, qstep_fn: QStepFn | None = None,
                 fused: bool = True) -> None:
        self.model, self.options, self.qstep_fn, self.fused = model, options, qstep_fn, fused
        o = options
        #: the fused kernel's path: both steps' ADMs, the Riemannian alpha-step (on the reduced
        #: lifting with an onto limb map) and no multipliers carried between steps
        self.fusable = (o.camera_solver == "admm" and o.pose_solver == "admm" and qstep_fn is None
                        and o.alpha_solver == "riemannian" and o.method.limbs and o.alpha_step != "full"
                        and model.limb_coordinates is not None and not o.warm_duals)
        #: the model's arrays as the kernel takes them (made on the first fused run)
        self._kernel_model: tuple[NDArray[np.float64], ...] | None = None
        #: the kernel's settings before and after the pose step's cap (which varies per run)
        self._settings = (
            (float(o.alternation_tol), float(o.theta if o.method.sparsity else 0.0), o.method.loss == "l1",
             float(o.eta), float(o.eta_growth)),
            (float(o.pose_tol), float(o.newton_tol), float(o.alpha_prox), int(o.camera_max_iter),
             float(o.camera_tol), float(o.tau)))

    @staticmethod
    def camera_data(xn: NDArray[np.float64], w: NDArray[np.float64], prior: PriorRows | None
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
        """The camera step's 2D points and weights for a run: with a prior term, the prior's
        image positions are further (pose joint, 2D point) pairs of the L1 fit (then the pose is
        stacked twice, the returned flag). Built once per run, not per alternation."""
        if prior is not None and (prior.weights[:, 0] > 0).any():
            return (np.ascontiguousarray(np.concatenate([xn, prior.target[:, :2]])),
                    np.concatenate([w, prior.weights[:, 0]]), True)
        return xn, w, False

    def camera(self, data: tuple[NDArray[np.float64], NDArray[np.float64], bool], pose: NDArray[np.float64],
                init: Camera | None, last: CameraResult | None = None) -> CameraResult:
        """One camera step of a run on its :meth:`camera_data` for ``pose`` (12, 3) (stacked twice
        with a prior term), from ``init`` (None: the step's own least-squares start), with the
        previous step's multipliers ``last.duals`` when ``options.warm_duals``."""
        o = self.options
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
        return camera_step_trusted(xn, pose, w, o, init, duals)

    def pose(self, xn: NDArray[np.float64], cam: Camera, w: NDArray[np.float64],
              alpha0: NDArray[np.float64], last: PoseResult | None = None,
              max_iter: int | None = None, prior: PriorRows | None = None) -> PoseResult:
        """One pose step of a run for the camera ``cam`` on the normalised 2D ``xn`` (12, 2) and
        weights ``w`` (12,), from ``alpha0`` (k,); ``max_iter`` None: the mode's cap
        (``pose_max_iter``, or ``hybrid_pose_max_iter`` with a prior term)."""
        o = self.options
        if max_iter is None:
            max_iter = o.pose_max_iter if prior is None else o.hybrid_pose_max_iter
        return pose_step(xn, cam.projection, cam.translation, w, self.model, alpha0, o, max_iter=max_iter,
                         prior=prior, duals=last.duals if last is not None and o.warm_duals else None,
                         qstep_fn=self.qstep_fn)

    def run(self, xn: NDArray[np.float64], w: NDArray[np.float64], alpha0: NDArray[np.float64],
             cam0: Camera | None, max_alternations: int | None = None, start: Run | None = None,
             pose_max_iter: int | None = None, prior: PriorRows | None = None) -> Run:
        """Alternate camera and pose steps from ``alpha0`` (and optionally a camera), or
        continue a previous run ``start``. With ``options.warm_duals`` the ADM multipliers of both
        steps are carried from one alternation to the next. The run keeps its lowest-objective
        alternation (the hybrid objective adds the prior's depth rows to the camera step's)."""
        o = self.options
        n_alt = o.max_alternations if max_alternations is None else max_alternations
        data = self.camera_data(xn, w, prior)
        if self.fused and self.fusable:
            return self._run_fused(xn, w, data, alpha0, cam0, n_alt, start, pose_max_iter, prior)
        last_pose: PoseResult | None
        if start is not None:
            alpha, cam, best, prev = start.pose.alpha, start.camera, start, start.objective
            it0, last_pose, history = start.n_iter, start.pose, list(start.history)
        else:
            alpha = alpha0
            cam = self.camera(data, self.model.pose(alpha), cam0)
            best, prev, it0, last_pose, history = None, np.inf, 0, None, []
        converged = False
        it = it0
        th = o.theta if o.method.sparsity else 0.0
        for it in range(it0 + 1, n_alt + 1):
            pres = self.pose(xn, cam.camera, w, alpha, last_pose, pose_max_iter, prior)
            alpha, last_pose = pres.alpha, pres
            cam = self.camera(data, pres.pose, cam.camera, cam)
            obj = cam.objective + th * _sum_abs(alpha)  # the fused run's own sum
            if prior is not None:
                obj += prior.depth_term(pres.pose, cam.camera.projection)
            history.append(Alternation(obj, SolveInfo(cam.objective, cam.n_iter, cam.converged),
                                       SolveInfo(pres.objective, pres.n_iter, pres.converged)))
            if best is None or obj < best.objective:
                best = Run(pres, cam, obj, it, False, tuple(history))
            if prev - obj <= o.alternation_tol * max(abs(prev), 1e-12) and np.isfinite(prev):
                converged = True
                break
            prev = obj
        assert best is not None
        return Run(best.pose, best.camera, best.objective, it, converged, tuple(history))

    def _run_fused(self, xn: NDArray[np.float64], w: NDArray[np.float64],
                   data: tuple[NDArray[np.float64], NDArray[np.float64], bool], alpha0: NDArray[np.float64],
                   cam0: Camera | None, n_alt: int, start: Run | None, pose_max_iter: int | None,
                   prior: PriorRows | None) -> Run:
        """:meth:`run` as one call of :func:`pose_lifter.core.run_kernel._run_kernel` (the same
        steps, objective, best alternation and stopping rule; the steps' results carry no
        multipliers)."""
        o, m = self.options, self.model
        if self._kernel_model is None:
            coords = m.limb_coordinates
            assert coords is not None
            vc, vt, cu24_t = m.riemannian_arrays
            self._kernel_model = (m.mean, m.u, m.sig, vc, vt, m.components, m._limb_matrix, coords[0],
                                  coords[1], coords[2], coords[3], cu24_t, m.kernel_limbs[1])
        mean, u, sig, vc, vt, comps, limb_matrix, z, nmat, s0, rad, cu24_t, cmu24 = self._kernel_model
        if prior is None:
            xp, pw = NO_PRIOR[0], NO_PRIOR[1]
            max_iter = o.pose_max_iter if pose_max_iter is None else pose_max_iter
        else:
            xp, pw = prior.target, prior.weights
            if prior.limb_radii is not None:
                rad = prior.limb_radii
            max_iter = o.hybrid_pose_max_iter if pose_max_iter is None else pose_max_iter
        cx, cw, doubled = data
        if start is not None:
            cam = start.camera.camera
            alpha, y0 = start.pose.alpha, m.mean
            m_init, t_init = cam.projection, cam.translation
            best0, prev0, it0 = start.objective, start.objective, start.n_iter
        else:
            alpha, y0 = alpha0, m.mean + m.components @ alpha0
            if cam0 is None:
                y = y0.reshape(N_JOINTS, 3)
                m_init, t_init = initial_camera(cx, np.concatenate([y, y]) if doubled else y, cw)
            else:
                m_init, t_init = cam0.projection, cam0.translation
            best0, prev0, it0 = np.inf, np.inf, 0
        alt_tol, th, l1, eta, eta_growth = self._settings[0]
        pose_tol, newton_tol, prox, cam_max_iter, cam_tol, tau = self._settings[1]
        with diverged_as_solver_error("run"):
            (status, done, it, converged, b_idx, b_obj, objs, counts, b_alpha, b_y, b_rot, b_t, b_f,
             b_i) = _run_kernel(
                xn, w, cx, cw, doubled, mean, u, sig, vc, vt, comps, limb_matrix, z, nmat, s0, rad, cu24_t,
                cmu24, xp, pw, prior is not None,
                np.ascontiguousarray(alpha, dtype=np.float64), y0,
                np.ascontiguousarray(m_init, dtype=np.float64),
                np.ascontiguousarray(t_init, dtype=np.float64),
                start is not None, float(best0), float(prev0), int(it0), int(n_alt), alt_tol, th, l1, eta,
                eta_growth, ETA_MAX, int(max_iter), pose_tol, RIEMANNIAN_MAX_ITER, newton_tol, prox,
                cam_max_iter, cam_tol, tau)
        if status != OK:
            raise SolverError("camera step diverged (non-finite camera); check the inputs"
                              if status == CAMERA_DIVERGED
                              else "pose step diverged (non-finite coefficients)")
        history = [] if start is None else list(start.history)
        for (obj, cobj, pobj), (cit, cconv, pit, pconv) in zip(objs[:done].tolist(), counts[:done].tolist(),
                                                              strict=True):
            history.append(Alternation(obj, SolveInfo(cobj, cit, bool(cconv)),
                                       SolveInfo(pobj, pit, bool(pconv))))
        if b_idx < 0:
            assert start is not None
            return Run(start.pose, start.camera, start.objective, it, converged, tuple(history))
        pobj, viol, cobj, scale = b_f.tolist()
        pit, pconv, ait, cit, cconv = b_i.tolist()
        pres = PoseResult(objective=pobj, n_iter=pit, converged=bool(pconv), alpha=b_alpha,
                          pose=b_y.reshape(N_JOINTS, 3), limb_violation=viol, alpha_iter=ait)
        cres = CameraResult(objective=cobj, n_iter=cit, converged=bool(cconv),
                            camera=Camera(b_rot, scale, b_t))
        return Run(pres, cres, float(b_obj), it, converged, tuple(history))

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


    def mirrored_run(self, xn: NDArray[np.float64], w: NDArray[np.float64], run: Run,
                      prior: PriorRows | None, max_alternations: int | None = None) -> Run:
        """The depth-mirrored copy of ``run`` as a start: screened by one alternation and continued
        when it already beats ``run`` (``warm_flip_screen``), or run to convergence."""
        mirrored = self.mirrored_alpha(run)
        if self.options.warm_flip_screen:
            # hybrid: a short screening pose step, as for the paper's cold starts
            short = None if prior is None else self.options.screen_pose_max_iter
            flip = self.run(xn, w, mirrored, None, max_alternations=1, prior=prior, pose_max_iter=short)
            if flip.objective < run.objective:
                flip = self.run(xn, w, flip.pose.alpha, None, max_alternations, start=flip, prior=prior)
            return flip
        return self.run(xn, w, mirrored, None, max_alternations, prior=prior)


    def start_alpha(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Minimum-norm coefficients of a camera-frame pose (12, 3) in its own body frame (zeros,
        the mean pose, for a degenerate pose)."""
        m = self.model
        alpha, ok = _mirror_kernel(np.ascontiguousarray(pose), _EYE3, m.mean, m.u, m.sig, m.v, False)
        return alpha if ok else np.zeros(self.model.n_bases)
