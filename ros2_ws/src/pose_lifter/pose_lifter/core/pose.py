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
inner ADM by a direct local solver of the same problem (SQP / Newton on the KKT system).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dpotrf as _dpotrf

from .bases import PoseBases
from .errors import InvalidInputError
from .options import Variant
from .skeleton import N_JOINTS, limb_selectors
from .types import PoseResult

__all__ = [
    "LiftedConstraints",
    "PoseModel",
    "lifted_alpha_admm",
    "newton_alpha",
    "pose_objective",
    "pose_step",
    "qstep",
    "restore_feasibility",
    "top_eigenpair",
]

QStepFn = Callable[
    [NDArray[np.float64], "LiftedConstraints", NDArray[np.float64], NDArray[np.float64], float],
    NDArray[np.float64],
]


@dataclass(frozen=True)
class LiftedConstraints:
    """The limb constraints of a lifted problem, with what the Q-step needs precomputed.

    Attributes
    ----------
    omegas : ndarray, shape (8, d, d)
        Symmetric ``Omega_i``; ``z^T Omega_i z = ||C_i y||^2 - L_i``.
    affine : ndarray, shape (9, d*d)
        Rows ``vec(Omega_i)`` and ``vec(e e^T)`` (the constraint ``Q[-1,-1] = 1``).
    affine_rhs : ndarray, shape (9,)
    gram_pinv : ndarray, shape (9, 9)
        Pseudo-inverse of the Gram matrix ``affine @ affine.T``.
    """

    omegas: NDArray[np.float64]
    affine: NDArray[np.float64]
    affine_rhs: NDArray[np.float64]
    gram_pinv: NDArray[np.float64]

    @property
    def dim(self) -> int:
        """Size ``d`` of the lifted matrix."""
        return int(self.omegas.shape[1])

    @staticmethod
    def build(omegas: NDArray[np.float64]) -> LiftedConstraints:
        """Precompute the affine projection data for ``omegas`` (8, d, d)."""
        om = 0.5 * (omegas + np.swapaxes(omegas, 1, 2))
        d = om.shape[1]
        e = np.zeros((d, d))
        e[-1, -1] = 1.0
        affine = np.vstack([om.reshape(om.shape[0], -1), e.reshape(1, -1)])
        rhs = np.zeros(affine.shape[0])
        rhs[-1] = 1.0
        gram_pinv = np.asarray(np.linalg.pinv(affine @ affine.T, rcond=1e-12), dtype=np.float64)
        return LiftedConstraints(om, affine, rhs, gram_pinv)

    def violation(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """``z^T Omega_i z`` for every constraint, shape (8,)."""
        return np.asarray(np.einsum("i,kij,j->k", z, self.omegas, z))


@dataclass(frozen=True)
class PoseModel:
    """Everything of the pose step that depends only on the bases and limb targets.

    Built once per basis file; never per frame.

    Attributes
    ----------
    mean : ndarray, shape (36,)
    components : ndarray, shape (36, k)
    limb_sq : ndarray, shape (8,)
        Target squared limb lengths ``L_i`` (right lower leg = 1).
    u, sig, v : ndarrays, shapes (36, r), (r,), (k, r)
        Thin SVD of the components.
    reduced : LiftedConstraints
        Constraints in the reduced lifting (``d = r + 1``, coordinates ``s = V^T alpha``).
    full : LiftedConstraints
        Constraints in the paper's lifting (``d = k + 1``).
    limb_cu, limb_cmu, limb_hess : ndarrays, shapes (8, 3, r), (8, 3), (8, r, r)
        ``C_i U S``, ``C_i mu`` and ``2 (C_i U S)^T (C_i U S)``: the limb constraints in the
        reduced coordinates evaluated in joint space (used by the Newton alpha-solver).
    """

    mean: NDArray[np.float64]
    components: NDArray[np.float64]
    limb_sq: NDArray[np.float64]
    u: NDArray[np.float64]
    sig: NDArray[np.float64]
    v: NDArray[np.float64]
    reduced: LiftedConstraints
    full: LiftedConstraints
    limb_cu: NDArray[np.float64]
    limb_cmu: NDArray[np.float64]
    limb_hess: NDArray[np.float64]

    @property
    def n_bases(self) -> int:
        return int(self.components.shape[1])

    @staticmethod
    def build(bases: PoseBases, limb_proportions: NDArray[np.float64]) -> PoseModel:
        """Precompute the SVD and both liftings' constraint data.

        Parameters
        ----------
        bases : PoseBases
        limb_proportions : ndarray, shape (8,)
            Limb lengths (not squared), right lower leg = 1.
        """
        props = np.asarray(limb_proportions, dtype=np.float64)
        if props.shape != (8,) or not np.all(np.isfinite(props)) or np.any(props <= 0):
            raise InvalidInputError("limb_proportions must be 8 positive lengths")
        mu = bases.mean
        b = bases.components
        u, s, vt = np.linalg.svd(b, full_matrices=False)
        r = int(np.sum(s > s[0] * 1e-10))
        u, s, v = u[:, :r], s[:r], vt[:r].T
        c = limb_selectors()  # (8, 3, 36)
        ctc = np.einsum("iak,ial->ikl", c, c)  # (8, 36, 36)
        limb_sq = props**2

        def omegas(basis: NDArray[np.float64]) -> NDArray[np.float64]:
            m = basis.shape[1]
            out = np.zeros((8, m + 1, m + 1))
            out[:, :m, :m] = np.einsum("ka,iab,bl->ikl", basis.T, ctc, basis)
            cross = np.einsum("ka,iab,b->ik", basis.T, ctc, mu)
            out[:, :m, m] = cross
            out[:, m, :m] = cross
            out[:, m, m] = np.einsum("a,iab,b->i", mu, ctc, mu) - limb_sq
            return out

        us = u * s
        cu = np.einsum("iak,kr->iar", c, us)
        return PoseModel(
            mean=mu, components=b, limb_sq=limb_sq, u=u, sig=s, v=v,
            reduced=LiftedConstraints.build(omegas(us)),
            full=LiftedConstraints.build(omegas(b)),
            limb_cu=cu,
            limb_cmu=np.einsum("iak,k->ia", c, mu),
            limb_hess=2.0 * np.einsum("iar,ias->irs", cu, cu),
        )

    def pose(self, alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(mu + B alpha)`` as (12, 3)."""
        return np.asarray((self.mean + self.components @ alpha).reshape(N_JOINTS, 3))

    def limb_violation(self, alpha: NDArray[np.float64]) -> float:
        """``max_i | ||C_i y|| - sqrt(L_i) |`` for ``y = mu + B alpha``."""
        y = self.pose(alpha)
        c = limb_selectors()
        lengths = np.linalg.norm(np.einsum("iak,k->ia", c, y.reshape(-1)), axis=1)
        return float(np.max(np.abs(lengths - np.sqrt(self.limb_sq))))


def qstep(
    w: NDArray[np.float64], cons: LiftedConstraints, p: NDArray[np.float64], g: NDArray[np.float64],
    delta: float,
) -> NDArray[np.float64]:
    """Closed-form Q-step of the inner ADM.

    ``argmin_Q tr(W Q) + tr(G^T (Q - P)) + delta/2 ||Q - P||_F^2``
    s.t. ``tr(Omega_i Q) = 0``, ``Q[-1,-1] = 1``: the unconstrained minimiser
    ``P - (W + G)/delta`` projected (Frobenius) onto the affine set. ``W`` must be symmetric.
    All matrices shape (d, d).
    """
    v = p - (w + g) / delta
    v = 0.5 * (v + v.T)
    coef = cons.gram_pinv @ (cons.affine @ v.reshape(-1) - cons.affine_rhs)
    return np.asarray(v - (coef @ cons.affine).reshape(v.shape))


def top_eigenpair(s: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
    """Largest eigenvalue and its unit eigenvector of a symmetric matrix (d, d)."""
    d = s.shape[0]
    if d <= 64:
        vals, vecs = np.linalg.eigh(s)
        return float(vals[-1]), vecs[:, -1]
    vals, vecs = scipy.linalg.eigh(s, subset_by_index=[d - 1, d - 1], check_finite=False)
    return float(vals[0]), vecs[:, 0]


@dataclass(frozen=True)
class _Lifted:
    z: NDArray[np.float64]
    n_iter: int
    converged: bool


def lifted_alpha_admm(
    w: NDArray[np.float64], cons: LiftedConstraints, z0: NDArray[np.float64], delta: float = 1.0,
    max_iter: int = 60, tol: float = 1e-6, qstep_fn: QStepFn | None = None,
) -> _Lifted:
    """Inner ADM of the appendix for ``min tr(W Q)`` s.t. the limb constraints, ``Q = P``,
    ``P`` PSD of rank <= 1.

    ``P`` starts at ``z0 z0^T`` (the current alpha: warm start) and the multiplier ``G`` at 0
    (reset for every alpha-subproblem; see the pitfalls note §2). Penalty ``delta`` constant.
    Stops when ``||Q - P||_F`` and the change of ``P`` are below ``tol * max(1, ||P||_F)``.

    Returns the rank-1 factor ``z`` of ``P`` scaled to ``z[-1] = 1``.
    """
    step = qstep if qstep_fn is None else qstep_fn
    p = np.outer(z0, z0)
    g = np.zeros_like(p)
    z = z0.copy()
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        q = step(w, cons, p, g, delta)
        s = q + g / delta
        lam, vec = top_eigenpair(0.5 * (s + s.T))
        lam = max(lam, 0.0)
        p_new = lam * np.outer(vec, vec)
        g = g + delta * (q - p_new)
        pn = max(1.0, float(np.linalg.norm(p_new)))
        r_primal = float(np.linalg.norm(q - p_new)) / pn
        r_change = float(np.linalg.norm(p_new - p)) / pn
        p = p_new
        if lam > 0 and abs(vec[-1]) > 1e-12:
            z = np.sqrt(lam) * vec
            z = z / z[-1]
        if r_primal < tol and r_change < tol:
            converged = True
            break
    return _Lifted(z, it, converged)


def restore_feasibility(
    cons: LiftedConstraints, z: NDArray[np.float64], max_iter: int = 30, tol: float = 1e-10,
) -> NDArray[np.float64]:
    """Gauss-Newton projection of ``z = [s; 1]`` onto ``{z^T Omega_i z = 0}`` (min-norm steps)."""
    z = z.copy()
    for _ in range(max_iter):
        g = cons.violation(z)
        if np.max(np.abs(g)) < tol:
            break
        jac = 2.0 * np.einsum("kij,j->ki", cons.omegas, z)[:, :-1]  # (8, d-1)
        step, *_ = np.linalg.lstsq(jac, g, rcond=None)
        z[:-1] -= step
    return z


def newton_alpha(
    w: NDArray[np.float64], cons: LiftedConstraints, z0: NDArray[np.float64], max_iter: int = 30,
    tol: float = 1e-10,
) -> _Lifted:
    """Direct local solver of ``min z^T W z`` s.t. ``z^T Omega_i z = 0``, ``z[-1] = 1``.

    SQP with the exact Hessian of the Lagrangian (Newton on the KKT system), started from a
    Gauss-Newton projection of ``z0``; a step is halved until the merit
    ``f + rho * ||g||_1`` decreases. Stops when the KKT residual is below ``tol``.
    """
    z = restore_feasibility(cons, z0)
    wss = w[:-1, :-1]
    om_ss = cons.omegas[:, :-1, :-1]
    nu = np.zeros(cons.omegas.shape[0])
    rho = 10.0
    converged = False
    it = 0

    def merit(zz: NDArray[np.float64]) -> float:
        return float(zz @ w @ zz) + rho * float(np.sum(np.abs(cons.violation(zz))))

    for it in range(1, max_iter + 1):
        grad = 2.0 * (w @ z)[:-1]
        jac = 2.0 * np.einsum("kij,j->ki", cons.omegas, z)[:, :-1]
        gval = cons.violation(z)
        kkt = np.linalg.norm(grad + jac.T @ nu) + np.linalg.norm(gval)
        if kkt < tol * max(1.0, float(np.linalg.norm(grad))):
            converged = True
            break
        hess = 2.0 * wss + 2.0 * np.einsum("k,kij->ij", nu, om_ss)
        m = jac.shape[0]
        n = hess.shape[0]
        kmat = np.zeros((n + m, n + m))
        kmat[:n, :n] = hess
        kmat[:n, n:] = jac.T
        kmat[n:, :n] = jac
        rhs = -np.concatenate([grad, gval])
        try:
            sol = np.linalg.solve(kmat, rhs)
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(kmat, rhs, rcond=None)[0]
        dz, nu_new = sol[:n], sol[n:]
        rho = max(rho, 2.0 * float(np.max(np.abs(nu_new))))
        m0 = merit(z)
        a = 1.0
        while a > 1e-4:
            cand = z.copy()
            cand[:-1] += a * dz
            if merit(cand) <= m0 + 1e-12:
                break
            a *= 0.5
        z[:-1] += a * dz
        nu = nu_new
    return _Lifted(restore_feasibility(cons, z), it, converged)


def newton_reduced(
    gmat: NDArray[np.float64], lin: NDArray[np.float64], model: PoseModel, s0: NDArray[np.float64],
    max_iter: int = 10, tol: float = 1e-9,
) -> NDArray[np.float64]:
    """Direct local solver of the reduced alpha-step, constraints evaluated in joint space.

    Minimises ``s^T G s - 2 lin^T s`` s.t. ``||C_i mu + C_i U S s||^2 = L_i`` (i = 1..8), the
    same problem as :func:`newton_alpha` on ``model.reduced`` (tested equal), by SQP with the
    exact Lagrangian Hessian (``2 G`` where that is not positive definite on the tangent space
    of the constraints) from a Gauss-Newton projection of ``s0``; steps are halved until the
    merit ``f + rho ||g||_1`` decreases. Shapes: gmat (r, r), lin (r,), s0 (r,).
    """
    return _newton_reduced(gmat, lin, model, s0, max_iter, tol)[0]


_EYE8 = 1e-14 * np.eye(8)


def _solve(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a^-1 b`` by LAPACK gesv called directly (numpy's wrapper costs more than the solve
    at these sizes); least squares if ``a`` is singular."""
    _, _, x, info = _dgesv(a, b)
    if info != 0:
        return np.asarray(np.linalg.lstsq(a, b, rcond=None)[0])
    return np.asarray(x)
AUGMENTED_PD_TEST = True
#: Start each SQP alpha-step from the previous ADM iteration's multipliers. Off: measured on 3 bags
#: x 30 tracked frames, SQP iterations unchanged (~9.6 per call, most calls end at the cap with
#: line-search steps of 1/32-1/4: the l1 merit's Maratos effect), objectives mixed (0.703/1.467 ->
#: 0.713/1.396), and the walk_clean band replay went from 57 to 82 mm P-MPJPE. (Also measured, not
#: kept: an augmented-Lagrangian merit instead of the l1 one: 6-7 SQP iterations per call and
#: warm frames 70 -> 49 ms, but objectives 0.713/1.396/0.496 -> 0.779/1.498/0.552 on the three bags.)
WARM_MULTIPLIERS = False
SECOND_ORDER_CORRECTION = False  # measured: faster SQP, but more pose-step local-minimum test misses


def _newton_reduced(
    gmat: NDArray[np.float64], lin: NDArray[np.float64], model: PoseModel, s0: NDArray[np.float64],
    max_iter: int = 10, tol: float = 1e-9, nu0: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """:func:`newton_reduced` returning ``(s, multipliers (8,), SQP iterations)``; ``nu0``
    warm-starts the multipliers (e.g. from the previous ADM iteration's alpha-step)."""
    r = s0.size
    cu24 = model.limb_cu.reshape(24, r)
    cmu24 = model.limb_cmu.reshape(24)
    hc = model.limb_hess.reshape(8, r * r)
    lsq = model.limb_sq

    def cons(s: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        lv = cmu24 + cu24 @ s  # (24,)
        return (lv * lv).reshape(8, 3).sum(axis=1) - lsq, lv

    def jacobian(lv: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(2.0 * (cu24 * lv[:, None]).reshape(8, 3, r).sum(axis=1))

    def project(s: NDArray[np.float64], n: int) -> NDArray[np.float64]:
        for _ in range(n):  # Gauss-Newton (min-norm) steps onto the constraint manifold
            g, lv = cons(s)
            if np.abs(g).max() < 1e-12:
                break
            jac = jacobian(lv)
            s = s - jac.T @ _solve(jac @ jac.T + _EYE8, g)
        return s

    s = project(s0.copy(), 30)
    nu = np.zeros(8) if nu0 is None else nu0.copy()
    rho = 10.0
    kmat = np.zeros((r + 8, r + 8))
    g2 = 2.0 * gmat
    it = 0
    for it in range(1, max_iter + 1):
        g, lv = cons(s)
        jac = jacobian(lv)
        gs = gmat @ s
        grad = 2.0 * (gs - lin)
        res_d = grad + jac.T @ nu
        kkt = math.sqrt(float(res_d @ res_d)) + math.sqrt(float(g @ g))
        if kkt < tol * max(1.0, math.sqrt(float(grad @ grad))):
            it -= 1
            break
        hess = g2 + (nu @ hc).reshape(r, r)
        # Newton when the Lagrangian Hessian is positive definite on the tangent space of the
        # constraints (the second-order sufficient condition), else Gauss-Newton (2 G). Tested
        # by a Cholesky of the augmented Hessian H + c J^T J (positive definite for a large c
        # iff the reduced Hessian is); the KKT step is the same with H or H + c J^T J.
        if AUGMENTED_PD_TEST:
            jtj = jac.T @ jac
            test = hess + (10.0 * float(np.abs(hess).max()) / max(float(np.abs(jtj).max()), 1e-300)) * jtj
        else:
            test = hess
        if _dpotrf(test, lower=1, clean=0)[1] != 0:  # not positive definite
            hess = g2
        kmat[:r, :r] = hess
        kmat[:r, r:] = jac.T
        kmat[r:, :r] = jac
        rhs = -np.concatenate([grad, g])
        sol = _solve(kmat, rhs)
        ds, nu_new = sol[:r], sol[r:]
        rho = max(rho, 2.0 * float(np.abs(nu_new).max()))
        q0 = float(s @ gs - 2.0 * lin @ s)
        f0 = q0 + rho * float(np.abs(g).sum())
        a = 1.0
        cand = s + ds
        gc, lvc = cons(cand)
        # along the step the objective is the quadratic q0 + a q1 + a^2 q2 and the limb vectors
        # are affine in a: no matrix products in the backtracking loop
        q1 = float(grad @ ds)
        q2 = float(ds @ gmat @ ds)
        dlv = lvc - lv
        if SECOND_ORDER_CORRECTION and float(cand @ gmat @ cand - 2.0 * lin @ cand) + rho * float(
                np.abs(gc).sum()) > f0 + 1e-12:
            # second-order correction (against the Maratos effect: the l1 merit rejecting a
            # good full step because of the constraints' curvature): one min-norm step back
            # towards the constraint manifold from s + ds, tried before any step halving
            jc = jacobian(lvc)
            soc = cand - jc.T @ _solve(jc @ jc.T + _EYE8, gc)
            gs2, _ = cons(soc)
            if float(soc @ gmat @ soc - 2.0 * lin @ soc) + rho * float(np.abs(gs2).sum()) <= f0 + 1e-12:
                s = soc
                nu = nu_new
                continue
        while a > 1e-4:
            if q0 + a * (q1 + a * q2) + rho * float(np.abs(gc).sum()) <= f0 + 1e-12:
                break
            a *= 0.5
            lva = lv + a * dlv
            gc = (lva * lva).reshape(8, 3).sum(axis=1) - lsq
        s = s + a * ds if a < 1.0 else cand
        nu = nu_new
    return project(s, 10), nu, it


def pose_objective(
    resid: NDArray[np.float64], wts: NDArray[np.float64], alpha: NDArray[np.float64], theta: float,
    loss: Literal["l1", "l2"],
) -> float:
    """``sum w rho(resid) + theta ||alpha||_1`` (resid, wts: shape (2n,))."""
    data = np.sum(wts * np.abs(resid)) if loss == "l1" else np.sum(wts * resid * resid)
    return float(data + theta * np.sum(np.abs(alpha)))


def pose_step(
    points: NDArray[np.float64],
    projection: NDArray[np.float64],
    translation: NDArray[np.float64],
    weights: NDArray[np.float64],
    model: PoseModel,
    variant: Variant,
    theta: float,
    alpha0: NDArray[np.float64],
    *,
    max_iter: int = 100,
    tol: float = 1e-4,
    eta: float = 1.0,
    eta_growth: float = 1.0,
    eta_max: float = 1e3,
    delta: float = 1.0,
    inner_max_iter: int = 60,
    inner_tol: float = 1e-6,
    alpha_step: str = "reduced",
    alpha_solver: str = "admm",
    qstep_fn: QStepFn | None = None,
    duals: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    state_out: list[tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None,
    newton_tol: float = 1e-9,
) -> PoseResult:
    """Solve the pose problem of the module docstring for a fixed camera by ADM.

    Parameters
    ----------
    points : ndarray, shape (12, 2)
    projection : ndarray, shape (2, 3)
        ``M0``.
    translation : ndarray, shape (2,)
    weights : ndarray, shape (12,)
    model : PoseModel
    variant : Variant
        Loss, limbs on/off, sparsity on/off.
    theta : float
        Sparsity weight (ignored without sparsity).
    alpha0 : ndarray, shape (k,)
        Start (warm start: the previous alternation's or frame's coefficients).
    max_iter, tol : int, float
        Outer ADM cap; stop when primal and dual residuals, relative, are below ``tol``.
    eta, delta : float
        Outer and inner penalties.
    eta_growth, eta_max : float
        The outer penalty is multiplied by ``eta_growth`` every iteration up to ``eta_max``
        (the paper's ``eta_k``; increasing penalties as in LADMAP [liu2013linearized]);
        the scaled multipliers are rescaled with it.
    inner_max_iter, inner_tol : int, float
        Inner ADM cap and tolerance.
    alpha_step : {"reduced", "full"}
    alpha_solver : {"admm", "newton"}
    qstep_fn : callable, optional
        Replaces the closed-form Q-step (the cvxpy reference path).
    duals : (ndarray (24,), ndarray (k,)), optional
        Warm start of the (unscaled) ADM multipliers of ``gamma = c - A alpha`` and
        ``beta = alpha``, e.g. from the previous alternation (default zeros).
    state_out : list, optional
        If given, the final unscaled multipliers are appended to it (for the next warm start).
    newton_tol : float
        Relative KKT tolerance of the reduced Newton alpha-step (``alpha_solver="newton"``).

    Returns
    -------
    PoseResult
        The iterate with the lowest objective among the feasible ones visited.
    """
    loss = variant.loss
    th = float(theta) if variant.sparsity else 0.0
    x = np.asarray(points, dtype=np.float64)
    m0 = np.asarray(projection, dtype=np.float64)
    k = model.n_bases
    wts = np.repeat(np.asarray(weights, dtype=np.float64), 2)  # (24,)
    # c = x - t - M mu, as a (24,) vector; A alpha = (M U) (S V^T alpha)
    u3 = model.u.reshape(N_JOINTS, 3, -1)
    mu_proj = model.mean.reshape(N_JOINTS, 3) @ m0.T
    c = (x - translation - mu_proj).reshape(-1)
    sig, v = model.sig, model.v
    mus = np.einsum("ab,jbr->jar", m0, u3).reshape(2 * N_JOINTS, -1) * sig  # (24, r) = M U S

    def a_times(alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(mus @ (v.T @ alpha))

    full = alpha_step == "full"
    if full:
        a_full = np.einsum("ab,jbk->jak", m0, model.components.reshape(N_JOINTS, 3, k)).reshape(
            2 * N_JOINTS, k
        )
        g_full = a_full.T @ a_full + np.eye(k)
    g_red = mus.T @ mus + np.eye(sig.size)
    cons = model.full if full else model.reduced
    nu_prev: list[NDArray[np.float64] | None] = [None]

    def alpha_update(d1: NDArray[np.float64], d2: NDArray[np.float64], alpha: NDArray[np.float64]
                     ) -> NDArray[np.float64]:
        if full:
            lin = a_full.T @ d1 + d2
            if not variant.limbs:
                return np.asarray(np.linalg.solve(g_full, lin))
            wmat = np.zeros((k + 1, k + 1))
            wmat[:k, :k] = g_full
            wmat[:k, k] = -lin
            wmat[k, :k] = -lin
            wmat[k, k] = float(d1 @ d1 + d2 @ d2)
            z0 = np.append(alpha, 1.0)
        else:
            vtd2 = v.T @ d2
            lin = mus.T @ d1 + vtd2
            if not variant.limbs:
                s = np.linalg.solve(g_red, lin)
                return np.asarray(d2 - v @ vtd2 + v @ s)
            if alpha_solver == "newton":
                s, nu, _ = _newton_reduced(g_red, lin, model, v.T @ alpha, tol=newton_tol,
                                           nu0=nu_prev[0] if WARM_MULTIPLIERS else None)
                nu_prev[0] = nu
                return np.asarray(d2 - v @ vtd2 + v @ s)
            r = sig.size
            wmat = np.zeros((r + 1, r + 1))
            wmat[:r, :r] = g_red
            wmat[:r, r] = -lin
            wmat[r, :r] = -lin
            wmat[r, r] = float(d1 @ d1 + vtd2 @ vtd2)
            z0 = np.append(v.T @ alpha, 1.0)
        if alpha_solver == "newton" and not full:
            vtd2 = v.T @ d2
            s = _newton_reduced(g_red, lin, model, z0[:-1], tol=newton_tol)[0]
            return np.asarray(d2 - v @ vtd2 + v @ s)
        if alpha_solver == "newton":
            z = newton_alpha(wmat, cons, z0).z
        else:
            z = lifted_alpha_admm(wmat, cons, z0, delta, inner_max_iter, inner_tol, qstep_fn).z
            z = restore_feasibility(cons, z)
        if full:
            return np.asarray(z[:-1])
        vtd2 = v.T @ d2
        return np.asarray(d2 - v @ vtd2 + v @ z[:-1])

    alpha = np.asarray(alpha0, dtype=np.float64).copy()
    if alpha.shape != (k,):
        raise InvalidInputError(f"alpha0 must have shape ({k},), got {alpha.shape}")
    feas_tol = 1e-6

    best_alpha = alpha.copy()
    best_obj = np.inf
    if not variant.limbs or model.limb_violation(alpha) < feas_tol:
        best_obj = pose_objective(c - a_times(alpha), wts, alpha, th, loss)
    if duals is None:
        u1 = np.zeros_like(c)
        u2 = np.zeros(k)
    else:
        u1 = np.asarray(duals[0], dtype=np.float64) / eta
        u2 = np.asarray(duals[1], dtype=np.float64) / eta
    beta = alpha.copy()
    converged = False
    it = 0
    scale_c = max(1.0, float(np.linalg.norm(c)))
    for it in range(1, max_iter + 1):
        ax = a_times(alpha)
        vg = c - ax + u1
        if loss == "l1":
            gamma = np.sign(vg) * np.maximum(np.abs(vg) - wts / eta, 0.0)
        else:
            gamma = eta * vg / (2.0 * wts + eta)
        beta_prev = beta
        vb = alpha + u2
        beta = np.sign(vb) * np.maximum(np.abs(vb) - th / eta, 0.0) if th > 0 else vb
        alpha_prev = alpha
        alpha = alpha_update(c - gamma + u1, beta - u2, alpha)
        ax = a_times(alpha)
        r1 = c - ax - gamma
        r2 = alpha - beta
        u1 += r1
        u2 += r2
        if eta_growth != 1.0 and eta < eta_max:
            eta_new = min(eta * eta_growth, eta_max)
            u1 *= eta / eta_new
            u2 *= eta / eta_new
            eta = eta_new
        obj = pose_objective(c - ax, wts, alpha, th, loss)
        if obj < best_obj:
            best_obj, best_alpha = obj, alpha.copy()
        an = max(1.0, float(np.linalg.norm(alpha)))
        primal = max(float(np.linalg.norm(r1)) / scale_c, float(np.linalg.norm(r2)) / an)
        dual = max(float(np.linalg.norm(ax - a_times(alpha_prev))) / scale_c,
                   float(np.linalg.norm(beta - beta_prev)) / an)
        if primal < tol and dual < tol:
            converged = True
            break
    if state_out is not None:
        state_out.append((eta * u1, eta * u2))
    if not np.isfinite(best_obj):
        # no feasible iterate (cannot happen with restore_feasibility unless it failed)
        best_alpha = alpha
        best_obj = pose_objective(c - a_times(alpha), wts, alpha, th, loss)
    if not np.all(np.isfinite(best_alpha)):
        raise InvalidInputError("pose step diverged (non-finite coefficients)")
    viol = model.limb_violation(best_alpha) if variant.limbs else 0.0
    return PoseResult(best_alpha, model.pose(best_alpha), best_obj, viol, it, converged)
