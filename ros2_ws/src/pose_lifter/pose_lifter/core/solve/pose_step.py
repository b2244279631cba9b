"""Pose step (paper eq. 4 and appendix A): robust sparse coefficients under limb constraints.

Problem, for a fixed camera ``M0`` (2x3) and translation ``t``::

    minimise_alpha  sum_j w_j rho(x_j - t - M0 y_j) + theta ||alpha||_1
    subject to      ||C_i y||^2 = L_i,  i = 1..8,      y = mu + B alpha

(``rho = |.|`` per coordinate for L1, squared for L2; ``w_j`` per-joint weights, 0 = missing).

ADM of the appendix (scaled form, penalty ``eta``), with ``gamma = c - A alpha`` and
``beta = alpha`` where ``c = x - t - M mu`` and ``A = M B``::

    gamma <- prox_{rho_w / eta}(c - A alpha + u1)          (soft-threshold)
    beta  <- soft(alpha + u2, theta / eta)                  (skipped without sparsity)
    alpha <- argmin ||A alpha - d1||^2 + ||alpha - d2||^2   s.t. limb constraints
             with d1 = c - gamma + u1, d2 = beta - u2
    u1 <- u1 + c - A alpha - gamma;   u2 <- u2 + alpha - beta

The alpha-step is solved in reduced coordinates: with the thin SVD ``B = U S V^T`` (rank
``r <= 33`` for centred poses), any alpha splits into ``V s`` (``s = V^T alpha``) plus a part in
the null space of ``B``; the latter only enters ``||alpha - d2||^2`` and is set to its optimum
``(I - V V^T) d2`` in closed form, leaving ``min ||M U S s - d1||^2 + ||s - V^T d2||^2`` s.t.
``||C_i (mu + U S s)||^2 = L_i`` (the same minimisers as the paper's problem in ``alpha``).

Where the bases allow it (the limb vectors ``l = C mu + C U S s`` an onto linear image of ``s``,
``PoseModel.limb_coordinates``: bases with >= 24 independent directions, as every shipped set),
the alpha-step is Riemannian Newton on the product of the 8 limb spheres
(:mod:`.alpha.sphere_newton`): ``s = s0 + Z l + N t`` with ``t`` free, eliminated in closed form,
and the constraints are ``||l_i|| = sqrt(L_i)``. Inside the ADM it takes one Newton step per
iteration with the proximal term ``alpha_prox ||s - s_k||^2`` (an inexact proximal ADM). It is
the alpha-step because it ends lowest and fastest: docs/method.md measures it against an SQP and
the paper's inner ADM.

On other bases the alpha-step is the paper's: the rank-1 lifted problem
``min z^T W z  s.t.  z^T Omega_i z = 0`` with ``z = [s; 1]``, solved by the inner ADM (Q-step in
closed form by projection onto the affine set ``{tr(Omega_i Q) = 0, Q[-1,-1] = 1}``; P-step =
the paper's lemma, top eigenpair), then a few Gauss-Newton projection steps that restore the limb
constraints to ``1e-10`` (the ADM meets them only to its tolerance).

Without limb constraints (the paper's variants ``..NA..``) the alpha-step is a linear solve:
``s = G^-1 ((M U S)^T d1 + V^T d2)`` with ``G = (M U S)^T M U S + I`` factorised once per pose step.

Where: with the Riemannian or the linear alpha-step the whole step is one compiled kernel,
:func:`pose_lifter.core.solve.pose_kernel._pose_kernel`. The paper's inner ADM
(:class:`.alpha.base.LiftedStep`, of :mod:`.alpha.lifted_admm`, with its closed-form or the cvxpy
Q-step) runs in this module's Python ADM loop (:func:`_adm`), which calls the kernel's compiled
rows, splitting, dual and penalty updates: each is written once.

Speed: the alpha-steps and the outer ADM loop are kernels on plain float64 arrays, compiled by
numba (``njit(cache=True)``: compiled once, then loaded from ``__pycache__``) when numba is
importable and run as the same Python code otherwise. The two agree to round-off, not bit for
bit: the kernels' products are loops and their small inverses and sums LAPACK calls and
reductions that numba and numpy make differently. On ``walk_clean`` the first frame's objective
agrees to ~1e-12 and tracked frames then drift apart (0.4832 vs 0.4740 on the third): the
warm-started solves are chaotic in round-off (a last-bit change grows ~10x per tracked frame), as
between machines with different BLAS builds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, SolverError, diverged_as_solver_error
from ..model.pose_model import PoseModel
from ..model.skeleton import N_JOINTS
from ..options import LifterOptions
from ..results import Duals, PoseResult
from .alpha.base import AlphaStep, Coordinates, LiftedStep
from .alpha.lifted_admm import QStepFn
from .pose_kernel import (
    Multipliers,
    PoseProblem,
    PoseRows,
    Split,
    _adm_dual_update,
    _adm_split,
    _depth_row,
    _depth_term,
    _grow_penalty,
    _n_rows,
    _objective,
    _pose_kernel,
    _pose_rows,
)
from .settings import step_settings


@dataclass(frozen=True)
class PriorRows:
    """The learned prior as rows of the pose step's L1 objective (hybrid mode).

    Attributes
    ----------
    target : ndarray, shape (12, 3)
        The prior's pose in the lifter's normalised camera frame: ``x, y`` image positions (same
        frame as the 2D input), ``z`` depth relative to the joints' mean depth.
    weights : ndarray, shape (12, 2)
        Per joint: weight of its two image-position rows and of its depth row (0 = no row).
    limb_radii : ndarray, shape (8,), optional
        Limb lengths (right-lower-leg units of the model) that replace the model's own in the
        8 constraints ``||C_i y|| = limb_radii[i]`` (a person's own proportions); None keeps them.
    """

    target: NDArray[np.float64]
    weights: NDArray[np.float64]
    limb_radii: NDArray[np.float64] | None = None

    @staticmethod
    def depth_row(projection: NDArray[np.float64]) -> NDArray[np.float64]:
        """``m3 = s r3`` of a scaled-orthographic ``M0 = s [r1; r2]`` (2, 3): the row that maps a
        model pose to depth in the same units (``r3 = r1 x r2``;
        :func:`pose_lifter.core.solve.pose_kernel._depth_row`)."""
        return _depth_row(np.ascontiguousarray(projection, dtype=np.float64))

    def depth_term(self, pose: NDArray[np.float64], projection: NDArray[np.float64]) -> float:
        """``sum_j weights[j, 1] |target[j, 2] - m3 (y_j - mean_i y_i)|`` for a pose (12, 3)
        (:func:`pose_lifter.core.solve.pose_kernel._depth_term`, the compiled run's own)."""
        return float(_depth_term(np.ascontiguousarray(pose, dtype=np.float64).reshape(-1),
                                 np.ascontiguousarray(projection, dtype=np.float64),
                                 np.ascontiguousarray(self.target, dtype=np.float64),
                                 np.ascontiguousarray(self.weights, dtype=np.float64)))


#: The compiled steps' prior operands without a prior: target (12, 3) and weights (12, 2), all
#: zero (no prior rows).
NO_PRIOR = (np.zeros((N_JOINTS, 3)), np.zeros((N_JOINTS, 2)))
_DEFAULTS = LifterOptions()


def prior_operands(model: PoseModel, prior: PriorRows | None
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The compiled steps' prior operands: target (12, 3), weights (12, 2) (zeros without a prior)
    and the limb lengths in use (8,) (the prior's per-person ones, else the model's)."""
    rad = model.limb_radii
    if prior is None:
        return NO_PRIOR[0], NO_PRIOR[1], rad
    if prior.limb_radii is not None:
        rad = np.ascontiguousarray(prior.limb_radii, dtype=np.float64)
    return (np.ascontiguousarray(prior.target, dtype=np.float64),
            np.ascontiguousarray(prior.weights, dtype=np.float64), rad)


def _compiled(problem: PoseProblem, model: PoseModel, options: LifterOptions, alpha: NDArray[np.float64],
              max_iter: int, duals: Duals | None) -> PoseResult:
    """:func:`pose_step` with a compiled alpha-step (Riemannian, or linear without limbs): one
    call of :func:`pose_lifter.core.solve.pose_kernel._pose_kernel`."""
    u1, u2 = _scaled_duals(duals, _n_rows(problem.prior_weights), model.n_bases, options.eta)
    out = _pose_kernel(problem, model.kernel_arrays, step_settings(options), int(max_iter), alpha,
                       Multipliers(u1, u2))
    if not np.all(np.isfinite(out.alpha)):
        raise SolverError("pose step diverged (non-finite coefficients)")
    return PoseResult(objective=float(out.objective), n_iter=int(out.n_iter), converged=bool(out.converged),
                      alpha=out.alpha, pose=out.pose.reshape(N_JOINTS, 3),
                      limb_violation=float(out.limb_violation), alpha_iter=int(out.alpha_iter),
                      duals=Duals(out.eta * u1, out.eta * u2))


def _scaled_duals(duals: Duals | None, m: int, k: int, eta: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The scaled multipliers ``u1`` (m,), ``u2`` (k,) the ADM starts from (zeros without a warm
    start of the right size)."""
    if duals is None or duals.data.shape != (m,):
        return np.zeros(m), np.zeros(k)
    return np.asarray(duals.data, dtype=np.float64) / eta, np.asarray(duals.coupling, dtype=np.float64) / eta


def pose_step(
    points: NDArray[np.float64],
    projection: NDArray[np.float64],
    translation: NDArray[np.float64],
    weights: NDArray[np.float64],
    model: PoseModel,
    alpha0: NDArray[np.float64],
    options: LifterOptions | None = None,
    *,
    max_iter: int | None = None,
    prior: PriorRows | None = None,
    duals: Duals | None = None,
    qstep_fn: QStepFn | None = None,
) -> PoseResult:
    """Solve the pose problem of the module docstring for a fixed camera by ADM: one compiled
    kernel with the Riemannian or the linear alpha-step
    (:func:`pose_lifter.core.solve.pose_kernel._pose_kernel`), the Python ADM loop :func:`_adm`
    around the paper's inner ADM otherwise.

    Parameters
    ----------
    points : ndarray, shape (12, 2)
    projection : ndarray, shape (2, 3)
        ``M0``.
    translation : ndarray, shape (2,)
    weights : ndarray, shape (12,)
    model : PoseModel
    alpha0 : ndarray, shape (k,)
        Start (warm start: the previous alternation's or frame's coefficients).
    options : LifterOptions, optional
        The settings (default ``LifterOptions()``): ``variant``, ``theta``; the outer ADM's
        ``pose_max_iter``, ``pose_tol`` (on the relative primal and dual residuals), ``eta`` and
        ``eta_growth`` (up to :data:`~pose_lifter.core.solve.settings.ETA_MAX`: the paper's
        ``eta_k``, as in LADMAP [liu2013linearized]); the Riemannian alpha-step's ``alpha_prox``,
        ``newton_tol``; the paper's inner ADM's ``delta``, ``inner_max_iter``, ``inner_tol``.
    max_iter : int, optional
        Outer ADM cap instead of ``options.pose_max_iter``.
    prior : PriorRows, optional
        The hybrid mode's L1 prior term (:class:`PriorRows`), added to the objective; needs the
        Riemannian path (limbs on, reduced lifting, onto limb map).
    duals : Duals, optional
        Warm start of the unscaled ADM multipliers of ``gamma = c - A alpha`` and ``beta = alpha``,
        e.g. the previous alternation's ``PoseResult.duals`` (default zeros).
    qstep_fn : callable, optional
        Replaces the closed-form Q-step (the cvxpy reference path).

    Returns
    -------
    PoseResult
        The iterate with the lowest objective among the feasible ones visited, with the final
        multipliers.

    Raises
    ------
    InvalidInputError
        ``alpha0`` of the wrong shape, or a prior term without the Riemannian path.
    SolverError
        The ADM diverged (non-finite coefficients).
    """
    o = _DEFAULTS if options is None else options
    if max_iter is None:
        max_iter = o.pose_max_iter
    k = model.n_bases
    alpha = np.ascontiguousarray(alpha0, dtype=np.float64)
    if alpha.shape != (k,):
        raise InvalidInputError(f"alpha0 must have shape ({k},), got {alpha.shape}")
    c64 = np.ascontiguousarray
    xp, pw, rad = prior_operands(model, prior)
    problem = PoseProblem(c64(points, dtype=np.float64), c64(weights, dtype=np.float64),
                          c64(projection, dtype=np.float64), c64(translation, dtype=np.float64), xp, pw, rad)
    with diverged_as_solver_error("pose step"):
        if prior is not None and not (o.method.limbs and compiled_pose_step(o, model, qstep_fn)):
            raise InvalidInputError("a prior term needs a variant with limbs, bases whose limb map is onto "
                                    "(>= 24 basis directions) and the closed-form Q-step")
        if compiled_pose_step(o, model, qstep_fn):
            return _compiled(problem, model, o, alpha, max_iter, duals)
        p = problem
        rows = _pose_rows(p.points, p.projection, p.translation, p.weights, model.kernel_arrays, xp, pw)
        # limbs on bases whose limb map is not onto, or the cvxpy Q-step: the paper's inner ADM
        step = _alpha_step(model, rows.mus, o, qstep_fn)
        return _adm(rows, model, alpha.copy(), step, max_iter, o, duals)


def compiled_pose_step(options: LifterOptions, model: PoseModel, qstep_fn: QStepFn | None = None) -> bool:
    """Whether the pose step of ``options`` on ``model`` is the compiled kernel (:func:`pose_step`,
    and the compiled run's): the linear alpha-step (no limbs) or the Riemannian one (limbs on an
    onto limb map, unless the cvxpy reference Q-step ``qstep_fn`` asks for the paper's inner ADM,
    which runs in the Python loop)."""
    return not options.method.limbs or (model.limb_coordinates is not None and qstep_fn is None)


def _alpha_step(model: PoseModel, mus: NDArray[np.float64], o: LifterOptions, qstep_fn: QStepFn | None
                ) -> AlphaStep:
    """The alpha-step of one pose step of the Python loop (see :func:`pose_step`): the paper's
    inner ADM in the reduced lifting (limbs on)."""
    return LiftedStep(Coordinates(mus, model.v), model.reduced, o.delta, o.inner_max_iter, o.inner_tol,
                      qstep_fn)


def _adm(rows: PoseRows, model: PoseModel, alpha: NDArray[np.float64], step: AlphaStep, max_iter: int,
         o: LifterOptions, duals: Duals | None) -> PoseResult:
    """The outer pose ADM of the module docstring on ``rows``
    (:func:`pose_lifter.core.solve.pose_kernel._pose_rows`) with the alpha-step ``step``, in Python
    around the compiled updates :func:`~pose_lifter.core.solve.pose_kernel._adm_split`,
    :func:`~pose_lifter.core.solve.pose_kernel._adm_dual_update` and
    :func:`~pose_lifter.core.solve.pose_kernel._grow_penalty` (the compiled step's own); the
    settings (loss, sparsity, limbs, penalties, tolerance) of ``o``."""
    st = step_settings(o)  # for the compiled updates (a record Python cannot read under numba)
    limbs, l1 = o.method.limbs, o.method.loss == "l1"
    th = float(o.theta) if o.method.sparsity else 0.0
    c, wts, mus = rows.c, rows.wts, rows.mus
    v = model.v
    k = model.n_bases
    m = c.size
    eta = float(o.eta)
    best_alpha = alpha.copy()
    best_obj = np.inf
    if not limbs or model.limb_violation(alpha) < 1e-6:
        best_obj = _objective(c - mus @ (v.T @ alpha), wts, alpha, th, l1)
    u = Multipliers(*_scaled_duals(duals, m, k, eta))
    beta, beta_prev = alpha.copy(), np.empty(k)
    gamma, d1, d2 = np.empty(m), np.empty(m), np.empty(k)
    converged = False
    it = 0
    alpha_it = 0
    ax = np.ascontiguousarray(mus @ (v.T @ alpha))
    for it in range(1, max_iter + 1):
        beta, beta_prev = beta_prev, beta
        split = Split(gamma, beta, d1, d2)
        _adm_split(rows, ax, alpha, u, eta, st, split)
        alpha, n = step(d1, d2, alpha)
        alpha = np.ascontiguousarray(alpha, dtype=np.float64)
        alpha_it += n
        ax_prev, ax = ax, np.ascontiguousarray(mus @ (v.T @ alpha))
        obj, primal, dual = _adm_dual_update(rows, ax, ax_prev, split, beta_prev, alpha, u, st)
        eta = _grow_penalty(eta, st, u)
        if obj < best_obj:
            best_obj, best_alpha = obj, alpha.copy()
        if primal < o.pose_tol and dual < o.pose_tol:
            converged = True
            break
    if not np.isfinite(best_obj):
        # no feasible iterate (cannot happen with restore_feasibility unless it failed)
        best_alpha = alpha
        best_obj = _objective(c - mus @ (v.T @ alpha), wts, alpha, th, l1)
    if not np.all(np.isfinite(best_alpha)):
        raise SolverError("pose step diverged (non-finite coefficients)")
    viol = model.limb_violation(best_alpha) if limbs else 0.0
    return PoseResult(objective=float(best_obj), n_iter=it, converged=converged, alpha=best_alpha,
                      pose=model.pose(best_alpha), limb_violation=viol, alpha_iter=alpha_it,
                      duals=Duals(eta * u.u1, eta * u.u2))
