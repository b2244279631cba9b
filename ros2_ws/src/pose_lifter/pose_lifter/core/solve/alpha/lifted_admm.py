"""The paper's alpha-step (appendix A): the rank-1 lifted problem ``min z^T W z`` s.t.
``z^T Omega_i z = 0`` by the inner (Q, P) ADM, then a Gauss-Newton projection onto the limb
constraints."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ...model.pose_model import LiftedConstraints
from ...results import AlphaResult

QStepFn = Callable[
    [NDArray[np.float64], "LiftedConstraints", NDArray[np.float64], NDArray[np.float64], float],
    NDArray[np.float64],
]




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
    import scipy.linalg

    vals, vecs = scipy.linalg.eigh(s, subset_by_index=[d - 1, d - 1], check_finite=False)
    return float(vals[0]), vecs[:, 0]


def lifted_alpha_admm(
    w: NDArray[np.float64], cons: LiftedConstraints, z0: NDArray[np.float64], delta: float = 1.0,
    max_iter: int = 60, tol: float = 1e-6, qstep_fn: QStepFn | None = None,
) -> AlphaResult:
    """Inner ADM of the appendix for ``min tr(W Q)`` s.t. the limb constraints, ``Q = P``,
    ``P`` PSD of rank <= 1.

    ``P`` starts at ``z0 z0^T`` (the current alpha: warm start) and the multiplier ``G`` at 0
    (reset for every alpha-subproblem; see the pitfalls note §2). Penalty ``delta`` constant.
    Stops when ``||Q - P||_F`` and the change of ``P`` are below ``tol * max(1, ||P||_F)``.

    Returns the rank-1 factor ``z`` of ``P`` scaled to ``z[-1] = 1`` (``x``; ``objective`` =
    ``z^T W z``).
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
    return AlphaResult(objective=float(z @ w @ z), n_iter=it, converged=converged, x=z)


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




def lifted_quadratic(g: NDArray[np.float64], lin: NDArray[np.float64], const: float) -> NDArray[np.float64]:
    """``W`` (n + 1, n + 1) with ``z^T W z = s^T G s - 2 lin^T s + const`` for ``z = [s; 1]``."""
    n = g.shape[0]
    wmat = np.zeros((n + 1, n + 1))
    wmat[:n, :n] = g
    wmat[:n, n] = -lin
    wmat[n, :n] = -lin
    wmat[n, n] = const
    return wmat
