"""SQP alpha-step: Newton on the KKT system of the limb-constrained least squares (the paper's
alpha-step problem, solved directly), in the lifting and in the reduced coordinates (compiled)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ...model.pose_model import LiftedConstraints, PoseModel
from ...numeric.jit import njit
from ...numeric.linalg import _EYE8, _pos_def, _solve
from ...results import AlphaResult
from .lifted_admm import restore_feasibility

#: SQP iteration cap of each Newton alpha-step.
NEWTON_MAX_ITER = 10


def newton_alpha(
    w: NDArray[np.float64], cons: LiftedConstraints, z0: NDArray[np.float64], max_iter: int = 30,
    tol: float = 1e-10,
) -> AlphaResult:
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
        # as the compiled kernel: the Lagrangian Hessian only where it is positive definite on
        # the constraints' tangent space (else the step may head for a saddle), else 2 W
        jtj = jac.T @ jac
        test = hess + (10.0 * float(np.abs(hess).max()) / max(float(np.abs(jtj).max()), 1e-300)) * jtj
        if not bool(_pos_def(test)):
            hess = 2.0 * wss
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
    z = restore_feasibility(cons, z)
    return AlphaResult(objective=float(z @ w @ z), n_iter=it, converged=converged, x=z)




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
def _newton_alpha_kernel(
    d1: NDArray[np.float64], d2: NDArray[np.float64], alpha: NDArray[np.float64], mus: NDArray[np.float64],
    v: NDArray[np.float64], g_red: NDArray[np.float64], cu24: NDArray[np.float64],
    cmu24: NDArray[np.float64], hc: NDArray[np.float64], lsq: NDArray[np.float64], max_iter: int, tol: float,
    eye8: NDArray[np.float64],
) -> tuple[NDArray[np.float64], int]:
    """The reduced Newton alpha-step of the pose ADM (limbs on), multipliers from zero (warm
    multipliers from the previous ADM iteration were measured no better). Returns ``(alpha,
    SQP iterations)``."""
    vtd2 = v.T @ d2
    lin = mus.T @ d1 + vtd2
    s, _, it = _newton_kernel(g_red, lin, cu24, cmu24, hc, lsq, v.T @ alpha, np.zeros(8), max_iter, tol, eye8)
    return d2 - v @ vtd2 + v @ s, it


class ReducedSQPStep:
    """The alpha-step protocol (:class:`pose_lifter.core.solve.alpha.base.AlphaStep`) by the compiled SQP
    in the reduced coordinates ``s = V^T alpha``, for one pose step (``mus = M U S`` (m, r))."""

    def __init__(self, model: PoseModel, mus: NDArray[np.float64], tol: float) -> None:
        self._model, self._mus, self._tol = model, mus, float(tol)
        self._g = mus.T @ mus + np.eye(model.sig.size)

    def __call__(self, d1: NDArray[np.float64], d2: NDArray[np.float64], alpha: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], int]:
        m = self._model
        a, it = _newton_alpha_kernel(d1, d2, alpha, self._mus, m.v, self._g, *m.kernel_limbs, NEWTON_MAX_ITER,
                                     self._tol, _EYE8)
        return a, int(it)
