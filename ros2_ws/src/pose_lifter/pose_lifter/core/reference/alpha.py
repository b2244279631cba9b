"""References for the alpha-step of the pose step (``core/solve/alpha/``): in the paper's lifted form
``min z^T W z`` s.t. ``z^T Omega_i z = 0`` (the limb constraints, :func:`limb_omegas`) and
``z[-1] = 1``, with ``z = [alpha; 1]``.

* :func:`reference_qstep`: the convex Q-step of the inner ADM (Clarabel);
* :func:`reference_alpha_sdp`: the SDP relaxation, a lower bound (SCS), with
  :func:`top_eigenvalue_share` to tell whether it is tight;
* :func:`reference_alpha_local`: the nonconvex problem itself, locally (SLSQP).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..model.skeleton import limb_selectors
from ._common import TOLERANCES, array, clarabel_kwargs, cvxpy, local_minimize, status_ok

__all__ = [
    "limb_omegas",
    "reference_alpha_local",
    "reference_alpha_sdp",
    "reference_qstep",
    "top_eigenvalue_share",
]


def limb_omegas(
    mean: NDArray[np.float64], components: NDArray[np.float64], limb_sq_lengths: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The paper's lifted limb constraints ``Omega_i`` (appendix, eq. update_alpha).

    ``z^T Omega_i z = ||C_i (B alpha + mu)||^2 - L_i`` for ``z = [alpha; 1]``.

    Parameters
    ----------
    mean : ndarray, shape (36,)
    components : ndarray, shape (36, k)
    limb_sq_lengths : ndarray, shape (8,)

    Returns
    -------
    ndarray, shape (8, k + 1, k + 1)
    """
    c = limb_selectors()
    mu = array(mean, (c.shape[2],), "mean")
    b = array(components, (c.shape[2], None), "components")
    lsq = array(limb_sq_lengths, (c.shape[0],), "limb_sq_lengths")
    k = b.shape[1]
    out = np.zeros((c.shape[0], k + 1, k + 1))
    for i in range(c.shape[0]):
        cb = c[i] @ b  # (3, k)
        cm = c[i] @ mu  # (3,)
        out[i, :k, :k] = cb.T @ cb
        out[i, :k, k] = cb.T @ cm
        out[i, k, :k] = cb.T @ cm
        out[i, k, k] = cm @ cm - lsq[i]
    return out


def top_eigenvalue_share(q: NDArray[np.float64]) -> float:
    """Rank-1-ness of a PSD matrix: ``lambda_max / sum(max(lambda, 0))`` (1 = rank 1)."""
    lam = np.linalg.eigvalsh(0.5 * (q + q.T))
    pos = np.clip(lam, 0.0, None)
    total = float(pos.sum())
    return float(pos[-1] / total) if total > 0 else 0.0


def _alpha_data(
    w_mat: NDArray[np.float64], omegas: Sequence[NDArray[np.float64]] | NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The alpha-step's data, checked: ``W`` square (m + 1, m + 1) and the ``Omega_i`` as one
    finite (c, m + 1, m + 1) array."""
    wm = array(w_mat, (None, None), "W")
    m1 = wm.shape[0]
    wm = array(wm, (m1, m1), "W")
    om = np.asarray(omegas, dtype=np.float64)
    if om.ndim != 3 or om.shape[1:] != (m1, m1):
        raise InvalidInputError(f"omegas must be (c, {m1}, {m1}), got {om.shape}")
    if not np.all(np.isfinite(om)):
        raise InvalidInputError("omegas have non-finite values")
    return wm, om


def reference_qstep(
    w_mat: NDArray[np.float64], omegas: Sequence[NDArray[np.float64]] | NDArray[np.float64],
    p_mat: NDArray[np.float64], g_mat: NDArray[np.float64], delta: float,
) -> NDArray[np.float64]:
    """Q-step of the inner ADM (appendix eq. update_T) with ``Q[-1, -1] = 1``; Clarabel.

    Minimises ``tr(W Q) + tr(G^T (Q - P)) + delta/2 ||Q - P||_F^2`` over symmetric ``Q``
    subject to ``tr(Omega_i Q) = 0`` for every ``i`` and ``Q[-1, -1] = 1``.

    Parameters
    ----------
    w_mat : ndarray, shape (m + 1, m + 1)
    omegas : sequence of ndarray, each (m + 1, m + 1)
    p_mat, g_mat : ndarray, shape (m + 1, m + 1)
    delta : float
        > 0.

    Returns
    -------
    ndarray, shape (m + 1, m + 1)
        The (symmetric) minimiser.
    """
    cp = cvxpy()

    wm, om = _alpha_data(w_mat, omegas)
    m1 = wm.shape[0]
    pm = array(p_mat, (m1, m1), "P")
    gm = array(g_mat, (m1, m1), "G")
    if not delta > 0:
        raise InvalidInputError("delta must be > 0")
    q = cp.Variable((m1, m1), symmetric=True)
    obj = cp.trace(wm @ q) + cp.trace(gm.T @ (q - pm)) + 0.5 * float(delta) * cp.sum_squares(q - pm)
    cons = [cp.trace(om[i] @ q) == 0 for i in range(om.shape[0])]
    cons.append(q[m1 - 1, m1 - 1] == 1)
    prob = cp.Problem(cp.Minimize(obj), cons)
    prob.solve(**clarabel_kwargs())
    status_ok(prob, "reference_qstep")
    val = np.asarray(q.value, dtype=np.float64)
    return 0.5 * (val + val.T)


def reference_alpha_sdp(
    w_mat: NDArray[np.float64], omegas: Sequence[NDArray[np.float64]] | NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """SDP relaxation of the alpha-step (drop rank(Q) <= 1); SCS.

    Minimises ``tr(W Q)`` over ``Q`` PSD with ``tr(Omega_i Q) = 0`` and ``Q[-1, -1] = 1``.
    Its value is a lower bound of ``min z^T W z`` s.t. ``z^T Omega_i z = 0``, ``z[-1] = 1``
    (up to SCS's accuracy, :data:`TOLERANCES` ``["scs_eps"]``); when the returned ``Q`` is
    rank 1 (:func:`top_eigenvalue_share` ~ 1) the relaxation is tight and
    ``z = sqrt(lambda_1) v_1`` (sign so that ``z[-1] > 0``) is a global minimiser.

    Parameters
    ----------
    w_mat : ndarray, shape (m + 1, m + 1)
        Need not be symmetric (only its symmetric part matters).
    omegas : sequence of ndarray, each (m + 1, m + 1)

    Returns
    -------
    q : ndarray, shape (m + 1, m + 1)
    lower_bound : float
        ``tr(W Q)`` at the returned ``Q``.
    """
    cp = cvxpy()

    wm, om = _alpha_data(w_mat, omegas)
    m1 = wm.shape[0]
    ws = 0.5 * (wm + wm.T)
    q = cp.Variable((m1, m1), PSD=True)
    cons = [cp.trace(om[i] @ q) == 0 for i in range(om.shape[0])]
    cons.append(q[m1 - 1, m1 - 1] == 1)
    prob = cp.Problem(cp.Minimize(cp.trace(ws @ q)), cons)
    eps = TOLERANCES["scs_eps"]
    prob.solve(solver="SCS", eps_abs=eps, eps_rel=eps, max_iters=200_000)
    status_ok(prob, "reference_alpha_sdp")
    val = np.asarray(q.value, dtype=np.float64)
    val = 0.5 * (val + val.T)
    return val, float(np.sum(ws * val))


def reference_alpha_local(
    w_mat: NDArray[np.float64], omegas: Sequence[NDArray[np.float64]] | NDArray[np.float64],
    z0: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """The alpha-step ``min z^T W z`` s.t. ``z^T Omega_i z = 0``, ``z[-1] = 1``; SLSQP.

    ``z[-1] = 1`` is eliminated (the variable is ``z[:-1]``); objective and constraints get
    analytic gradients. SLSQP may stop on a rank-deficient constraint Jacobian; it is then
    restarted once from its end point and, failing that, ``trust-constr`` is run from ``z0``
    (:class:`ReferenceSolverError` if nothing ends feasible). A local solver: the result
    depends on ``z0``.

    Parameters
    ----------
    w_mat : ndarray, shape (m + 1, m + 1)
    omegas : sequence of ndarray, each (m + 1, m + 1)
    z0 : ndarray, shape (m + 1,)
        Start (its last entry is ignored and set to 1).

    Returns
    -------
    z : ndarray, shape (m + 1,)
    objective : float
        ``z^T W z``.
    """
    wm, om = _alpha_data(w_mat, omegas)
    m1 = wm.shape[0]
    z_init = array(z0, (m1,), "z0")
    ws = 0.5 * (wm + wm.T)
    oms = 0.5 * (om + np.swapaxes(om, 1, 2))

    def full(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.append(a, 1.0)

    def fun(a: NDArray[np.float64]) -> float:
        z = full(a)
        return float(z @ ws @ z)

    def jac(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(2.0 * (ws @ full(a))[:-1])

    def cfun(a: NDArray[np.float64]) -> NDArray[np.float64]:
        z = full(a)
        return np.asarray(np.einsum("i,cij,j->c", z, oms, z))

    def cjac(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(2.0 * (oms @ full(a))[:, :-1])

    a = local_minimize(fun, z_init[:-1], jac, [{"type": "eq", "fun": cfun, "jac": cjac}], None, cfun,
                        "reference_alpha_local")
    z = full(a)
    return z, float(z @ ws @ z)
