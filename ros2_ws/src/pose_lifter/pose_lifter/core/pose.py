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
spheres (:func:`_sphere_newton`): in the reduced coordinates the limb vectors ``l = C mu + C U S
s`` are an onto linear image of ``s`` (``PoseModel.limb_coordinates``), so ``s = s0 + Z l + N t``
with ``t`` free, eliminated in closed form (:func:`_sphere_setup`), and the constraints are
``||l_i|| = sqrt(L_i)``. Inside the ADM it takes one Newton step per iteration with the proximal
term ``alpha_prox ||s - s_k||^2`` (an inexact proximal ADM).

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

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dpotrf as _dpotrf

from ._jit import HAVE_NUMBA, njit
from .bases import PoseBases
from .errors import InvalidInputError, SolverError, diverged_as_solver_error
from .options import Variant
from .skeleton import N_JOINTS, limb_selectors
from .types import PoseResult

#: SQP iteration cap of each Newton alpha-step.
NEWTON_MAX_ITER = 10
#: Iteration cap of each Riemannian Newton alpha-step inside the pose ADM (an inexact, proximal
#: ADM). Measured on 190 recorded warm lifts of 5 committed bags, pose_max_iter 30: 1, 2, 3 Newton
#: steps give mean objectives 0.6916 / 0.6965 / 0.6965 at 1.8 / 2.0 / 2.3 ms per frame; run to
#: convergence (20) it was 0.8178 without the proximal term, 0.7679 with it (alpha_prox = 1, at
#: pose_max_iter 20).
RIEMANNIAN_MAX_ITER = 1

__all__ = [
    "LiftedConstraints",
    "PoseModel",
    "PriorRows",
    "lifted_alpha_admm",
    "newton_alpha",
    "pose_objective",
    "pose_step",
    "qstep",
    "restore_feasibility",
    "riemannian_alpha",
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


def _lifted_omegas(basis: NDArray[np.float64], mu: NDArray[np.float64], limb_sq: NDArray[np.float64]
                   ) -> NDArray[np.float64]:
    """``Omega_i`` (8, m + 1, m + 1) of the lifting ``z = [coefficients; 1]`` for ``y = mu + basis
    coefficients`` (basis (36, m)): ``z^T Omega_i z = ||C_i y||^2 - L_i``."""
    c = limb_selectors()
    ctc = np.einsum("iak,ial->ikl", c, c)  # (8, 36, 36)
    m = basis.shape[1]
    out = np.zeros((8, m + 1, m + 1))
    out[:, :m, :m] = np.einsum("ka,iab,bl->ikl", basis.T, ctc, basis)
    cross = np.einsum("ka,iab,b->ik", basis.T, ctc, mu)
    out[:, :m, m] = cross
    out[:, m, :m] = cross
    out[:, m, m] = np.einsum("a,iab,b->i", mu, ctc, mu) - limb_sq
    return out


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
        Constraints in the paper's lifting (``d = k + 1``): a cached property built on first
        use (~0.25 s for 200 bases; only ``alpha_step="full"`` needs it).
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
    limb_cu: NDArray[np.float64]
    limb_cmu: NDArray[np.float64]
    limb_hess: NDArray[np.float64]

    @functools.cached_property
    def kernel_limbs(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                    NDArray[np.float64]]:
        """``C_i U S`` (24, r), ``C_i mu`` (24,), the limb Hessians (8, r*r) and ``L_i`` (8,) as
        C-contiguous arrays for the compiled Newton kernel (made once per model)."""
        r = self.sig.size
        return (np.ascontiguousarray(self.limb_cu.reshape(24, r)),
                np.ascontiguousarray(self.limb_cmu.reshape(24)),
                np.ascontiguousarray(self.limb_hess.reshape(8, r * r)),
                np.ascontiguousarray(self.limb_sq))

    @functools.cached_property
    def limb_coordinates(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                        NDArray[np.float64]] | None:
        """The reduced coordinates ``s`` split as ``s = s0 + Z l + N t``, where ``l`` (24,) are the
        8 limb vectors ``C_i (mu + U S s)`` and ``t`` is free: ``(Z (r, 24), N (r, r - 24), s0 (r,),
        limb lengths (8,))``. The limb constraints are then ``||l_i|| = sqrt(L_i)``, a product of
        spheres (the ``"riemannian"`` alpha-solver). None when the limb map ``C U S`` (24, r) does
        not have full row rank (fewer than 24 independent basis directions, e.g. a small PCA)."""
        cu24 = self.kernel_limbs[0]
        if cu24.shape[1] < 24:
            return None
        uu, sv, vt = np.linalg.svd(cu24)
        if sv[-1] <= 1e-8 * sv[0]:
            return None
        z = vt[:24].T @ ((uu.T) / sv[:, None])  # (r, 24): cu24 @ z = I
        n = np.ascontiguousarray(vt[24:].T)  # (r, r - 24): cu24 @ n = 0
        s0 = -z @ self.kernel_limbs[1]
        return np.ascontiguousarray(z), n, s0, np.sqrt(self.limb_sq)

    @property
    def n_bases(self) -> int:
        return int(self.components.shape[1])

    @staticmethod
    def build(bases: PoseBases, limb_proportions: NDArray[np.float64]) -> PoseModel:
        """Precompute the SVD and the reduced lifting's constraint data (the paper's lifting,
        :attr:`full`, is built on first use).

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
        limb_sq = props**2
        us = u * s
        cu = np.einsum("iak,kr->iar", c, us)
        return PoseModel(
            mean=mu, components=b, limb_sq=limb_sq, u=u, sig=s, v=v,
            reduced=LiftedConstraints.build(_lifted_omegas(us, mu, limb_sq)),
            limb_cu=cu,
            limb_cmu=np.einsum("iak,k->ia", c, mu),
            limb_hess=2.0 * np.einsum("iar,ias->irs", cu, cu),
        )

    @functools.cached_property
    def full(self) -> LiftedConstraints:
        """Constraints in the paper's lifting (``d = k + 1``), built on first use."""
        return LiftedConstraints.build(_lifted_omegas(self.components, self.mean, self.limb_sq))

    def pose(self, alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(mu + B alpha)`` as (12, 3)."""
        return np.asarray((self.mean + self.components @ alpha).reshape(N_JOINTS, 3))

    def limb_violation(self, alpha: NDArray[np.float64]) -> float:
        """``max_i | ||C_i y|| - sqrt(L_i) |`` for ``y = mu + B alpha``."""
        lv = (self._limb_matrix @ (self.mean + self.components @ alpha)).reshape(8, 3)
        return float(np.max(np.abs(np.sqrt(np.sum(lv * lv, axis=1)) - np.sqrt(self.limb_sq))))

    @functools.cached_property
    def riemannian_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``V`` (k, r), ``V^T`` (r, k) and ``(C U S)^T`` (r, 24), C-contiguous: the Riemannian pose
        kernel's operands that depend only on the bases (made once per model)."""
        return (np.ascontiguousarray(self.v), np.ascontiguousarray(self.v.T),
                np.ascontiguousarray(self.kernel_limbs[0].T))

    @functools.cached_property
    def _limb_matrix(self) -> NDArray[np.float64]:
        """The 8 ``C_i`` stacked, (24, 36)."""
        return np.ascontiguousarray(limb_selectors().reshape(24, 3 * N_JOINTS))


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


def riemannian_alpha(
    gmat: NDArray[np.float64], lin: NDArray[np.float64], model: PoseModel, s0: NDArray[np.float64],
    max_iter: int = 100, tol: float = 1e-10,
) -> tuple[NDArray[np.float64], int, bool]:
    """The reduced alpha-step ``min s^T G s - 2 lin^T s`` s.t. ``||C_i mu + C_i U S s||^2 = L_i``
    (the problem of :func:`newton_alpha` on ``model.reduced``) by Riemannian Newton in limb
    coordinates: the free directions eliminated in closed form (:func:`_sphere_setup`), then
    :func:`_sphere_newton` on the product of the 8 limb spheres from the limb vectors of ``s0``.
    Shapes: gmat (r, r) positive definite, lin (r,), s0 (r,). Returns ``(s, iterations, converged)``.

    Raises
    ------
    InvalidInputError
        If the model's limb map is not onto (``model.limb_coordinates`` is None).
    """
    coords = model.limb_coordinates
    if coords is None:
        raise InvalidInputError("the bases' limb map is not onto (fewer than 24 independent directions)")
    z, n, sz, rad = coords
    g = np.ascontiguousarray(gmat, dtype=np.float64)
    q, rmat, s1, s2 = _sphere_setup(g, z, n)
    h = np.asarray(lin, dtype=np.float64) - g @ sz
    cu24, cmu24 = model.kernel_limbs[:2]
    lv, it, conv = _sphere_newton(q, rmat @ h, cmu24 + cu24 @ np.asarray(s0, dtype=np.float64), rad,
                                  int(max_iter), float(tol))
    return sz + s1 @ lv + s2 @ h, int(it), bool(conv)


_EYE8 = 1e-14 * np.eye(8)


def _solve_lapack(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a^-1 b`` by LAPACK gesv called directly (numpy's wrapper costs more than the solve
    at these sizes); least squares if ``a`` is singular."""
    _, _, x, info = _dgesv(a, b)
    if info != 0:
        return np.asarray(np.linalg.lstsq(a, b, rcond=None)[0])
    return np.asarray(x)


def _pos_def_lapack(a: NDArray[np.float64]) -> bool:
    """Whether the Cholesky factorisation (LAPACK potrf, lower triangle) of ``a`` succeeds."""
    return bool(_dpotrf(a, lower=1, clean=0)[1] == 0)


@njit
def _solve_jit(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`_solve_lapack` inside the compiled kernels: numba's ``solve`` is the same LAPACK
    gesv (scipy's), raising on a singular ``a``; least squares then (numpy's default rcond)."""
    try:
        return np.asarray(np.linalg.solve(a, b), dtype=np.float64)
    except Exception:  # singular, or non-finite values (gesv propagates them; numba raises)
        pass
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return np.full(b.shape[0], np.nan)
    return np.asarray(np.linalg.lstsq(a, b, rcond=2.220446049250313e-16 * max(a.shape[0], a.shape[1]))[0],
                      dtype=np.float64)


@njit
def _pos_def_jit(a: NDArray[np.float64]) -> bool:
    """:func:`_pos_def_lapack` inside the compiled kernels (numba's ``cholesky``: the same
    potrf on the lower triangle, raising where the matrix is not positive definite)."""
    try:
        np.linalg.cholesky(a)
    except Exception:
        return False
    return True


# the compiled kernels call LAPACK through numba; without numba they run as plain Python and call
# scipy's LAPACK directly
_solve = _solve_jit if HAVE_NUMBA else _solve_lapack
_pos_def = _pos_def_jit if HAVE_NUMBA else _pos_def_lapack


@njit
def _limbs(s: NDArray[np.float64], cu24: NDArray[np.float64], cmu24: NDArray[np.float64],
           lsq: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Limb constraint values ``||C_i mu + C_i U S s||^2 - L_i`` (8,) and the limb vectors (24,)."""
    lv = cmu24 + cu24 @ s
    return (lv * lv).reshape(8, 3).sum(axis=1) - lsq, lv


@njit
def _limb_jacobian(lv: NDArray[np.float64], cu24: NDArray[np.float64]) -> NDArray[np.float64]:
    """Jacobian (8, r) of :func:`_limbs` at limb vectors ``lv``."""
    r = cu24.shape[1]
    return np.asarray(2.0 * (cu24 * lv.reshape(24, 1)).reshape(8, 3, r).sum(axis=1))


@njit
def _project_limbs(s: NDArray[np.float64], n: int, cu24: NDArray[np.float64], cmu24: NDArray[np.float64],
                   lsq: NDArray[np.float64], eye8: NDArray[np.float64]) -> NDArray[np.float64]:
    """At most ``n`` Gauss-Newton (min-norm) steps of ``s`` onto the constraint manifold."""
    for _ in range(n):
        g, lv = _limbs(s, cu24, cmu24, lsq)
        if np.abs(g).max() < 1e-12:
            break
        jac = _limb_jacobian(lv, cu24)
        s = s - jac.T @ _solve(jac @ jac.T + eye8, g)
    return s


@njit
def _newton_kernel(
    gmat: NDArray[np.float64], lin: NDArray[np.float64], cu24: NDArray[np.float64],
    cmu24: NDArray[np.float64], hc: NDArray[np.float64], lsq: NDArray[np.float64],
    s0: NDArray[np.float64], nu0: NDArray[np.float64], max_iter: int, tol: float, eye8: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """SQP of the reduced alpha-step ``min s^T G s - 2 lin^T s`` s.t. ``||C_i mu + C_i U S s||^2 =
    L_i`` with the exact Lagrangian Hessian (Gauss-Newton ``2 G`` where that is not positive
    definite on the constraints' tangent space) from a Gauss-Newton projection of ``s0``; steps
    halved until the merit ``f + rho ||g||_1`` decreases (the same problem as
    :func:`newton_alpha` on ``model.reduced``). Returns ``(s, multipliers (8,), iterations)``."""
    r = s0.size
    s = _project_limbs(s0.copy(), 30, cu24, cmu24, lsq, eye8)
    nu = nu0.copy()
    rho = 10.0
    kmat = np.zeros((r + 8, r + 8))
    rhs = np.empty(r + 8)
    g2 = 2.0 * gmat
    it = 0
    for it in range(1, max_iter + 1):
        g, lv = _limbs(s, cu24, cmu24, lsq)
        jac = _limb_jacobian(lv, cu24)
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
        jtj = jac.T @ jac
        test = hess + (10.0 * float(np.abs(hess).max()) / max(float(np.abs(jtj).max()), 1e-300)) * jtj
        if not _pos_def(test):
            hess = g2
        kmat[:r, :r] = hess
        kmat[:r, r:] = jac.T
        kmat[r:, :r] = jac
        rhs[:r] = -grad
        rhs[r:] = -g
        sol = _solve(kmat, rhs)
        ds, nu_new = sol[:r], sol[r:]
        rho = max(rho, 2.0 * float(np.abs(nu_new).max()))
        q0 = float(s @ gs - 2.0 * lin @ s)
        f0 = q0 + rho * np.sum(np.abs(g))
        a = 1.0
        cand = s + ds
        gc, lvc = _limbs(cand, cu24, cmu24, lsq)
        # along the step the objective is the quadratic q0 + a q1 + a^2 q2 and the limb vectors
        # are affine in a: no matrix products in the backtracking loop
        q1 = float(grad @ ds)
        q2 = float(ds @ gmat @ ds)
        dlv = lvc - lv
        while a > 1e-4:
            if q0 + a * (q1 + a * q2) + rho * np.sum(np.abs(gc)) <= f0 + 1e-12:
                break
            a *= 0.5
            lva = lv + a * dlv
            gc = (lva * lva).reshape(8, 3).sum(axis=1) - lsq
        s = s + a * ds if a < 1.0 else cand
        nu = nu_new
    return _project_limbs(s, 10, cu24, cmu24, lsq, eye8), nu, it


@njit
def _cholesky_solve(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray[np.float64], bool]:
    """``a^-1 b`` by a Cholesky factorisation of the symmetric ``a`` (n, n) (lower triangle read);
    ``(x, True)``, or ``(b, False)`` when ``a`` is not (numerically) positive definite. Written
    out: at n = 16 a LAPACK call costs more than the arithmetic."""
    n = a.shape[0]
    lo = np.zeros((n, n))
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= lo[j, k] * lo[j, k]
        if not d > 1e-14 * abs(a[j, j]) or not d > 0.0:
            return b, False
        d = math.sqrt(d)
        lo[j, j] = d
        for i in range(j + 1, n):
            e = a[i, j]
            for k in range(j):
                e -= lo[i, k] * lo[j, k]
            lo[i, j] = e / d
    y = np.empty(n)
    for i in range(n):
        e = b[i]
        for k in range(i):
            e -= lo[i, k] * y[k]
        y[i] = e / lo[i, i]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        e = y[i]
        for k in range(i + 1, n):
            e -= lo[k, i] * x[k]
        x[i] = e / lo[i, i]
    return x, True


@njit
def _retract_into(x: NDArray[np.float64], prev: NDArray[np.float64], rad: NDArray[np.float64],
                  out: NDArray[np.float64]) -> None:
    """Projection of the 8 limb vectors ``x`` (24,) onto their spheres ``||l_i|| = rad_i``,
    written into ``out`` (may be ``x``; not ``prev``); a (near-)zero limb keeps the direction of
    ``prev``."""
    for i in range(8):
        x0, x1, x2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        n = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if n < 1e-12 * rad[i]:
            x0, x1, x2 = prev[3 * i], prev[3 * i + 1], prev[3 * i + 2]
            n = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
            if n == 0.0:
                x0, x1, x2, n = 1.0, 0.0, 0.0, 1.0
        f = rad[i] / n
        out[3 * i], out[3 * i + 1], out[3 * i + 2] = x0 * f, x1 * f, x2 * f


@njit
def _quad_into(q: NDArray[np.float64], b: NDArray[np.float64], x: NDArray[np.float64],
               qx: NDArray[np.float64]) -> float:
    """``Q x`` written into ``qx`` (24,); returns ``x^T Q x - 2 b^T x`` (``Q`` (24, 24) symmetric)."""
    qx[:] = 0.0
    for j in range(24):  # Q symmetric: Q x = sum_j Q[j] x_j (vectorisable, no reduction chain)
        xj = x[j]
        for i in range(24):
            qx[i] += q[j, i] * xj
    f = 0.0
    for i in range(24):
        f += x[i] * (qx[i] - 2.0 * b[i])
    return f


@njit
def _sphere_newton(q: NDArray[np.float64], b: NDArray[np.float64], l0: NDArray[np.float64],
                   rad: NDArray[np.float64], max_iter: int, tol: float
                   ) -> tuple[NDArray[np.float64], int, bool]:
    """Riemannian Newton for ``min_l l^T Q l - 2 b^T l`` over the product of 8 spheres
    ``||l_i|| = rad_i`` (``l`` = the 8 limb vectors, (24,); ``Q`` (24, 24) positive definite).

    Each iteration: the Riemannian gradient (the Euclidean one projected on the tangent
    spaces, i.e. the KKT residual with least-squares multipliers ``mu_i``), the Riemannian
    Hessian ``T^T (2 Q + 2 diag(mu_i I_3)) T`` in orthonormal tangent bases ``T`` (24, 16),
    shifted by a multiple of the identity until it is positive definite (so the step is a
    descent direction), the step retracted onto the spheres by normalisation, and Armijo
    backtracking on the objective (every iterate is feasible: no merit function, no Maratos
    effect). Stops when ``||grad_R|| <= tol * max(1, ||grad||)`` or when the Newton step
    predicts a decrease below ``1e-13 * max(1, |f|)`` (converged), or when the line search fails
    (not converged); returns ``(l, iterations, converged)``. Written with scalars and reused
    buffers (it runs once per pose-ADM iteration).
    """
    l = np.empty(24)
    _retract_into(l0, l0, rad, l)
    ql = np.empty(24)
    f = _quad_into(q, b, l, ql)
    cand = np.empty(24)
    qc = np.empty(24)
    d = np.empty(24)
    eg = np.empty(24)
    tb = np.empty((24, 2))  # tangent basis: rows 3i..3i+2 hold sphere i's two vectors
    gr = np.empty(16)
    mu = np.empty(8)
    w = np.empty((24, 16))
    hr = np.empty((16, 16))
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        egn = 0.0
        for i in range(24):
            eg[i] = 2.0 * (ql[i] - b[i])
            egn += eg[i] * eg[i]
        gn = 0.0
        for i in range(8):
            u0, u1, u2 = l[3 * i] / rad[i], l[3 * i + 1] / rad[i], l[3 * i + 2] / rad[i]
            g0, g1, g2 = eg[3 * i], eg[3 * i + 1], eg[3 * i + 2]
            # orthonormal completion of u (Duff et al. 2017, "Building an orthonormal basis,
            # revisited": no branch near the poles)
            sign = 1.0 if u2 >= 0.0 else -1.0
            aa = -1.0 / (sign + u2)
            bb = u0 * u1 * aa
            e10, e11, e12 = 1.0 + sign * u0 * u0 * aa, sign * bb, -sign * u0
            e20, e21, e22 = bb, sign + u1 * u1 * aa, -u1
            tb[3 * i, 0], tb[3 * i + 1, 0], tb[3 * i + 2, 0] = e10, e11, e12
            tb[3 * i, 1], tb[3 * i + 1, 1], tb[3 * i + 2, 1] = e20, e21, e22
            mu[i] = -(u0 * g0 + u1 * g1 + u2 * g2) / (2.0 * rad[i])
            ga = e10 * g0 + e11 * g1 + e12 * g2
            gb = e20 * g0 + e21 * g1 + e22 * g2
            gr[2 * i], gr[2 * i + 1] = ga, gb
            gn += ga * ga + gb * gb
        if math.sqrt(gn) <= tol * max(1.0, math.sqrt(egn)):
            converged = True
            it -= 1
            break
        # W = 2 Q T, then H = T^T W + 2 diag(mu_i): T is block diagonal (3 x 2 blocks)
        for row in range(24):
            for j in range(8):
                q0, q1, q2 = q[row, 3 * j], q[row, 3 * j + 1], q[row, 3 * j + 2]
                w[row, 2 * j] = 2.0 * (q0 * tb[3 * j, 0] + q1 * tb[3 * j + 1, 0] + q2 * tb[3 * j + 2, 0])
                w[row, 2 * j + 1] = 2.0 * (q0 * tb[3 * j, 1] + q1 * tb[3 * j + 1, 1] + q2 * tb[3 * j + 2, 1])
        scale = 0.0
        for i in range(8):
            for e in range(2):
                t0, t1, t2 = tb[3 * i, e], tb[3 * i + 1, e], tb[3 * i + 2, e]
                for col in range(16):
                    hr[2 * i + e, col] = t0 * w[3 * i, col] + t1 * w[3 * i + 1, col] + t2 * w[3 * i + 2, col]
                hr[2 * i + e, 2 * i + e] += 2.0 * mu[i]
        for i in range(16):
            scale = max(scale, abs(hr[i, i]))
        # modified Newton: the smallest shift c * 4^k making it positive definite
        shift = 0.0
        ok = False
        step = gr
        for _ in range(60):
            for i in range(16):
                hr[i, i] += shift
            step, ok = _cholesky_solve(hr, gr)
            for i in range(16):
                hr[i, i] -= shift
            if ok:
                break
            shift = 1e-6 * max(scale, 1e-300) if shift == 0.0 else 4.0 * shift
        if not ok:
            break
        slope = 0.0
        for i in range(16):
            slope -= gr[i] * step[i]
        if not slope < -1e-13 * max(1.0, abs(f)):
            # the predicted decrease is at the round-off level of f: stationary to working
            # precision (the gradient test can be out of reach when |Q l| >> |grad|)
            converged = True
            break
        for i in range(8):  # d = -T step
            sa, sb = step[2 * i], step[2 * i + 1]
            for p in range(3):
                d[3 * i + p] = -(tb[3 * i + p, 0] * sa + tb[3 * i + p, 1] * sb)
        a = 1.0
        accepted = False
        fc = f
        while a > 1e-10:
            for i in range(24):
                cand[i] = l[i] + a * d[i]
            _retract_into(cand, l, rad, cand)
            fc = _quad_into(q, b, cand, qc)
            if fc <= f + 1e-4 * a * slope:
                accepted = True
                break
            a *= 0.5
        if not accepted:
            break
        l, cand = cand, l
        ql, qc = qc, ql
        f = fc
    return l, it, converged


@njit
def _sphere_setup(g: NDArray[np.float64], z: NDArray[np.float64], n: NDArray[np.float64]
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                             NDArray[np.float64]]:
    """The alpha-step's quadratic ``s^T G s - 2 lin^T s`` in limb coordinates.

    With ``s = s0 + Z l + N t`` (``l`` the 8 limb vectors (24,), ``t`` free (m,), ``Z`` (r, 24)
    a right inverse and ``N`` (r, m) a null-space basis of the limb map), the free part ``t`` is
    eliminated in closed form. Returns ``Q`` (24, 24), ``R`` (24, r), ``S1`` (r, 24), ``S2``
    (r, r) such that, with ``h = lin - G s0``, the objective is ``l^T Q l - 2 (R h)^T l`` up to a
    constant and the minimising ``s`` for given ``l`` is ``s0 + S1 l + S2 h``.
    """
    gz = g @ z
    k1 = np.linalg.inv(n.T @ (g @ n)) @ n.T  # (m, r): t = k1 (h - G Z l)
    gzn = gz.T @ n  # (24, m)
    q = z.T @ gz - gzn @ (k1 @ gz)
    return 0.5 * (q + q.T), z.T - gzn @ k1, z - n @ (k1 @ gz), n @ k1


@njit
def _newton_alpha_kernel(
    d1: NDArray[np.float64], d2: NDArray[np.float64], alpha: NDArray[np.float64], mus: NDArray[np.float64],
    v: NDArray[np.float64], g_red: NDArray[np.float64], cu24: NDArray[np.float64],
    cmu24: NDArray[np.float64], hc: NDArray[np.float64], lsq: NDArray[np.float64], max_iter: int, tol: float,
    eye8: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The reduced Newton alpha-step of :func:`pose_step` (limbs on), multipliers from zero (warm
    multipliers from the previous ADM iteration were measured no better)."""
    vtd2 = v.T @ d2
    lin = mus.T @ d1 + vtd2
    s, _, _ = _newton_kernel(g_red, lin, cu24, cmu24, hc, lsq, v.T @ alpha, np.zeros(8), max_iter, tol, eye8)
    return d2 - v @ vtd2 + v @ s


@njit
def _axpy_rows(at: NDArray[np.float64], x: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """``out += at.T @ x`` as a sum of the rows of ``at`` (n, m) (C-contiguous): each step is a
    vectorisable axpy over m, with no floating-point reduction chain (which LLVM may not
    reorder, so a dot-product loop runs at one add per ~4 cycles)."""
    for p in range(at.shape[0]):
        xp = x[p]
        for q in range(at.shape[1]):
            out[q] += at[p, q] * xp


@njit
def _riemannian_alpha_kernel(
    d1: NDArray[np.float64], d2: NDArray[np.float64], sk: NDArray[np.float64], mus: NDArray[np.float64],
    vc: NDArray[np.float64], vt: NDArray[np.float64], gs0: NDArray[np.float64], q: NDArray[np.float64],
    rmat_t: NDArray[np.float64], s1_t: NDArray[np.float64], s2_t: NDArray[np.float64],
    s0: NDArray[np.float64], cu24_t: NDArray[np.float64], cmu24: NDArray[np.float64],
    rad: NDArray[np.float64], max_iter: int, tol: float, prox: float, alpha_out: NDArray[np.float64],
    s_out: NDArray[np.float64],
) -> int:
    """The alpha-step of :func:`pose_step` (limbs on) by :func:`_sphere_newton` in limb
    coordinates (see :func:`_sphere_setup`), started from the limb vectors of the current
    iterate, whose reduced coordinates are ``sk = V^T alpha_k`` (r,). Writes ``alpha`` (k,) and
    ``s = V^T alpha`` (r,) into ``alpha_out``, ``s_out`` (which may be ``sk``); returns the
    Newton iterations. Matrices come C-contiguous and transposed where that makes every product
    a sum of rows (:func:`_axpy_rows`): ``vc = V`` (k, r), ``vt = V^T`` (r, k), ``mus = M U S``
    (24, r), ``rmat_t = R^T`` (r, 24), ``s1_t = S1^T`` (24, r), ``s2_t = S2^T`` (r, r),
    ``cu24_t = (C U S)^T`` (r, 24)."""
    r = sk.size
    vtd2 = np.zeros(r)
    _axpy_rows(vc, d2, vtd2)  # V^T d2
    h = np.zeros(r)
    _axpy_rows(mus, d1, h)  # (M U S)^T d1
    for j in range(r):
        h[j] += vtd2[j] + prox * sk[j] - gs0[j]
    b = np.zeros(24)
    _axpy_rows(rmat_t, h, b)
    l0 = cmu24.copy()
    _axpy_rows(cu24_t, sk, l0)
    lv, it, _ = _sphere_newton(q, b, l0, rad, max_iter, tol)
    s = s0.copy()
    _axpy_rows(s1_t, lv, s)
    _axpy_rows(s2_t, h, s)
    for j in range(r):
        s_out[j] = s[j]
        s[j] -= vtd2[j]
    alpha_out[:] = d2
    _axpy_rows(vt, s, alpha_out)  # d2 + V (s - V^T d2)
    return it


@njit
def _objective(resid: NDArray[np.float64], wts: NDArray[np.float64], alpha: NDArray[np.float64],
               theta: float, l1: bool) -> float:
    """:func:`pose_objective` on plain arrays (``l1`` False: squared loss)."""
    data = np.sum(wts * np.abs(resid)) if l1 else np.sum(wts * resid * resid)
    return float(data + theta * np.sum(np.abs(alpha)))


@njit
def _adm_split(
    c: NDArray[np.float64], ax: NDArray[np.float64], u1: NDArray[np.float64], u2: NDArray[np.float64],
    alpha: NDArray[np.float64], wts: NDArray[np.float64], eta: float, th: float, l1: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """gamma- and beta-steps of the pose ADM: ``(gamma, beta, d1, d2)`` of the module docstring
    (``ax = A alpha``; ``th = 0``: no sparsity)."""
    vg = c - ax + u1
    if l1:
        gamma = np.sign(vg) * np.maximum(np.abs(vg) - wts / eta, 0.0)
    else:
        gamma = eta * vg / (2.0 * wts + eta)
    vb = alpha + u2
    beta = np.sign(vb) * np.maximum(np.abs(vb) - th / eta, 0.0) if th > 0 else vb
    return gamma, beta, c - gamma + u1, beta - u2


@njit
def _grow_penalty(eta: float, eta_growth: float, eta_max: float, u1: NDArray[np.float64],
                  u2: NDArray[np.float64]) -> float:
    """The pose ADM's penalty schedule: ``eta <- min(eta * eta_growth, eta_max)``, with the
    scaled multipliers ``u1``, ``u2`` rescaled in place so the unscaled ones are unchanged."""
    if eta_growth != 1.0 and eta < eta_max:
        eta_new = min(eta * eta_growth, eta_max)
        u1 *= eta / eta_new
        u2 *= eta / eta_new
        return eta_new
    return eta


@njit
def _adm_dual_update(
    c: NDArray[np.float64], gamma: NDArray[np.float64], alpha: NDArray[np.float64],
    beta: NDArray[np.float64], beta_prev: NDArray[np.float64], ax_prev: NDArray[np.float64],
    u1: NDArray[np.float64], u2: NDArray[np.float64], mus: NDArray[np.float64], v: NDArray[np.float64],
    wts: NDArray[np.float64], th: float, l1: bool, scale_c: float,
) -> tuple[NDArray[np.float64], float, float, float]:
    """After the alpha-step of the pose ADM: ``u1``, ``u2`` updated in place; returns ``A alpha``,
    the objective and the relative primal and dual residuals."""
    ax = mus @ (v.T @ alpha)
    r1 = c - ax - gamma
    r2 = alpha - beta
    u1 += r1
    u2 += r2
    obj = _objective(c - ax, wts, alpha, th, l1)
    an = max(1.0, math.sqrt(float(alpha @ alpha)))
    primal = max(math.sqrt(float(r1 @ r1)) / scale_c, math.sqrt(float(r2 @ r2)) / an)
    dax = ax - ax_prev
    dbeta = beta - beta_prev
    dual = max(math.sqrt(float(dax @ dax)) / scale_c, math.sqrt(float(dbeta @ dbeta)) / an)
    return ax, obj, primal, dual


@njit
def _riemannian_adm_kernel(
    c: NDArray[np.float64], wts: NDArray[np.float64], mus: NDArray[np.float64], vc: NDArray[np.float64],
    vt: NDArray[np.float64], gs0: NDArray[np.float64], q: NDArray[np.float64], rmat: NDArray[np.float64],
    s1: NDArray[np.float64], s2: NDArray[np.float64], s0: NDArray[np.float64], cu24_t: NDArray[np.float64],
    cmu24: NDArray[np.float64],
    rad: NDArray[np.float64], alpha0: NDArray[np.float64], u1: NDArray[np.float64], u2: NDArray[np.float64],
    best_obj: float, eta: float, eta_growth: float, eta_max: float, th: float, l1: bool, max_iter: int,
    tol: float, alpha_max_iter: int, alpha_tol: float, prox: float, scale_c: float,
) -> tuple[NDArray[np.float64], float, float, int, bool]:
    """The pose ADM loop of :func:`pose_step` with the Riemannian alpha-step, in one kernel (the
    Python loop's updates; ``V^T alpha`` is carried instead of recomputed). ``u1``, ``u2``
    (scaled multipliers) are updated in place. ``vc = V`` (k, r), ``vt = V^T`` (r, k) and
    ``cu24_t = (C U S)^T`` (r, 24) come C-contiguous (``PoseModel.riemannian_arrays``). Returns
    ``(best alpha, best objective, final eta, iterations, converged)``; ``best_obj`` is the
    objective of ``alpha0`` if feasible, else ``inf``."""
    m = c.size
    k = alpha0.size
    alpha = alpha0.copy()
    best_alpha = alpha.copy()
    beta = alpha.copy()
    beta_prev = np.empty(k)
    gamma = np.empty(m)
    d1 = np.empty(m)
    d2 = np.empty(k)
    sk = vt @ alpha
    ax = mus @ sk
    converged = False
    it = 0
    # the vector updates are written as loops (fused, no temporaries): the same arithmetic as
    # _adm_split / _adm_dual_update, summed sequentially
    ax_prev = np.empty(m)
    # C-contiguous operands in the orientation _axpy_rows wants (camera-dependent: per pose step)
    mus_t = np.ascontiguousarray(mus.T)
    rmat_t = np.ascontiguousarray(rmat.T)
    s1_t = np.ascontiguousarray(s1.T)
    s2_t = np.ascontiguousarray(s2.T)
    for it in range(1, max_iter + 1):
        beta, beta_prev = beta_prev, beta
        for i in range(m):  # gamma-step (prox of the data term)
            vg = c[i] - ax[i] + u1[i]
            if l1:
                gi = math.copysign(max(abs(vg) - wts[i] / eta, 0.0), vg)
            else:
                gi = eta * vg / (2.0 * wts[i] + eta)
            gamma[i] = gi
            d1[i] = c[i] - gi + u1[i]
        for i in range(k):  # beta-step (prox of theta ||.||_1)
            vb = alpha[i] + u2[i]
            bi = math.copysign(max(abs(vb) - th / eta, 0.0), vb) if th > 0 else vb
            beta[i] = bi
            d2[i] = bi - u2[i]
        _riemannian_alpha_kernel(d1, d2, sk, mus, vc, vt, gs0, q, rmat_t, s1_t, s2_t, s0, cu24_t, cmu24, rad,
                                 alpha_max_iter, alpha_tol, prox, alpha, sk)
        ax, ax_prev = ax_prev, ax
        ax[:] = 0.0
        _axpy_rows(mus_t, sk, ax)
        r1sq, dsq, data = 0.0, 0.0, 0.0
        for i in range(m):
            e = c[i] - ax[i]
            data += wts[i] * (abs(e) if l1 else e * e)
            r = e - gamma[i]
            u1[i] += r
            r1sq += r * r
            dsq += (ax[i] - ax_prev[i]) ** 2
        r2sq, asq, anorm1, dbsq = 0.0, 0.0, 0.0, 0.0
        for i in range(k):
            a = alpha[i]
            r = a - beta[i]
            u2[i] += r
            r2sq += r * r
            asq += a * a
            anorm1 += abs(a)
            dbsq += (beta[i] - beta_prev[i]) ** 2
        obj = data + th * anorm1
        an = max(1.0, math.sqrt(asq))
        primal = max(math.sqrt(r1sq) / scale_c, math.sqrt(r2sq) / an)
        dual = max(math.sqrt(dsq) / scale_c, math.sqrt(dbsq) / an)
        eta = _grow_penalty(eta, eta_growth, eta_max, u1, u2)
        if obj < best_obj:
            best_obj = obj
            best_alpha[:] = alpha
        if primal < tol and dual < tol:
            converged = True
            break
    if not math.isfinite(best_obj):
        best_alpha = alpha
    return best_alpha, best_obj, eta, it, converged


@njit
def _limb_violation_jit(y: NDArray[np.float64], limb_matrix: NDArray[np.float64], rad: NDArray[np.float64]
                        ) -> float:
    """:meth:`PoseModel.limb_violation` of the pose ``y`` (36,)."""
    lv = limb_matrix @ y
    out = 0.0
    for i in range(8):
        n = math.sqrt(lv[3 * i] ** 2 + lv[3 * i + 1] ** 2 + lv[3 * i + 2] ** 2)
        out = max(out, abs(n - rad[i]))
    return out


@njit
def _riemannian_pose_kernel(
    x: NDArray[np.float64], m0: NDArray[np.float64], t: NDArray[np.float64], w: NDArray[np.float64],
    mean: NDArray[np.float64], u: NDArray[np.float64], sig: NDArray[np.float64], vc: NDArray[np.float64],
    vt: NDArray[np.float64], comps: NDArray[np.float64], limb_matrix: NDArray[np.float64],
    z: NDArray[np.float64], n: NDArray[np.float64], s0: NDArray[np.float64], rad: NDArray[np.float64],
    cu24_t: NDArray[np.float64], cmu24: NDArray[np.float64], alpha0: NDArray[np.float64],
    u1: NDArray[np.float64], u2: NDArray[np.float64],
    th: float, l1: bool, eta: float, eta_growth: float, eta_max: float, max_iter: int, tol: float,
    alpha_max_iter: int, alpha_tol: float, prox: float,
    xp: NDArray[np.float64], pw: NDArray[np.float64], m3: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float, float, NDArray[np.float64], float, int, bool]:
    """:func:`pose_step` with the Riemannian alpha-step, set-up included: ``c = x - t - M mu``,
    ``M U S``, the limb-coordinate quadratic (:func:`_sphere_setup`), then
    :func:`_riemannian_adm_kernel`. Shapes: x (12, 2), m0 (2, 3), t (2,), w (12,), alpha0 (k,),
    u1 (m,), u2 (k,) (scaled multipliers, updated in place; ``m`` = 24 + the prior rows below).

    Prior rows (the hybrid mode's L1 prior term, :class:`pose_lifter.core.lifter.Lifter`): for
    each joint ``j`` with ``pw[j, 0] > 0`` two rows ``pw[j, 0] |xp[j, a] - t_a - M_a y_j|`` (the
    prior's image position, a = x, y), and with ``pw[j, 1] > 0`` one row
    ``pw[j, 1] |xp[j, 2] - m3 (y_j - mean_i y_i)|`` (its depth relative to the joints' mean;
    ``m3`` = scale times the camera's third rotation row). ``pw`` all zero: the paper's problem.
    Returns ``(alpha, objective, limb violation, pose (36,), final eta, iterations,
    converged)``."""
    r = sig.size
    nj = x.shape[0]
    n_xy = 0
    n_z = 0
    for j in range(nj):
        n_xy += 1 if pw[j, 0] > 0.0 else 0
        n_z += 1 if pw[j, 1] > 0.0 else 0
    m = 2 * nj + 2 * n_xy + n_z
    wts = np.empty(m)
    c = np.empty(m)
    mus = np.empty((m, r))
    for j in range(nj):
        for a in range(2):
            wts[2 * j + a] = w[j]
            c[2 * j + a] = x[j, a] - t[a] - (m0[a, 0] * mean[3 * j] + m0[a, 1] * mean[3 * j + 1]
                                             + m0[a, 2] * mean[3 * j + 2])
            for k in range(r):
                mus[2 * j + a, k] = (m0[a, 0] * u[3 * j, k] + m0[a, 1] * u[3 * j + 1, k]
                                     + m0[a, 2] * u[3 * j + 2, k]) * sig[k]
    row = 2 * nj
    for j in range(nj):  # the prior's image positions: rows like the data rows
        if pw[j, 0] > 0.0:
            for a in range(2):
                wts[row] = pw[j, 0]
                c[row] = xp[j, a] - t[a] - (m0[a, 0] * mean[3 * j] + m0[a, 1] * mean[3 * j + 1]
                                            + m0[a, 2] * mean[3 * j + 2])
                for k in range(r):
                    mus[row, k] = (m0[a, 0] * u[3 * j, k] + m0[a, 1] * u[3 * j + 1, k]
                                   + m0[a, 2] * u[3 * j + 2, k]) * sig[k]
                row += 1
    if n_z > 0:  # the prior's relative depths: m3 (y_j - mean_i y_i)
        ubar = np.zeros((3, r))
        mbar = np.zeros(3)
        for j in range(nj):
            for a in range(3):
                mbar[a] += mean[3 * j + a] / nj
                for k in range(r):
                    ubar[a, k] += u[3 * j + a, k] / nj
        for j in range(nj):
            if pw[j, 1] > 0.0:
                wts[row] = pw[j, 1]
                c[row] = xp[j, 2] - (m3[0] * (mean[3 * j] - mbar[0]) + m3[1] * (mean[3 * j + 1] - mbar[1])
                                     + m3[2] * (mean[3 * j + 2] - mbar[2]))
                for k in range(r):
                    mus[row, k] = (m3[0] * (u[3 * j, k] - ubar[0, k]) + m3[1] * (u[3 * j + 1, k] - ubar[1, k])
                                   + m3[2] * (u[3 * j + 2, k] - ubar[2, k])) * sig[k]
                row += 1
    g = mus.T @ mus
    for k in range(r):
        g[k, k] += 1.0 + prox
    q, rmat, s1, s2 = _sphere_setup(g, z, n)
    gs0 = g @ s0
    best_obj = np.inf
    if _limb_violation_jit(mean + comps @ alpha0, limb_matrix, rad) < 1e-6:
        best_obj = _objective(c - mus @ (vt @ alpha0), wts, alpha0, th, l1)
    scale_c = max(1.0, math.sqrt(float(c @ c)))
    best_alpha, best_obj, eta, it, converged = _riemannian_adm_kernel(
        c, wts, mus, vc, vt, gs0, q, rmat, s1, s2, s0, cu24_t, cmu24, rad, alpha0, u1, u2, best_obj, eta,
        eta_growth, eta_max, th, l1, max_iter, tol, alpha_max_iter, alpha_tol, prox, scale_c)
    if not math.isfinite(best_obj):
        best_obj = _objective(c - mus @ (vt @ best_alpha), wts, best_alpha, th, l1)
    y = mean + comps @ best_alpha
    return best_alpha, best_obj, _limb_violation_jit(y, limb_matrix, rad), y, eta, it, converged


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
        model pose to depth in the same units (``r3 = r1 x r2``)."""
        a, b = projection[0], projection[1]
        # r1 x r2 written out (np.cross costs ~60 us in argument handling; same arithmetic)
        cross = np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
        return cross / max(float(np.sqrt(a @ a)), 1e-300)

    def depth_term(self, pose: NDArray[np.float64], projection: NDArray[np.float64]) -> float:
        """``sum_j weights[j, 1] |target[j, 2] - m3 (y_j - mean_i y_i)|`` for a pose (12, 3)."""
        d = (pose - pose.mean(axis=0)) @ self.depth_row(projection)
        return float(self.weights[:, 1] @ np.abs(self.target[:, 2] - d))


_NO_PRIOR = (np.zeros((N_JOINTS, 3)), np.zeros((N_JOINTS, 2)), np.zeros(3))


def pose_objective(
    resid: NDArray[np.float64], wts: NDArray[np.float64], alpha: NDArray[np.float64], theta: float,
    loss: Literal["l1", "l2"],
) -> float:
    """``sum w rho(resid) + theta ||alpha||_1`` (resid, wts: shape (2n,))."""
    return _objective(np.ascontiguousarray(resid, dtype=np.float64),
                      np.ascontiguousarray(wts, dtype=np.float64),
                      np.ascontiguousarray(alpha, dtype=np.float64), float(theta), loss == "l1")


def _riemannian_pose_step(
    x: NDArray[np.float64], m0: NDArray[np.float64], translation: NDArray[np.float64],
    weights: NDArray[np.float64], model: PoseModel, l1: bool, th: float, alpha0: NDArray[np.float64],
    max_iter: int, tol: float, eta: float, eta_growth: float, eta_max: float,
    duals: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    state_out: list[tuple[NDArray[np.float64], NDArray[np.float64]]] | None, newton_tol: float,
    alpha_prox: float, prior: PriorRows | None = None,
) -> PoseResult:
    """:func:`pose_step` with ``alpha_solver="riemannian"`` (limbs on, reduced lifting, onto limb
    map): one call of :func:`_riemannian_pose_kernel`."""
    k = model.n_bases
    alpha = np.ascontiguousarray(alpha0, dtype=np.float64)
    if alpha.shape != (k,):
        raise InvalidInputError(f"alpha0 must have shape ({k},), got {alpha.shape}")
    coords = model.limb_coordinates
    assert coords is not None
    z, n, s0, rad = coords
    if prior is not None and prior.limb_radii is not None:
        rad = np.ascontiguousarray(prior.limb_radii, dtype=np.float64)
    cmu24 = model.kernel_limbs[1]
    if prior is None:
        xp, pw, m3 = _NO_PRIOR
    else:
        xp, pw = prior.target, prior.weights
        m3 = prior.depth_row(m0)
    m = 2 * N_JOINTS + 2 * int(np.count_nonzero(pw[:, 0] > 0)) + int(np.count_nonzero(pw[:, 1] > 0))
    if duals is None or duals[0].shape != (m,):
        u1, u2 = np.zeros(m), np.zeros(k)
    else:
        u1 = np.asarray(duals[0], dtype=np.float64) / eta
        u2 = np.asarray(duals[1], dtype=np.float64) / eta
    vc, vt, cu24_t = model.riemannian_arrays
    best, obj, viol, y, eta_end, it, converged = _riemannian_pose_kernel(
        np.ascontiguousarray(x), np.ascontiguousarray(m0),
        np.ascontiguousarray(translation, dtype=np.float64), np.ascontiguousarray(weights, dtype=np.float64),
        model.mean, model.u, model.sig, vc, vt, model.components, model._limb_matrix, z, n, s0, rad, cu24_t,
        cmu24, alpha, u1, u2, float(th), bool(l1), float(eta), float(eta_growth), float(eta_max),
        int(max_iter), float(tol), RIEMANNIAN_MAX_ITER, float(newton_tol), float(alpha_prox), xp, pw, m3)
    if state_out is not None:
        state_out.append((eta_end * u1, eta_end * u2))
    if not np.all(np.isfinite(best)):
        raise SolverError("pose step diverged (non-finite coefficients)")
    return PoseResult(best, y.reshape(N_JOINTS, 3), float(obj), float(viol), int(it), bool(converged))


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
    alpha_prox: float = 1.0,
    prior: PriorRows | None = None,
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
    alpha_solver : {"admm", "newton", "riemannian"}
        ``"riemannian"`` needs limbs on, the reduced lifting and an onto limb map
        (``model.limb_coordinates``); otherwise ``"newton"`` is used.
    qstep_fn : callable, optional
        Replaces the closed-form Q-step (the cvxpy reference path).
    duals : (ndarray (24,), ndarray (k,)), optional
        Warm start of the (unscaled) ADM multipliers of ``gamma = c - A alpha`` and
        ``beta = alpha``, e.g. from the previous alternation (default zeros).
    state_out : list, optional
        If given, the final unscaled multipliers are appended to it (for the next warm start).
    newton_tol : float
        Relative KKT tolerance of the reduced Newton alpha-step (``alpha_solver="newton"``) and
        of the Riemannian one (which stops at ``RIEMANNIAN_MAX_ITER`` steps first, as a rule).
    alpha_prox : float
        Proximal weight of the Riemannian alpha-step (``LifterOptions.alpha_prox``).
    prior : PriorRows, optional
        The hybrid mode's L1 prior term (:class:`PriorRows`), added to the objective; needs the
        Riemannian path (limbs on, reduced lifting, onto limb map).

    Returns
    -------
    PoseResult
        The iterate with the lowest objective among the feasible ones visited.

    Raises
    ------
    InvalidInputError
        ``alpha0`` of the wrong shape, or a prior term without the Riemannian path.
    SolverError
        The ADM diverged (non-finite coefficients).
    """
    loss = variant.loss
    th = float(theta) if variant.sparsity else 0.0
    x = np.asarray(points, dtype=np.float64)
    m0 = np.asarray(projection, dtype=np.float64)
    k = model.n_bases
    if (alpha_solver == "riemannian" and variant.limbs and alpha_step != "full"
            and model.limb_coordinates is not None):
        with diverged_as_solver_error("pose step"):
            return _riemannian_pose_step(x, m0, translation, weights, model, loss == "l1", th, alpha0,
                                         max_iter, tol, eta, eta_growth, eta_max, duals, state_out,
                                         newton_tol, alpha_prox, prior)
    if prior is not None:
        raise InvalidInputError("a prior term needs alpha_solver='riemannian' with limbs, the reduced "
                                "lifting and bases whose limb map is onto (>= 24 basis directions)")
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
    if alpha_solver == "riemannian":  # not applicable here (limbs off, full lifting or a limb map
        alpha_solver = "newton"        # that is not onto): the SQP solves the same problem

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
            if alpha_solver == "newton" and variant.limbs:
                return _newton_alpha_kernel(d1, d2, alpha, mus, v, g_red, *model.kernel_limbs,
                                            NEWTON_MAX_ITER, float(newton_tol), _EYE8)
            vtd2 = v.T @ d2
            lin = mus.T @ d1 + vtd2
            if not variant.limbs:
                s = np.linalg.solve(g_red, lin)
                return np.asarray(d2 - v @ vtd2 + v @ s)
            r = sig.size
            wmat = np.zeros((r + 1, r + 1))
            wmat[:r, :r] = g_red
            wmat[:r, r] = -lin
            wmat[r, :r] = -lin
            wmat[r, r] = float(d1 @ d1 + vtd2 @ vtd2)
            z0 = np.append(v.T @ alpha, 1.0)
        if alpha_solver == "newton":  # the full lifting (the reduced one returned above)
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
    l1 = loss == "l1"
    ax = a_times(alpha)
    for it in range(1, max_iter + 1):
        beta_prev, ax_prev = beta, ax
        gamma, beta, d1, d2 = _adm_split(c, ax, u1, u2, alpha, wts, float(eta), th, l1)
        alpha = alpha_update(d1, d2, alpha)
        ax, obj, primal, dual = _adm_dual_update(c, gamma, alpha, beta, beta_prev, ax_prev, u1, u2, mus, v,
                                                 wts, th, l1, scale_c)
        eta = _grow_penalty(float(eta), float(eta_growth), float(eta_max), u1, u2)
        if obj < best_obj:
            best_obj, best_alpha = obj, alpha.copy()
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
        raise SolverError("pose step diverged (non-finite coefficients)")
    viol = model.limb_violation(best_alpha) if variant.limbs else 0.0
    return PoseResult(best_alpha, model.pose(best_alpha), best_obj, viol, it, converged)
