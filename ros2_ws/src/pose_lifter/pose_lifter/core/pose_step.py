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

The alpha-step is the paper's rank-1 lifted problem ``min z^T W z  s.t.  z^T Omega_i z = 0``
with ``z = [.; 1]``, solved by the inner ADM (Q-step in closed form by projection onto the
affine set ``{tr(Omega_i Q) = 0, Q[-1,-1] = 1}``; P-step = the paper's lemma, top eigenpair).
Two exactly equivalent liftings (``alpha_step``):

* ``"full"``: ``z = [alpha; 1]`` of size ``k + 1`` (the paper's).
* ``"reduced"``: with the thin SVD ``B = U S V^T`` (rank ``r <= 33`` for centred poses), any
  alpha splits into ``V s`` (``s = V^T alpha``) plus a part in the null space of ``B``; the
  latter only enters ``||alpha - d2||^2`` and is set to its optimum ``(I - V V^T) d2`` in
  closed form, leaving ``min ||M U S s - d1||^2 + ||s - V^T d2||^2`` s.t.
  ``||C_i (mu + U S s)||^2 = L_i``, lifted with ``z = [s; 1]`` of size ``r + 1``. Same
  minimisers, same conditioning as the paper's lifting, a 34x34 instead of a 201x201 matrix.

After the inner ADM, a few Gauss-Newton projection steps restore the limb constraints to
``1e-10`` (the ADM meets them only to its tolerance). ``alpha_solver="newton"`` replaces the
inner ADM by a direct local solver of the same problem (SQP / Newton on the KKT system), and
``alpha_solver="riemannian"`` (the default) by Riemannian Newton on the product of the 8 limb
spheres (:mod:`.alpha.sphere_newton`): in the reduced coordinates the limb vectors ``l = C mu + C U S
s`` are an onto linear image of ``s`` (``PoseModel.limb_coordinates``), so ``s = s0 + Z l + N t``
with ``t`` free, eliminated in closed form, and the constraints are
``||l_i|| = sqrt(L_i)``. Inside the ADM it takes one Newton step per iteration with the proximal
term ``alpha_prox ||s - s_k||^2`` (an inexact proximal ADM).

Where: this module holds the one outer ADM loop (:func:`_adm`) over an alpha-step solver
(:class:`.alpha.base.AlphaStep`: :mod:`.alpha.lifted_admm`, :mod:`.alpha.sqp`,
:mod:`.alpha.sphere_newton`); :mod:`.pose_kernel` holds the same loop with the Riemannian
alpha-step fused into one compiled kernel (the default path, ``fused=True``), checked against
the loop in ``tests/core/test_pose_step.py``.

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
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .alpha.base import AlphaStep, Coordinates, LiftedStep, UnconstrainedStep
from .alpha.lifted_admm import QStepFn
from .alpha.sphere_newton import RIEMANNIAN_MAX_ITER, SphereNewtonStep
from .alpha.sqp import ReducedSQPStep
from .errors import InvalidInputError, SolverError, diverged_as_solver_error
from .options import LifterOptions, Variant
from .pose_kernel import (
    _adm_dual_update,
    _adm_split,
    _depth_row,
    _depth_term,
    _grow_penalty,
    _objective,
    _riemannian_pose_kernel,
)
from .pose_model import PoseModel
from .results import Duals, PoseResult
from .skeleton import N_JOINTS


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
        :func:`pose_lifter.core.pose_kernel._depth_row`)."""
        return _depth_row(np.ascontiguousarray(projection, dtype=np.float64))

    def depth_term(self, pose: NDArray[np.float64], projection: NDArray[np.float64]) -> float:
        """``sum_j weights[j, 1] |target[j, 2] - m3 (y_j - mean_i y_i)|`` for a pose (12, 3)
        (:func:`pose_lifter.core.pose_kernel._depth_term`, the fused run's own)."""
        return float(_depth_term(np.ascontiguousarray(pose, dtype=np.float64).reshape(-1),
                                 np.ascontiguousarray(projection, dtype=np.float64),
                                 np.ascontiguousarray(self.target, dtype=np.float64),
                                 np.ascontiguousarray(self.weights, dtype=np.float64)))


#: The compiled pose kernel's prior operands without a prior: target (12, 3), weights (12, 2) and
#: depth row (3,), all zero (no prior rows).
NO_PRIOR = (np.zeros((N_JOINTS, 3)), np.zeros((N_JOINTS, 2)), np.zeros(3))
_DEFAULTS = LifterOptions()


def pose_objective(
    resid: NDArray[np.float64], wts: NDArray[np.float64], alpha: NDArray[np.float64], theta: float,
    loss: Literal["l1", "l2"],
) -> float:
    """``sum w rho(resid) + theta ||alpha||_1`` (resid, wts: shape (2n,))."""
    return _objective(np.ascontiguousarray(resid, dtype=np.float64),
                      np.ascontiguousarray(wts, dtype=np.float64),
                      np.ascontiguousarray(alpha, dtype=np.float64), float(theta), loss == "l1")


def _fused_riemannian(
    x: NDArray[np.float64], m0: NDArray[np.float64], translation: NDArray[np.float64],
    weights: NDArray[np.float64], model: PoseModel, l1: bool, th: float, alpha: NDArray[np.float64],
    max_iter: int, tol: float, eta: float, eta_growth: float, eta_max: float, duals: Duals | None,
    newton_tol: float, alpha_prox: float, prior: PriorRows | None,
) -> PoseResult:
    """:func:`pose_step` with the Riemannian alpha-step as one call of the fused kernel
    :func:`pose_lifter.core.pose_kernel._riemannian_pose_kernel` (set-up included)."""
    coords = model.limb_coordinates
    assert coords is not None
    z, n, s0, rad = coords
    if prior is not None and prior.limb_radii is not None:
        rad = np.ascontiguousarray(prior.limb_radii, dtype=np.float64)
    if prior is None:
        xp, pw, m3 = NO_PRIOR
    else:
        xp, pw = prior.target, prior.weights
        m3 = prior.depth_row(m0)
    u1, u2 = _scaled_duals(duals, _n_rows(prior), model.n_bases, eta)
    vc, vt, cu24_t = model.riemannian_arrays
    best, obj, viol, y, eta_end, it, converged, alpha_it = _riemannian_pose_kernel(
        np.ascontiguousarray(x), np.ascontiguousarray(m0),
        np.ascontiguousarray(translation, dtype=np.float64), np.ascontiguousarray(weights, dtype=np.float64),
        model.mean, model.u, model.sig, vc, vt, model.components, model._limb_matrix, z, n, s0, rad, cu24_t,
        model.kernel_limbs[1], alpha, u1, u2, float(th), bool(l1), float(eta), float(eta_growth),
        float(eta_max), int(max_iter), float(tol), RIEMANNIAN_MAX_ITER, float(newton_tol), float(alpha_prox),
        xp, pw, m3)
    if not np.all(np.isfinite(best)):
        raise SolverError("pose step diverged (non-finite coefficients)")
    return PoseResult(objective=float(obj), n_iter=int(it), converged=bool(converged), alpha=best,
                      pose=y.reshape(N_JOINTS, 3), limb_violation=float(viol), alpha_iter=int(alpha_it),
                      duals=Duals(eta_end * u1, eta_end * u2))


def _n_rows(prior: PriorRows | None) -> int:
    """Rows of the pose step's L1 objective: 2 per joint, plus the prior's (2 per image position,
    1 per depth)."""
    if prior is None:
        return 2 * N_JOINTS
    pw = prior.weights
    return 2 * N_JOINTS + 2 * int(np.count_nonzero(pw[:, 0] > 0)) + int(np.count_nonzero(pw[:, 1] > 0))


def _scaled_duals(duals: Duals | None, m: int, k: int, eta: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The scaled multipliers ``u1`` (m,), ``u2`` (k,) the ADM starts from (zeros without a warm
    start of the right size)."""
    if duals is None or duals.data.shape != (m,):
        return np.zeros(m), np.zeros(k)
    return np.asarray(duals.data, dtype=np.float64) / eta, np.asarray(duals.coupling, dtype=np.float64) / eta


def _rows(x: NDArray[np.float64], m0: NDArray[np.float64], translation: NDArray[np.float64],
          weights: NDArray[np.float64], model: PoseModel, prior: PriorRows | None
          ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The L1 rows of the pose objective ``sum_i wts_i rho(c_i - (M U S s)_i)``: ``c`` (m,), ``wts``
    (m,) and ``mus = M U S`` (m, r) (``s = V^T alpha``): 2 per joint, then the prior's rows in the
    fused kernel's order (:func:`pose_lifter.core.pose_kernel._riemannian_pose_kernel`)."""
    u3 = model.u.reshape(N_JOINTS, 3, -1)
    mean3 = model.mean.reshape(N_JOINTS, 3)
    c = (x - translation - mean3 @ m0.T).reshape(-1)
    mus = np.einsum("ab,jbr->jar", m0, u3).reshape(2 * N_JOINTS, -1) * model.sig  # (24, r)
    wts = np.repeat(np.asarray(weights, dtype=np.float64), 2)
    if prior is None:
        return c, wts, mus
    xy = prior.weights[:, 0] > 0
    z = prior.weights[:, 1] > 0
    m3 = prior.depth_row(m0)
    c_xy = (prior.target[:, :2] - translation - mean3 @ m0.T)[xy].reshape(-1)
    mus_xy = mus.reshape(N_JOINTS, 2, -1)[xy].reshape(-1, mus.shape[1])
    c_z = prior.target[z, 2] - (mean3[z] - mean3.mean(axis=0)) @ m3
    mus_z = np.einsum("a,jar->jr", m3, (u3 - u3.mean(axis=0))[z]) * model.sig
    wts_all = np.concatenate([wts, np.repeat(prior.weights[xy, 0], 2), prior.weights[z, 1]])
    return np.concatenate([c, c_xy, c_z]), wts_all, np.vstack([mus, mus_xy, mus_z])


#: Cap of the pose ADM's growing penalty ``eta`` (``LifterOptions.eta_growth``).
ETA_MAX = 1e3


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
    fused: bool = True,
) -> PoseResult:
    """Solve the pose problem of the module docstring for a fixed camera by ADM.

    One outer ADM loop over an alpha-step solver (:class:`pose_lifter.core.alpha.base.AlphaStep`);
    with the Riemannian alpha-step (``fused``) the same loop runs as one compiled kernel
    (:mod:`pose_lifter.core.pose_kernel`), checked against this loop in the tests.

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
        The settings (default ``LifterOptions()``): ``variant`` (loss, limbs, sparsity), ``theta``;
        the outer ADM's ``pose_max_iter``, ``pose_tol`` (stop when the relative primal and dual
        residuals are below it), ``eta`` and ``eta_growth`` (the penalty grows by this factor every
        iteration up to :data:`ETA_MAX`, the paper's ``eta_k``, as in LADMAP [liu2013linearized];
        the scaled multipliers are rescaled with it); the alpha-step's ``alpha_step``,
        ``alpha_solver`` (``"riemannian"`` needs limbs on, the reduced lifting and an onto limb map,
        ``model.limb_coordinates``; otherwise ``"newton"`` is used), ``alpha_prox``, ``newton_tol``,
        and the inner ADM's ``delta``, ``inner_max_iter``, ``inner_tol``.
    max_iter : int, optional
        Outer ADM cap instead of ``options.pose_max_iter`` (the hybrid mode's and the screening
        runs' caps).
    prior : PriorRows, optional
        The hybrid mode's L1 prior term (:class:`PriorRows`), added to the objective; needs the
        Riemannian path (limbs on, reduced lifting, onto limb map).
    duals : Duals, optional
        Warm start of the unscaled ADM multipliers of ``gamma = c - A alpha`` and ``beta = alpha``,
        e.g. the previous alternation's ``PoseResult.duals`` (default zeros).
    qstep_fn : callable, optional
        Replaces the closed-form Q-step (the cvxpy reference path).
    fused : bool
        Riemannian path: run the compiled kernel (False: the Python loop, the kernel's reference).

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
    variant = o.method
    theta, eta, eta_growth, eta_max, tol = o.theta, o.eta, o.eta_growth, ETA_MAX, o.pose_tol
    alpha_step, alpha_solver = o.alpha_step, o.alpha_solver
    alpha_prox, newton_tol = o.alpha_prox, o.newton_tol
    delta, inner_max_iter, inner_tol = o.delta, o.inner_max_iter, o.inner_tol
    if max_iter is None:
        max_iter = o.pose_max_iter
    loss = variant.loss
    l1 = loss == "l1"
    th = float(theta) if variant.sparsity else 0.0
    x = np.asarray(points, dtype=np.float64)
    m0 = np.asarray(projection, dtype=np.float64)
    k = model.n_bases
    alpha = np.ascontiguousarray(alpha0, dtype=np.float64)
    if alpha.shape != (k,):
        raise InvalidInputError(f"alpha0 must have shape ({k},), got {alpha.shape}")
    riemannian = (alpha_solver == "riemannian" and variant.limbs and alpha_step != "full"
                  and model.limb_coordinates is not None)
    if prior is not None and not riemannian:
        raise InvalidInputError("a prior term needs alpha_solver='riemannian' with limbs, the reduced "
                                "lifting and bases whose limb map is onto (>= 24 basis directions)")
    with diverged_as_solver_error("pose step"):
        if riemannian and fused:
            return _fused_riemannian(x, m0, translation, weights, model, l1, th, alpha, max_iter, tol, eta,
                                     eta_growth, eta_max, duals, newton_tol, alpha_prox, prior)
        c, wts, mus = _rows(x, m0, np.asarray(translation, dtype=np.float64), weights, model, prior)
        # "riemannian" where it does not apply (limbs off, the full lifting or a limb map that is not
        # onto): the SQP solves the same problem
        solver = "newton" if alpha_solver == "riemannian" and not riemannian else alpha_solver
        step = _alpha_step(model, variant, m0, mus, alpha, alpha_step, solver, delta, inner_max_iter,
                           inner_tol, qstep_fn, newton_tol, alpha_prox, prior)
        radii = None if prior is None else prior.limb_radii
        return _adm(c, wts, mus, model, variant, th, alpha.copy(), step, max_iter, tol, eta, eta_growth,
                    eta_max, duals, radii)


def _alpha_step(model: PoseModel, variant: Variant, m0: NDArray[np.float64], mus: NDArray[np.float64],
                alpha0: NDArray[np.float64], alpha_step: str, solver: str, delta: float, inner_max_iter: int,
                inner_tol: float, qstep_fn: QStepFn | None, newton_tol: float, alpha_prox: float,
                prior: PriorRows | None) -> AlphaStep:
    """The alpha-step solver of one pose step (see :func:`pose_step`)."""
    if solver == "riemannian":
        radii = model.limb_coordinates[3] if model.limb_coordinates is not None else None
        if prior is not None and prior.limb_radii is not None:
            radii = prior.limb_radii
        assert radii is not None
        return SphereNewtonStep(model, mus, radii, alpha0, newton_tol, alpha_prox)
    if alpha_step == "full":
        k = model.n_bases
        a_full = np.einsum("ab,jbk->jak", m0, model.components.reshape(N_JOINTS, 3, k))
        coords, cons = Coordinates(a_full.reshape(2 * N_JOINTS, k), None), model.full
    else:
        if solver == "newton" and variant.limbs:
            return ReducedSQPStep(model, mus, newton_tol)
        coords, cons = Coordinates(mus, model.v), model.reduced
    if not variant.limbs:
        return UnconstrainedStep(coords)
    return LiftedStep(coords, cons, "newton" if solver == "newton" else "admm", delta, inner_max_iter,
                      inner_tol, qstep_fn)


def _adm(c: NDArray[np.float64], wts: NDArray[np.float64], mus: NDArray[np.float64], model: PoseModel,
         variant: Variant, th: float, alpha: NDArray[np.float64], step: AlphaStep, max_iter: int, tol: float,
         eta: float, eta_growth: float, eta_max: float, duals: Duals | None,
         radii: NDArray[np.float64] | None = None) -> PoseResult:
    """The outer pose ADM of the module docstring on the rows ``(c, wts, mus)`` (see :func:`_rows`)
    with the alpha-step ``step``; feasibility (the start's, the result's limb violation) against
    the limb lengths ``radii`` (8,) the step constrains (None: the model's)."""
    l1 = variant.loss == "l1"
    v = model.v
    k = model.n_bases
    feas_tol = 1e-6
    best_alpha = alpha.copy()
    best_obj = np.inf
    if not variant.limbs or model.limb_violation(alpha, radii) < feas_tol:
        best_obj = _objective(c - mus @ (v.T @ alpha), wts, alpha, th, l1)
    u1, u2 = _scaled_duals(duals, c.size, k, eta)
    beta = alpha.copy()
    converged = False
    it = 0
    alpha_it = 0
    scale_c = max(1.0, float(np.linalg.norm(c)))
    ax = mus @ (v.T @ alpha)
    for it in range(1, max_iter + 1):
        beta_prev, ax_prev = beta, ax
        gamma, beta, d1, d2 = _adm_split(c, ax, u1, u2, alpha, wts, float(eta), th, l1)
        alpha, n = step(d1, d2, alpha)
        alpha_it += n
        ax, obj, primal, dual = _adm_dual_update(c, gamma, alpha, beta, beta_prev, ax_prev, u1, u2, mus, v,
                                                 wts, th, l1, scale_c)
        eta = _grow_penalty(float(eta), float(eta_growth), float(eta_max), u1, u2)
        if obj < best_obj:
            best_obj, best_alpha = obj, alpha.copy()
        if primal < tol and dual < tol:
            converged = True
            break
    if not np.isfinite(best_obj):
        # no feasible iterate (cannot happen with restore_feasibility unless it failed)
        best_alpha = alpha
        best_obj = _objective(c - mus @ (v.T @ alpha), wts, alpha, th, l1)
    if not np.all(np.isfinite(best_alpha)):
        raise SolverError("pose step diverged (non-finite coefficients)")
    viol = model.limb_violation(best_alpha, radii) if variant.limbs else 0.0
    return PoseResult(objective=float(best_obj), n_iter=it, converged=converged, alpha=best_alpha,
                      pose=model.pose(best_alpha), limb_violation=viol, alpha_iter=alpha_it,
                      duals=Duals(eta * u1, eta * u2))
