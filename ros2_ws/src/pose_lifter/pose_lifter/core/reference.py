"""Independent reference solvers for every subproblem of the method (the paper used CVX).

Each function here solves one subproblem of the fast path (``camera.py``, ``pose_step.py``) by a
different route, so the two can check each other:

* convex problems are written in cvxpy and solved by Clarabel (LPs and QPs) or SCS (the SDP
  relaxation; Clarabel densifies a large PSD cone, see ``shared/notes/ros2-from-pip.md``);
* nonconvex problems (the camera rotation, the limb-constrained alpha-step and pose step)
  get *local* references: scipy searches / SLSQP from given starts. They certify nothing
  globally; they are a second, independently coded local solver.

Conventions are those of the fast path: a 2D pose is ``points`` (n, 2), a 3D pose ``pose``
(n, 3) or the paper's ``y = pose.reshape(-1)``; ``weights`` (n,) >= 0 per joint (0 =
missing); ``loss`` is ``"l1"`` (sum of per-coordinate absolute values, weighted per joint)
or ``"l2"`` (weighted squared Euclidean norms). The camera is scaled orthographic,
``x_j = s R[:2] y_j + t`` (``shared/notes/method-pitfalls.md`` section 1).

cvxpy is imported inside the functions: the core imports without it.

Every tolerance used here or by the tests that compare the fast path with these references
is stated once, in :data:`TOLERANCES`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from .errors import InvalidInputError, SolverError
from .results import Camera
from .skeleton import limb_selectors

__all__ = [
    "TOLERANCES",
    "ReferenceSolverError",
    "camera_objective",
    "limb_omegas",
    "pose_objective",
    "reference_alpha_local",
    "reference_alpha_sdp",
    "reference_camera",
    "reference_camera_given_rotation",
    "reference_pose_convex",
    "reference_pose_limbs_local",
    "reference_qstep",
    "top_eigenvalue_share",
]

Loss = Literal["l1", "l2"]

#: Every tolerance of the reference solvers and of the fast-path-vs-reference tests.
#:
#: Solver settings
#:   ``clarabel_tol``      Clarabel's tol_gap_abs / tol_gap_rel / tol_feas.
#:   ``scs_eps``           SCS eps_abs / eps_rel (first-order method: ~1e-6 relative at best).
#:   ``slsqp_ftol``        SLSQP's ftol.
#:   ``camera_xatol``      Nelder-Mead xatol (radians) of the rotation search.
#:   ``camera_fatol``      Nelder-Mead fatol of the rotation search.
#: Checks of the references on their own
#:   ``kkt``               Q-step KKT residual / constraint residual (relative to ||data||).
#:   ``feasibility``       equality constraints at a SLSQP / Clarabel solution (absolute).
#:   ``sdp_bound_rel``     SDP value <= local value + this * (1 + |local value|) (SCS slack).
#:   ``recovery``          camera / pose recovered from noise-free data (absolute).
#: Fast path vs reference
#:   ``camera_objective_rel``  fast camera objective <= reference * (1 + rel) + abs.
#:   ``camera_objective_abs``
#:   ``camera_rotation``       ||R2_fast - R2_ref||_F when the optimum is unique.
#:   ``qstep_solution``        max |Q_fast - Q_ref| (both exact: closed form vs Clarabel).
#:   ``pose_objective_rel``    convex pose step: |f_fast - f_ref| <= rel * (1 + f_ref).
#:   ``pose_alpha``            convex pose step: ||alpha_fast - alpha_ref||_inf (unique
#:                             optimum assumed: L2 with theta > 0 on a full-rank problem).
#:   ``alpha_step_objective_rel``  limb-constrained alpha-step / pose step: fast objective
#:                             <= local reference * (1 + rel) + abs (nonconvex: only "not
#:                             worse than a local reference from the same start").
#:   ``alpha_step_objective_abs``
#:   ``limb_violation``        max_i | ||C_i y||^2 - L_i | accepted from the fast path.
#:   ``nonconvex_median_ratio``  limb-constrained pose step over a set of problems: fast
#:   ``nonconvex_max_ratio``     objective / best local reference (SLSQP from several starts),
#:                               median and worst case.
TOLERANCES: Final[dict[str, float]] = {
    "clarabel_tol": 1e-9,
    "scs_eps": 1e-9,
    "slsqp_ftol": 1e-13,
    "camera_xatol": 1e-9,
    "camera_fatol": 1e-12,
    "kkt": 1e-7,
    "feasibility": 1e-7,
    "sdp_bound_rel": 1e-4,
    "recovery": 1e-6,
    "camera_objective_rel": 1e-3,
    "camera_objective_abs": 1e-5,
    "camera_rotation": 1e-3,
    "qstep_solution": 1e-6,
    "pose_objective_rel": 1e-3,
    "pose_alpha": 1e-3,
    "alpha_step_objective_rel": 1e-2,
    "alpha_step_objective_abs": 1e-4,
    "limb_violation": 1e-3,
    "nonconvex_median_ratio": 1.05,
    "nonconvex_max_ratio": 1.3,
}


class ReferenceSolverError(SolverError):
    """A reference solver did not reach an optimal (or optimal-inaccurate) status."""


# ----------------------------------------------------------------------------- helpers


def _arr(a: Any, shape: tuple[int | None, ...], name: str) -> NDArray[np.float64]:
    out = np.asarray(a, dtype=np.float64)
    if out.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, out.shape, strict=True)):
        raise InvalidInputError(f"{name} must have shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise InvalidInputError(f"{name} has non-finite values")
    return out


def _check_loss(loss: str) -> Loss:
    if loss not in ("l1", "l2"):
        raise InvalidInputError(f"loss must be 'l1' or 'l2', got {loss!r}")
    return "l1" if loss == "l1" else "l2"


def _weights(weights: Any, n: int) -> NDArray[np.float64]:
    w = _arr(weights, (n,), "weights")
    if np.any(w < 0):
        raise InvalidInputError("weights must be >= 0")
    return w


def _loss_value(residual: NDArray[np.float64], w: NDArray[np.float64], loss: Loss) -> float:
    """``sum_j w_j loss(residual_j)`` for residuals of shape (n, 2)."""
    if loss == "l1":
        return float(np.sum(w * np.abs(residual).sum(axis=1)))
    return float(np.sum(w * (residual**2).sum(axis=1)))


def _status_ok(problem: Any, name: str) -> None:
    if problem.status not in ("optimal", "optimal_inaccurate"):
        raise ReferenceSolverError(f"{name}: solver status {problem.status!r}")


def _cvxpy() -> Any:
    """cvxpy, imported lazily (typed as Any: its annotations are incomplete for mypy)."""
    import importlib

    return importlib.import_module("cvxpy")


def _clarabel_kwargs() -> dict[str, Any]:
    tol = TOLERANCES["clarabel_tol"]
    return {"solver": "CLARABEL", "tol_gap_abs": tol, "tol_gap_rel": tol, "tol_feas": tol,
            "max_iter": 500}


def camera_objective(
    points: NDArray[np.float64], pose: NDArray[np.float64], weights: NDArray[np.float64],
    camera: Camera, loss: str,
) -> float:
    """The camera problem's objective ``sum_j w_j loss(x_j - s R[:2] y_j - t)``.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    pose : ndarray, shape (n, 3)
    weights : ndarray, shape (n,)
    camera : Camera
    loss : {"l1", "l2"}
    """
    x = _arr(points, (None, 2), "points")
    y = _arr(pose, (x.shape[0], 3), "pose")
    w = _weights(weights, x.shape[0])
    return _loss_value(x - camera.project(y), w, _check_loss(loss))


def pose_objective(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64], theta: float,
    loss: str, alpha: NDArray[np.float64],
) -> float:
    """The pose problem's objective ``sum_j w_j loss(x_j - M0 y_j - t) + theta ||alpha||_1``.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    camera : Camera
    mean : ndarray, shape (3n,)
    components : ndarray, shape (3n, k)
    weights : ndarray, shape (n,)
    theta : float
    loss : {"l1", "l2"}
    alpha : ndarray, shape (k,)
    """
    x = _arr(points, (None, 2), "points")
    n = x.shape[0]
    mu = _arr(mean, (3 * n,), "mean")
    b = _arr(components, (3 * n, None), "components")
    a = _arr(alpha, (b.shape[1],), "alpha")
    w = _weights(weights, n)
    y = (mu + b @ a).reshape(n, 3)
    return _loss_value(x - camera.project(y), w, _check_loss(loss)) + float(theta) * float(np.abs(a).sum())


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
    mu = _arr(mean, (c.shape[2],), "mean")
    b = _arr(components, (c.shape[2], None), "components")
    lsq = _arr(limb_sq_lengths, (c.shape[0],), "limb_sq_lengths")
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


def _local_minimize(
    fun: Any, x0: NDArray[np.float64], jac: Any, constraints: list[dict[str, Any]],
    bounds: list[tuple[float | None, float | None]] | None, eq_fun: Any, name: str,
) -> NDArray[np.float64]:
    """SLSQP; if it stops without success or infeasible, SLSQP again from its own end point
    and then scipy's ``trust-constr`` (same analytic derivatives). Raises
    :class:`ReferenceSolverError` when no attempt ends feasible."""
    feas = TOLERANCES["feasibility"]
    opts = {"ftol": TOLERANCES["slsqp_ftol"], "maxiter": 3000}
    tried: list[str] = []
    x = np.asarray(x0, dtype=np.float64)
    for _ in range(2):
        res = minimize(fun, x, jac=jac, method="SLSQP", bounds=bounds, constraints=constraints, options=opts)
        x_new = np.asarray(res.x, dtype=np.float64)
        viol = float(np.max(np.abs(eq_fun(x_new))))
        if res.success and viol <= feas:
            return x_new
        tried.append(f"SLSQP: {res.message} (violation {viol:.2e})")
        if np.all(np.isfinite(x_new)):
            x = x_new
    from scipy.optimize import Bounds, NonlinearConstraint

    cons_tc = [NonlinearConstraint(c["fun"], 0.0, 0.0 if c["type"] == "eq" else np.inf, jac=c["jac"])
               for c in constraints]
    tc_bounds = None
    if bounds is not None:
        lo = np.array([-np.inf if b[0] is None else b[0] for b in bounds])
        hi = np.array([np.inf if b[1] is None else b[1] for b in bounds])
        tc_bounds = Bounds(lo, hi)
    res = minimize(fun, np.asarray(x0, dtype=np.float64), jac=jac, method="trust-constr", bounds=tc_bounds,
                   constraints=cons_tc, options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 5000})
    x_new = np.asarray(res.x, dtype=np.float64)
    viol = float(np.max(np.abs(eq_fun(x_new))))
    if viol <= feas:
        return x_new
    tried.append(f"trust-constr: {res.message} (violation {viol:.2e})")
    raise ReferenceSolverError(f"{name}: no local solver reached feasibility: " + "; ".join(tried))


# ----------------------------------------------------------------------- camera problem


def _weighted_median_deviation(
    a: NDArray[np.float64], w: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Row-wise ``min_t sum_j w_j |a_ij - t|`` and its minimiser (a weighted median).

    a : (m, n), w : (n,) > 0. Returns (values (m,), medians (m,)).
    """
    order = np.argsort(a, axis=1, kind="stable")
    a_sorted = np.take_along_axis(a, order, axis=1)
    cw = np.cumsum(w[order], axis=1)
    idx = np.argmax(cw >= 0.5 * cw[:, -1:], axis=1)
    med = a_sorted[np.arange(a.shape[0]), idx]
    val = np.sum(w * np.abs(a - med[:, None]), axis=1)
    return val, med


def _inner_l1_exact(
    x: NDArray[np.float64], p: NDArray[np.float64], w: NDArray[np.float64],
) -> tuple[float, NDArray[np.float64], float]:
    """Exact ``min_{s >= 0, t} sum_j w_j ||x_j - s p_j - t||_1`` by breakpoint enumeration.

    For fixed ``s`` the best ``t_c`` is a weighted median of ``x_jc - s p_jc`` and the value
    ``h_c(s)`` is convex and piecewise linear in ``s`` with kinks only where two of these
    numbers cross, i.e. at ``s = (x_ic - x_jc) / (p_ic - p_jc)``. The minimum of
    ``h_1 + h_2`` over ``s >= 0`` is therefore at ``s = 0`` or at one of these slopes;
    all candidates are evaluated. Only joints with ``w > 0`` enter.
    """
    keep = w > 0
    xk, pk, wk = x[keep], p[keep], w[keep]
    cands = [np.zeros(1)]
    for c in range(2):
        dx = xk[:, None, c] - xk[None, :, c]
        dp = pk[:, None, c] - pk[None, :, c]
        iu = np.triu_indices(xk.shape[0], 1)
        ok = np.abs(dp[iu]) > 1e-15
        s = dx[iu][ok] / dp[iu][ok]
        cands.append(s[s >= 0])
    s_all = np.unique(np.concatenate(cands))
    total = np.zeros(s_all.shape[0])
    meds = np.zeros((s_all.shape[0], 2))
    for c in range(2):
        a = xk[None, :, c] - s_all[:, None] * pk[None, :, c]
        val, med = _weighted_median_deviation(a, wk)
        total += val
        meds[:, c] = med
    i = int(np.argmin(total))
    return float(s_all[i]), meds[i].copy(), float(total[i])


def _inner_l2_exact(
    x: NDArray[np.float64], p: NDArray[np.float64], w: NDArray[np.float64],
) -> tuple[float, NDArray[np.float64], float]:
    """Exact ``min_{s >= 0, t} sum_j w_j ||x_j - s p_j - t||^2`` (weighted LS, s clipped)."""
    wsum = float(w.sum())
    xbar = (w[:, None] * x).sum(axis=0) / wsum
    pbar = (w[:, None] * p).sum(axis=0) / wsum
    xc, pc = x - xbar, p - pbar
    den = float(np.sum(w[:, None] * pc * pc))
    s = max(float(np.sum(w[:, None] * pc * xc)) / den, 0.0) if den > 0 else 0.0
    t = xbar - s * pbar
    return s, t, float(np.sum(w[:, None] * (x - s * p - t) ** 2))


def reference_camera_given_rotation(
    points: NDArray[np.float64], pose: NDArray[np.float64], weights: NDArray[np.float64],
    rotation: NDArray[np.float64], loss: str,
) -> tuple[float, NDArray[np.float64], float]:
    """Camera problem for a fixed rotation: an LP (L1) or QP (L2) in ``(s, t)``, Clarabel.

    Minimises ``sum_j w_j loss(x_j - s R[:2] y_j - t)`` over ``s >= 0``, ``t``.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    pose : ndarray, shape (n, 3)
    weights : ndarray, shape (n,)
    rotation : ndarray, shape (3, 3)
    loss : {"l1", "l2"}

    Returns
    -------
    scale : float
    translation : ndarray, shape (2,)
    objective : float
        Re-evaluated in numpy at the returned ``(s, t)``.
    """
    cp = _cvxpy()

    x = _arr(points, (None, 2), "points")
    n = x.shape[0]
    y = _arr(pose, (n, 3), "pose")
    w = _weights(weights, n)
    rot = _arr(rotation, (3, 3), "rotation")
    lo = _check_loss(loss)
    p = y @ rot[:2].T  # (n, 2)
    s = cp.Variable(nonneg=True)
    t = cp.Variable(2)
    resid = x - s * p - np.ones((n, 1)) @ cp.reshape(t, (1, 2), order="C")
    wcol = w[:, None] * np.ones((1, 2))
    if lo == "l1":
        obj = cp.sum(cp.multiply(wcol, cp.abs(resid)))
    else:
        obj = cp.sum(cp.multiply(wcol, cp.square(resid)))
    prob = cp.Problem(cp.Minimize(obj))
    prob.solve(**_clarabel_kwargs())
    _status_ok(prob, "reference_camera_given_rotation")
    scale = max(float(s.value), 0.0)
    trans = np.asarray(t.value, dtype=np.float64).reshape(2)
    return scale, trans, _loss_value(x - scale * p - trans, w, lo)


def reference_camera(
    points: NDArray[np.float64], pose: NDArray[np.float64], weights: NDArray[np.float64],
    loss: str, rotation_init: NDArray[np.float64] | None = None, n_restarts: int = 8,
    seed: int = 0,
) -> tuple[Camera, float]:
    """Camera problem over ``R in SO(3)``, ``s >= 0``, ``t``: a multi-start local search.

    The objective ``f(R) = min_{s, t} sum_j w_j loss(x_j - s R[:2] y_j - t)`` is evaluated
    exactly for every rotation (L1: enumeration of the breakpoints of the piecewise-linear
    convex function of ``s``, with weighted-median translations; L2: weighted least
    squares with ``s`` clipped at 0). ``f`` is minimised over a rotation vector ``v``
    (``R = exp([v]x) R0``) by Nelder-Mead from ``rotation_init`` (if given), the identity,
    and ``n_restarts`` random rotations (seeded): a coarse search from every start, then the
    best (and the runner-up unless clearly worse) are refined (Nelder-Mead restarted once at
    its own result).
    The best rotation's ``(s, t)`` is then re-solved by
    :func:`reference_camera_given_rotation` (cvxpy + Clarabel) and the better of the two
    inner solutions kept.

    This is a *local* search with restarts: it is not a certificate of global optimality
    for the nonconvex rotation. With ``n_restarts`` >= 8 it found the global optimum of
    every small test problem we tried (noise-free data: objective 0).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    pose : ndarray, shape (n, 3)
    weights : ndarray, shape (n,)
    loss : {"l1", "l2"}
    rotation_init : ndarray, shape (3, 3), optional
    n_restarts : int
        Random starting rotations in addition to ``rotation_init`` and the identity.
    seed : int

    Returns
    -------
    camera : Camera
    objective : float
    """
    x = _arr(points, (None, 2), "points")
    n = x.shape[0]
    y = _arr(pose, (n, 3), "pose")
    w = _weights(weights, n)
    lo = _check_loss(loss)
    if np.count_nonzero(w) < 3:
        raise InvalidInputError("the camera problem needs at least 3 joints with weight > 0")
    inner = _inner_l1_exact if lo == "l1" else _inner_l2_exact

    starts: list[NDArray[np.float64]] = []
    if rotation_init is not None:
        starts.append(_arr(rotation_init, (3, 3), "rotation_init"))
    starts.append(np.eye(3))
    if n_restarts > 0:
        starts.extend(Rotation.random(int(n_restarts), random_state=seed).as_matrix())

    def f(v: NDArray[np.float64], r0: NDArray[np.float64]) -> float:
        rot = Rotation.from_rotvec(v).as_matrix() @ r0
        return inner(x, y @ rot[:2].T, w)[2]

    simplex = 0.2 * np.vstack([np.zeros(3), np.eye(3)])

    def search(
        r0: NDArray[np.float64], xatol: float, fatol: float, rounds: int,
    ) -> tuple[NDArray[np.float64], float]:
        r, val = r0, f(np.zeros(3), r0)
        for _ in range(rounds):
            res = minimize(f, np.zeros(3), args=(r,), method="Nelder-Mead",
                           options={"xatol": xatol, "fatol": fatol, "maxiter": 4000,
                                    "initial_simplex": simplex})
            if res.fun < val - fatol:
                r = Rotation.from_rotvec(res.x).as_matrix() @ r
                val = float(res.fun)
            else:
                break
        return r, val

    # coarse search from every start, then refine the two best to full accuracy
    coarse = [search(r0, 1e-3, 1e-6, 1) for r0 in starts]
    values = np.array([v for _, v in coarse])
    order = np.argsort(values, kind="stable")[:2]
    if len(order) == 2 and values[order[1]] > values[order[0]] * (1 + 1e-3) + 1e-9:
        order = order[:1]  # the runner-up is clearly worse: refine the best only
    refined = [search(coarse[i][0], TOLERANCES["camera_xatol"], TOLERANCES["camera_fatol"], 2) for i in order]
    best_rot, _ = min(refined, key=lambda rv: rv[1])
    rot = Rotation.from_matrix(best_rot).as_matrix()  # re-orthonormalise
    s_fast, t_fast, v_fast = inner(x, y @ rot[:2].T, w)
    s_cvx, t_cvx, v_cvx = reference_camera_given_rotation(x, y, w, rot, lo)
    if v_cvx <= v_fast:
        return Camera(rot, s_cvx, t_cvx), v_cvx
    return Camera(rot, s_fast, np.asarray(t_fast, dtype=np.float64)), v_fast


# ------------------------------------------------------------------ Q-step and alpha-step


def _omega_stack(omegas: Sequence[NDArray[np.float64]] | NDArray[np.float64], m1: int) -> NDArray[np.float64]:
    om = np.asarray(omegas, dtype=np.float64)
    if om.ndim != 3 or om.shape[1:] != (m1, m1):
        raise InvalidInputError(f"omegas must be (c, {m1}, {m1}), got {om.shape}")
    if not np.all(np.isfinite(om)):
        raise InvalidInputError("omegas have non-finite values")
    return om


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
    cp = _cvxpy()

    wm = _arr(w_mat, (None, None), "W")
    m1 = wm.shape[0]
    wm = _arr(wm, (m1, m1), "W")
    pm = _arr(p_mat, (m1, m1), "P")
    gm = _arr(g_mat, (m1, m1), "G")
    om = _omega_stack(omegas, m1)
    if not delta > 0:
        raise InvalidInputError("delta must be > 0")
    q = cp.Variable((m1, m1), symmetric=True)
    obj = cp.trace(wm @ q) + cp.trace(gm.T @ (q - pm)) + 0.5 * float(delta) * cp.sum_squares(q - pm)
    cons = [cp.trace(om[i] @ q) == 0 for i in range(om.shape[0])]
    cons.append(q[m1 - 1, m1 - 1] == 1)
    prob = cp.Problem(cp.Minimize(obj), cons)
    prob.solve(**_clarabel_kwargs())
    _status_ok(prob, "reference_qstep")
    val = np.asarray(q.value, dtype=np.float64)
    return 0.5 * (val + val.T)


def reference_alpha_sdp(
    w_mat: NDArray[np.float64], omegas: Sequence[NDArray[np.float64]] | NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """SDP relaxation of the alpha-step (drop rank(Q) <= 1); SCS.

    Minimises ``tr(W Q)`` over ``Q`` PSD with ``tr(Omega_i Q) = 0`` and ``Q[-1, -1] = 1``.
    Its value is a lower bound of ``min z^T W z`` s.t. ``z^T Omega_i z = 0``, ``z[-1] = 1``
    (up to SCS's accuracy, see ``TOLERANCES["sdp_bound_rel"]``); when the returned ``Q`` is
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
    cp = _cvxpy()

    wm = _arr(w_mat, (None, None), "W")
    m1 = wm.shape[0]
    wm = _arr(wm, (m1, m1), "W")
    om = _omega_stack(omegas, m1)
    ws = 0.5 * (wm + wm.T)
    q = cp.Variable((m1, m1), PSD=True)
    cons = [cp.trace(om[i] @ q) == 0 for i in range(om.shape[0])]
    cons.append(q[m1 - 1, m1 - 1] == 1)
    prob = cp.Problem(cp.Minimize(cp.trace(ws @ q)), cons)
    eps = TOLERANCES["scs_eps"]
    prob.solve(solver="SCS", eps_abs=eps, eps_rel=eps, max_iters=200_000)
    _status_ok(prob, "reference_alpha_sdp")
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
    wm = _arr(w_mat, (None, None), "W")
    m1 = wm.shape[0]
    wm = _arr(wm, (m1, m1), "W")
    om = _omega_stack(omegas, m1)
    z_init = _arr(z0, (m1,), "z0")
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

    a = _local_minimize(fun, z_init[:-1], jac, [{"type": "eq", "fun": cfun, "jac": cjac}], None, cfun,
                        "reference_alpha_local")
    z = full(a)
    return z, float(z @ ws @ z)


# -------------------------------------------------------------------------- pose problems


def _pose_linear_map(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Residual ``r(alpha) = b - A alpha`` (stacked x1, y1, x2, ...) and per-entry weights."""
    x = _arr(points, (None, 2), "points")
    n = x.shape[0]
    mu = _arr(mean, (3 * n,), "mean")
    bm = _arr(components, (3 * n, None), "components")
    w = _weights(weights, n)
    big_m = np.kron(np.eye(n), camera.projection)  # (2n, 3n)
    a_mat = big_m @ bm
    b_vec = x.reshape(-1) - big_m @ mu - np.tile(camera.translation, n)
    return a_mat, b_vec, np.repeat(w, 2)


def reference_pose_convex(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64], theta: float, loss: str,
) -> tuple[NDArray[np.float64], float]:
    """Pose step without limb constraints (L1NAWS, L1NANS, L2NAWS, L2NANS); Clarabel.

    Minimises ``sum_j w_j loss(x_j - (M0 y_j + t)) + theta ||alpha||_1`` with
    ``y = (mu + B alpha).reshape(n, 3)``, ``M0 = camera.projection``, ``t =
    camera.translation`` (an LP for L1, a QP for L2).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    camera : Camera
    mean : ndarray, shape (3n,)
    components : ndarray, shape (3n, k)
    weights : ndarray, shape (n,)
    theta : float
        >= 0 (0 for the "NS" variants).
    loss : {"l1", "l2"}

    Returns
    -------
    alpha : ndarray, shape (k,)
    objective : float
        Re-evaluated in numpy at ``alpha``.
    """
    cp = _cvxpy()

    lo = _check_loss(loss)
    a_mat, b_vec, w2 = _pose_linear_map(points, camera, mean, components, weights)
    if not theta >= 0:
        raise InvalidInputError("theta must be >= 0")
    alpha = cp.Variable(a_mat.shape[1])
    resid = b_vec - a_mat @ alpha
    data = cp.sum(cp.multiply(w2, cp.abs(resid))) if lo == "l1" else cp.sum(cp.multiply(w2, cp.square(resid)))
    prob = cp.Problem(cp.Minimize(data + float(theta) * cp.norm1(alpha)))
    prob.solve(**_clarabel_kwargs())
    _status_ok(prob, "reference_pose_convex")
    a = np.asarray(alpha.value, dtype=np.float64).reshape(-1)
    return a, pose_objective(points, camera, mean, components, weights, theta, lo, a)


def reference_pose_limbs_local(
    points: NDArray[np.float64], camera: Camera, mean: NDArray[np.float64],
    components: NDArray[np.float64], weights: NDArray[np.float64], theta: float, loss: str,
    limb_sq_lengths: NDArray[np.float64], alpha0: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """Full (nonconvex) pose step with the 8 limb constraints: a local SLSQP reference.

    Minimises ``sum_j w_j loss(x_j - (M0 y_j + t)) + theta ||alpha||_1`` subject to
    ``||C_i y||^2 = L_i`` (``C`` from :func:`pose_lifter.core.skeleton.limb_selectors`), in a
    smooth form: ``alpha = a_plus - a_minus`` with ``a_plus, a_minus >= 0`` and
    ``||alpha||_1 -> sum(a_plus + a_minus)``; for L1 the absolute residuals become slacks
    ``e >= |r|`` (two linear inequalities per coordinate) minimising ``sum w e``. Analytic
    gradients throughout; same SLSQP / trust-constr fallback as
    :func:`reference_alpha_local`. Local: the result depends on ``alpha0``.

    Parameters
    ----------
    points : ndarray, shape (12, 2)
    camera : Camera
    mean : ndarray, shape (36,)
    components : ndarray, shape (36, k)
    weights : ndarray, shape (12,)
    theta : float
    loss : {"l1", "l2"}
    limb_sq_lengths : ndarray, shape (8,)
        ``L_i``, squared target lengths.
    alpha0 : ndarray, shape (k,)

    Returns
    -------
    alpha : ndarray, shape (k,)
    objective : float
        The original (non-smooth) objective at ``alpha``.
    """
    lo = _check_loss(loss)
    a_mat, b_vec, w2 = _pose_linear_map(points, camera, mean, components, weights)
    mu = np.asarray(mean, dtype=np.float64)
    bm = np.asarray(components, dtype=np.float64)
    k = bm.shape[1]
    a0 = _arr(alpha0, (k,), "alpha0")
    c = limb_selectors()
    lsq = _arr(limb_sq_lengths, (c.shape[0],), "limb_sq_lengths")
    cb = np.einsum("ija,ak->ijk", c, bm)  # (8, 3, k)
    cm = c @ mu  # (8, 3)
    r_dim = a_mat.shape[0]
    nvar = 2 * k + (r_dim if lo == "l1" else 0)
    th = float(theta)

    def alpha_of(u: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(u[:k] - u[k : 2 * k])

    def fun(u: NDArray[np.float64]) -> float:
        reg = th * float(u[: 2 * k].sum())
        if lo == "l1":
            return float(w2 @ u[2 * k :]) + reg
        r = b_vec - a_mat @ alpha_of(u)
        return float(w2 @ (r * r)) + reg

    def jac(u: NDArray[np.float64]) -> NDArray[np.float64]:
        g = np.zeros(nvar)
        g[: 2 * k] = th
        if lo == "l1":
            g[2 * k :] = w2
        else:
            r = b_vec - a_mat @ alpha_of(u)
            ga = -2.0 * a_mat.T @ (w2 * r)
            g[:k] += ga
            g[k : 2 * k] -= ga
        return g

    def limb_fun(u: NDArray[np.float64]) -> NDArray[np.float64]:
        v = cm + cb @ alpha_of(u)  # (8, 3)
        return np.asarray((v * v).sum(axis=1) - lsq)

    def limb_jac(u: NDArray[np.float64]) -> NDArray[np.float64]:
        v = cm + cb @ alpha_of(u)
        ga = 2.0 * np.einsum("ij,ijk->ik", v, cb)  # (8, k)
        out = np.zeros((c.shape[0], nvar))
        out[:, :k] = ga
        out[:, k : 2 * k] = -ga
        return out

    cons: list[dict[str, Any]] = [{"type": "eq", "fun": limb_fun, "jac": limb_jac}]
    bounds: list[tuple[float | None, float | None]] = [(0.0, None)] * (2 * k)
    u0 = np.concatenate([np.maximum(a0, 0.0), np.maximum(-a0, 0.0)])
    if lo == "l1":
        # e - r >= 0 and e + r >= 0 with r = b - A alpha
        jr = np.hstack([-a_mat, a_mat])  # d r / d (a+, a-)

        def ineq(u: NDArray[np.float64]) -> NDArray[np.float64]:
            r = b_vec - a_mat @ alpha_of(u)
            e = u[2 * k :]
            return np.concatenate([e - r, e + r])

        ineq_jac = np.vstack([np.hstack([-jr, np.eye(r_dim)]), np.hstack([jr, np.eye(r_dim)])])
        cons.append({"type": "ineq", "fun": ineq, "jac": lambda u: ineq_jac})
        bounds += [(0.0, None)] * r_dim
        u0 = np.concatenate([u0, np.abs(b_vec - a_mat @ a0)])
    u = _local_minimize(fun, u0, jac, cons, bounds, limb_fun, "reference_pose_limbs_local")
    alpha = alpha_of(u)
    return alpha, pose_objective(points, camera, mean, components, weights, th, lo, alpha)
