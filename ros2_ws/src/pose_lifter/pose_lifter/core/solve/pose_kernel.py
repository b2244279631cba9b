"""The pose step's compiled pieces: its L1 rows, the ADM's splitting, dual and penalty updates, the
alpha-step without limbs, and the pose step as one kernel (:func:`_pose_kernel`) with the
Riemannian alpha-step (limbs on, an onto limb map) or the linear one (no limbs): the pose step of
every compiled run. :func:`pose_lifter.core.solve.pose_step.pose_step` calls it; its Python ADM
loop calls the same rows and updates around the paper's inner ADM and the cvxpy Q-step."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..numeric.jit import njit
from ..numeric.linalg import _axpy_rows, _cholesky, _cholesky_apply
from ..numeric.records import ModelArrays, StepSettings
from .alpha.sphere_newton import SphereStep, _riemannian_alpha_kernel, _sphere_setup, newton_work


class PoseProblem(NamedTuple):
    """A pose step's problem for :func:`_pose_kernel`: the 2D, the fixed camera and the prior's
    rows (module docstring of :mod:`pose_lifter.core.solve.pose_step`)."""

    points: NDArray[np.float64]  #: (12, 2) the normalised 2D
    weights: NDArray[np.float64]  #: (12,) per joint (0: missing)
    projection: NDArray[np.float64]  #: (2, 3) the camera's ``M0``
    translation: NDArray[np.float64]  #: (2,)
    target: NDArray[np.float64]  #: (12, 3) the prior's pose in the normalised frame (zeros: none)
    prior_weights: NDArray[np.float64]  #: (12, 2) its image-position and depth rows' weights
    radii: NDArray[np.float64]  #: (8,) the limb lengths in use


class PoseOut(NamedTuple):
    """What :func:`_pose_kernel` returns."""

    alpha: NDArray[np.float64]  #: (k,) the best feasible iterate's coefficients
    objective: float  #: its objective
    limb_violation: float  #: its largest limb-length error
    pose: NDArray[np.float64]  #: (36,) its pose ``mu + B alpha``
    eta: float  #: the final penalty (the unscaled multipliers are ``eta * u``)
    n_iter: int  #: ADM iterations
    converged: bool  #: whether the residuals fell below the tolerance
    alpha_iter: int  #: Newton steps of the alpha-steps, summed


class PoseRows(NamedTuple):
    """The L1 rows of a pose step's objective ``sum_i wts_i rho(c_i - (M U S s)_i)`` (``s = V^T
    alpha``; :func:`_pose_rows`)."""

    c: NDArray[np.float64]  #: (m,)
    wts: NDArray[np.float64]  #: (m,)
    mus: NDArray[np.float64]  #: (m, r) ``M U S``
    scale: float  #: ``max(1, ||c||)``: the scale of the ADM's relative residuals


class Multipliers(NamedTuple):
    """The pose ADM's scaled multipliers (updated in place)."""

    u1: NDArray[np.float64]  #: (m,) of ``gamma = c - A alpha``
    u2: NDArray[np.float64]  #: (k,) of ``beta = alpha``


class Split(NamedTuple):
    """What the gamma- and beta-steps of an ADM iteration write (:func:`_adm_split`)."""

    gamma: NDArray[np.float64]  #: (m,)
    beta: NDArray[np.float64]  #: (k,)
    d1: NDArray[np.float64]  #: (m,) the alpha-step's data target ``c - gamma + u1``
    d2: NDArray[np.float64]  #: (k,) its coefficient target ``beta - u2``


@njit
def _sum_abs(a: NDArray[np.float64]) -> float:
    """``||a||_1`` of an (n,) array, summed in order: the sparsity term ``||alpha||_1`` of a run's
    objective (:func:`pose_lifter.core.solve.run_kernel._run_objective`)."""
    res = 0.0
    for i in range(a.size):
        res += abs(a[i])
    return res


@njit
def _depth_row(m0: NDArray[np.float64]) -> NDArray[np.float64]:
    """``m3 = s r3 = s r1 x r2`` (3,) of a scaled-orthographic ``M0 = s [r1; r2]`` (2, 3): the row
    that maps a model pose to depth in the image's units (``||m1|| = s``). The one implementation
    of :meth:`pose_lifter.core.solve.pose_step.PriorRows.depth_row`."""
    a0, a1, a2 = m0[0, 0], m0[0, 1], m0[0, 2]
    b0, b1, b2 = m0[1, 0], m0[1, 1], m0[1, 2]
    nrm = max(math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-300)
    out = np.empty(3)
    out[0] = (a1 * b2 - a2 * b1) / nrm
    out[1] = (a2 * b0 - a0 * b2) / nrm
    out[2] = (a0 * b1 - a1 * b0) / nrm
    return out


@njit
def _depth_term(y: NDArray[np.float64], m0: NDArray[np.float64], xp: NDArray[np.float64],
                pw: NDArray[np.float64]) -> float:
    """The prior's depth rows of the objective, ``sum_j pw[j, 1] |xp[j, 2] - m3 (y_j - mean_l y_l)|``,
    for the flat pose ``y`` (3n,), ``M0`` (2, 3) (``m3``: :func:`_depth_row`), the prior's target
    ``xp`` (n, 3) and weights ``pw`` (n, 2). The one implementation of
    :meth:`pose_lifter.core.solve.pose_step.PriorRows.depth_term`."""
    nj = xp.shape[0]
    m3 = _depth_row(m0)
    c0, c1, c2 = 0.0, 0.0, 0.0
    for j in range(nj):
        c0 += y[3 * j]
        c1 += y[3 * j + 1]
        c2 += y[3 * j + 2]
    c0 /= nj
    c1 /= nj
    c2 /= nj
    res = 0.0
    for j in range(nj):
        d = (y[3 * j] - c0) * m3[0] + (y[3 * j + 1] - c1) * m3[1] + (y[3 * j + 2] - c2) * m3[2]
        res += pw[j, 1] * abs(xp[j, 2] - d)
    return res


@njit
def _objective(resid: NDArray[np.float64], wts: NDArray[np.float64], alpha: NDArray[np.float64],
               theta: float, l1: bool) -> float:
    """``sum wts rho(resid) + theta ||alpha||_1`` (``l1`` False: squared loss)."""
    data = np.sum(wts * np.abs(resid)) if l1 else np.sum(wts * resid * resid)
    return float(data + theta * np.sum(np.abs(alpha)))


@njit
def _adm_split(rows: PoseRows, ax: NDArray[np.float64], alpha: NDArray[np.float64], u: Multipliers,
               eta: float, st: StepSettings, out: Split) -> None:
    """gamma- and beta-steps of the pose ADM (``pose_step`` module docstring), written into
    ``out``: ``gamma = prox(c - A alpha + u1)``, ``beta = soft(alpha + u2, th / eta)`` (``th =
    0``: no sparsity), ``d1 = c - gamma + u1``, ``d2 = beta - u2``; ``ax = A alpha`` (m,), the loss
    and ``th`` from ``st``."""
    c, wts, u1, u2 = rows.c, rows.wts, u.u1, u.u2
    gamma, beta, d1, d2 = out.gamma, out.beta, out.d1, out.d2
    th, l1 = st.th, st.l1
    for i in range(c.size):  # gamma-step (prox of the data term)
        vg = c[i] - ax[i] + u1[i]
        if l1:
            gi = math.copysign(max(abs(vg) - wts[i] / eta, 0.0), vg)
        else:
            gi = eta * vg / (2.0 * wts[i] + eta)
        gamma[i] = gi
        d1[i] = c[i] - gi + u1[i]
    for i in range(alpha.size):  # beta-step (prox of theta ||.||_1)
        vb = alpha[i] + u2[i]
        bi = math.copysign(max(abs(vb) - th / eta, 0.0), vb) if th > 0 else vb
        beta[i] = bi
        d2[i] = bi - u2[i]


@njit
def _adm_dual_update(rows: PoseRows, ax: NDArray[np.float64], ax_prev: NDArray[np.float64], split: Split,
                     beta_prev: NDArray[np.float64], alpha: NDArray[np.float64], u: Multipliers,
                     st: StepSettings) -> tuple[float, float, float]:
    """After the alpha-step of the pose ADM (``ax = A alpha`` (m,), ``ax_prev`` before it; the
    iteration's ``split``, ``beta_prev`` (k,) the previous beta): the multipliers ``u`` updated in
    place; returns the objective and the relative primal and dual residuals (sums in order, no
    temporaries)."""
    c, wts, gamma, beta, u1, u2 = rows.c, rows.wts, split.gamma, split.beta, u.u1, u.u2
    th, l1 = st.th, st.l1
    r1sq, dsq, data = 0.0, 0.0, 0.0
    for i in range(c.size):
        e = c[i] - ax[i]
        data += wts[i] * (abs(e) if l1 else e * e)
        r = e - gamma[i]
        u1[i] += r
        r1sq += r * r
        dsq += (ax[i] - ax_prev[i]) ** 2
    r2sq, asq, anorm1, dbsq = 0.0, 0.0, 0.0, 0.0
    for i in range(alpha.size):
        a = alpha[i]
        r = a - beta[i]
        u2[i] += r
        r2sq += r * r
        asq += a * a
        anorm1 += abs(a)
        dbsq += (beta[i] - beta_prev[i]) ** 2
    obj = data + th * anorm1
    an = max(1.0, math.sqrt(asq))
    primal = max(math.sqrt(r1sq) / rows.scale, math.sqrt(r2sq) / an)
    dual = max(math.sqrt(dsq) / rows.scale, math.sqrt(dbsq) / an)
    return obj, primal, dual


@njit
def _grow_penalty(eta: float, st: StepSettings, u: Multipliers) -> float:
    """The pose ADM's penalty schedule: ``eta <- min(eta * eta_growth, eta_max)`` (``st``), with
    the scaled multipliers ``u`` rescaled in place so the unscaled ones are unchanged."""
    eta_growth, eta_max = st.eta_growth, st.eta_max
    if eta_growth != 1.0 and eta < eta_max:
        eta_new = min(eta * eta_growth, eta_max)
        u1, u2 = u.u1, u.u2
        u1 *= eta / eta_new
        u2 *= eta / eta_new
        return eta_new
    return eta


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
def _n_rows(pw: NDArray[np.float64]) -> int:
    """Rows of the pose step's L1 objective for the prior weights ``pw`` (12, 2): 2 per joint, 2 per
    prior image position (``pw[j, 0] > 0``) and 1 per prior depth (``pw[j, 1] > 0``)."""
    nj: int = pw.shape[0]
    m: int = 2 * nj
    for j in range(nj):
        m += (2 if pw[j, 0] > 0.0 else 0) + (1 if pw[j, 1] > 0.0 else 0)
    return m


@njit
def _pose_rows(x: NDArray[np.float64], m0: NDArray[np.float64], t: NDArray[np.float64],
               w: NDArray[np.float64], km: ModelArrays, xp: NDArray[np.float64], pw: NDArray[np.float64]
               ) -> PoseRows:
    """The L1 rows of the pose objective ``sum_i wts_i rho(c_i - (M U S s)_i)`` (``s = V^T alpha``)
    for the camera ``m0`` (2, 3), ``t`` (2,), the 2D ``x`` (12, 2) and weights ``w`` (12,):
    :class:`PoseRows` with ``m`` = :func:`_n_rows` rows.

    2 rows per joint, then the prior's (the hybrid mode's L1 prior term): for each joint ``j`` with
    ``pw[j, 0] > 0`` two rows ``pw[j, 0] |xp[j, a] - t_a - M_a y_j|`` (the prior's image position,
    a = x, y), and with ``pw[j, 1] > 0`` one row ``pw[j, 1] |xp[j, 2] - m3 (y_j - mean_i y_i)|``
    (its depth relative to the joints' mean; ``m3`` = :func:`_depth_row`). ``pw`` all zero: the
    paper's problem."""
    mean, u, sig = km.mean, km.u, km.sig
    r = sig.size
    nj = x.shape[0]
    m = _n_rows(pw)
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
    if (pw[:, 1] > 0.0).any():  # the prior's relative depths: m3 (y_j - mean_i y_i)
        m3 = _depth_row(m0)
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
    return PoseRows(c, wts, mus, max(1.0, math.sqrt(float(c @ c))))


@njit
def _linear_alpha_kernel(d1: NDArray[np.float64], d2: NDArray[np.float64], sk: NDArray[np.float64],
                         mus: NDArray[np.float64], chol: NDArray[np.float64], km: ModelArrays,
                         alpha_out: NDArray[np.float64]) -> int:
    """The alpha-step without limb constraints, ``argmin ||A alpha - d1||^2 + ||alpha - d2||^2``
    (``A = M U S V^T``), in the reduced coordinates: ``s = G^-1 (mus^T d1 + V^T d2)`` with ``G =
    mus^T mus + I`` (r, r) given by its Cholesky factor ``chol``, then ``alpha = d2 + V (s - V^T
    d2)`` (the part of ``alpha`` in the null space of the bases at its optimum). Writes ``alpha``
    (k,) into ``alpha_out`` and ``s`` (r,) into ``sk``; returns 1 (one solve)."""
    vc, vt = km.vc, km.vt
    r = sk.size
    vtd2 = np.zeros(r)
    _axpy_rows(vc, d2, vtd2)  # V^T d2
    lin = vtd2.copy()
    _axpy_rows(mus, d1, lin)  # + (M U S)^T d1
    s = _cholesky_apply(chol, lin)
    for j in range(r):
        sk[j] = s[j]
        s[j] -= vtd2[j]
    alpha_out[:] = d2
    _axpy_rows(vt, s, alpha_out)  # d2 + V (s - V^T d2)
    return 1


@njit
def _alpha_setup(mus: NDArray[np.float64], rad: NDArray[np.float64], km: ModelArrays, st: StepSettings
                 ) -> tuple[SphereStep, NDArray[np.float64]]:
    """A pose step's alpha-step operands for the rows' matrix ``mus`` (m, r): with limbs
    (``st.limbs``) the Riemannian step's (:class:`SphereStep`: ``G = mus^T mus + (1 + prox) I``
    in limb coordinates, :func:`_sphere_setup`) and an empty factor; without, an empty
    :class:`SphereStep` and the Cholesky factor (r, r) of ``G = mus^T mus + I``
    (:func:`_linear_alpha_kernel`)."""
    r = mus.shape[1]
    g = mus.T @ mus
    if not st.limbs:
        for j in range(r):
            g[j, j] += 1.0
        chol, _ = _cholesky(g)  # G >= I: positive definite
        empty = np.zeros((0, 0))
        return SphereStep(mus, (np.zeros(0), empty, empty, empty, empty), rad, newton_work(0)), chol
    for j in range(r):
        g[j, j] += 1.0 + st.prox
    q, rmat, s1, s2 = _sphere_setup(g, km.z, km.n)
    # C-contiguous operands in the orientation _axpy_rows wants (camera-dependent: per pose step)
    geom = (g @ km.s0, q, np.ascontiguousarray(rmat.T), np.ascontiguousarray(s1.T),
            np.ascontiguousarray(s2.T))
    return SphereStep(mus, geom, rad, newton_work(r)), np.zeros((0, 0))


@njit
def _pose_adm(rows: PoseRows, km: ModelArrays, st: StepSettings, rad: NDArray[np.float64],
              alpha0: NDArray[np.float64], u: Multipliers, best_obj: float, max_iter: int
              ) -> tuple[NDArray[np.float64], float, float, int, bool, int]:
    """The pose ADM (``pose_step`` module docstring) on ``rows`` (:func:`_pose_rows`) with the
    Riemannian alpha-step under the limb lengths ``rad`` (8,) (:func:`_riemannian_alpha_kernel`)
    or, without limbs (``st.limbs`` False), the linear one (:func:`_linear_alpha_kernel`), each
    set up once (:func:`_alpha_setup`); ``V^T alpha`` is carried from step to step. ``u`` are the
    scaled multipliers, updated in place; ``best_obj`` the objective of ``alpha0`` (k,) if
    feasible, else ``inf``. Returns ``(best alpha, best objective, final eta, iterations,
    converged, alpha-step iterations)``."""
    mus = rows.mus
    vt = km.vt
    tol = st.pose_tol
    eta = st.eta
    sphere, chol = _alpha_setup(mus, rad, km, st)
    m = rows.c.size
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
    alpha_it = 0
    ax_prev = np.empty(m)
    mus_t = np.ascontiguousarray(mus.T)
    for it in range(1, max_iter + 1):
        beta, beta_prev = beta_prev, beta
        split = Split(gamma, beta, d1, d2)
        _adm_split(rows, ax, alpha, u, eta, st, split)
        if st.limbs:
            alpha_it += _riemannian_alpha_kernel(d1, d2, sk, sphere, km, st, alpha)
        else:
            alpha_it += _linear_alpha_kernel(d1, d2, sk, mus, chol, km, alpha)
        ax, ax_prev = ax_prev, ax
        ax[:] = 0.0
        _axpy_rows(mus_t, sk, ax)
        obj, primal, dual = _adm_dual_update(rows, ax, ax_prev, split, beta_prev, alpha, u, st)
        eta = _grow_penalty(eta, st, u)
        if obj < best_obj:
            best_obj = obj
            best_alpha[:] = alpha
        if primal < tol and dual < tol:
            converged = True
            break
    if not math.isfinite(best_obj):
        best_alpha = alpha
    return best_alpha, best_obj, eta, it, converged, alpha_it


@njit
def _pose_kernel(problem: PoseProblem, km: ModelArrays, st: StepSettings, max_iter: int,
                 alpha0: NDArray[np.float64], u: Multipliers) -> PoseOut:
    """The pose step of ``problem``: its rows (:func:`_pose_rows`), the start's objective if it
    meets the limb lengths (always without limbs), then the ADM (:func:`_pose_adm`) from
    ``alpha0`` (k,) with the scaled multipliers ``u`` (updated in place) and at most ``max_iter``
    iterations. Without limbs its limb violation is 0 (none is asked for)."""
    th, l1 = st.th, st.l1
    rad = problem.radii
    rows = _pose_rows(problem.points, problem.projection, problem.translation, problem.weights, km,
                      problem.target, problem.prior_weights)
    best_obj = np.inf
    if not st.limbs or _limb_violation_jit(km.mean + km.comps @ alpha0, km.limb_matrix, rad) < 1e-6:
        best_obj = _objective(rows.c - rows.mus @ (km.vt @ alpha0), rows.wts, alpha0, th, l1)
    best_alpha, best_obj, eta, it, converged, alpha_it = _pose_adm(rows, km, st, rad, alpha0, u, best_obj,
                                                                   max_iter)
    if not math.isfinite(best_obj):
        best_obj = _objective(rows.c - rows.mus @ (km.vt @ best_alpha), rows.wts, best_alpha, th, l1)
    y = km.mean + km.comps @ best_alpha
    lv = _limb_violation_jit(y, km.limb_matrix, rad) if st.limbs else 0.0
    return PoseOut(best_alpha, best_obj, lv, y, eta, it, converged, alpha_it)
