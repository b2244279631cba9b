"""Riemannian Newton alpha-step: the limb-constrained least squares on the product of the 8
limb spheres (the default alpha-solver of the pose ADM)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ...errors import InvalidInputError
from ...model.pose_model import PoseModel
from ...numeric.jit import njit
from ...numeric.linalg import _axpy_rows, _cholesky_apply_into, _cholesky_into
from ...numeric.records import ModelArrays, StepSettings
from ...results import AlphaResult

#: The alpha-step's quadratic in limb coordinates for one pose step (:func:`_sphere_setup`), as
#: :func:`_riemannian_alpha_kernel` takes it: ``(G s0 (r,), Q (24, 24), R^T (r, 24), S1^T (24, r),
#: S2^T (r, r))``, C-contiguous.
SphereGeometry = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                       NDArray[np.float64]]


class NewtonWork(NamedTuple):
    """The buffers of :func:`_sphere_newton` and :func:`_riemannian_alpha_kernel`, made once per
    pose step (:func:`newton_work`) and written by every alpha-step of its ADM: the solver's
    inner loop allocates nothing."""

    l: NDArray[np.float64]  #: (24,) the iterate's limb vectors
    ql: NDArray[np.float64]  #: (24,) ``Q l``
    cand: NDArray[np.float64]  #: (24,) the line search's trial point
    qc: NDArray[np.float64]  #: (24,) ``Q cand``
    d: NDArray[np.float64]  #: (24,) the step in limb coordinates
    tb: NDArray[np.float64]  #: (24, 2) the spheres' tangent bases
    gr: NDArray[np.float64]  #: (16,) the Riemannian gradient in them
    mu: NDArray[np.float64]  #: (8,) the multipliers
    w: NDArray[np.float64]  #: (24, 16) ``2 Q T``
    hr: NDArray[np.float64]  #: (16, 16) the Riemannian Hessian
    lo: NDArray[np.float64]  #: (16, 16) its Cholesky factor
    y: NDArray[np.float64]  #: (16,) the forward substitution
    step: NDArray[np.float64]  #: (16,) the Newton step
    vtd2: NDArray[np.float64]  #: (r,) ``V^T d2``
    h: NDArray[np.float64]  #: (r,) the linear term in reduced coordinates
    b: NDArray[np.float64]  #: (24,) its limb part ``R h``
    l0: NDArray[np.float64]  #: (24,) the start's limb vectors
    s: NDArray[np.float64]  #: (r,) the reduced coordinates of the result


@njit
def newton_work(r: int) -> NewtonWork:
    """Fresh :class:`NewtonWork` for bases of rank ``r``."""
    return NewtonWork(np.empty(24), np.empty(24), np.empty(24), np.empty(24), np.empty(24), np.empty((24, 2)),
                      np.empty(16), np.empty(8), np.empty((24, 16)), np.empty((16, 16)), np.empty((16, 16)),
                      np.empty(16), np.empty(16), np.empty(r), np.empty(r), np.empty(24), np.empty(24),
                      np.empty(r))


#: Iteration cap of each Riemannian Newton alpha-step inside the pose ADM (an inexact, proximal
#: ADM). Measured on 190 recorded warm lifts of 5 committed bags, pose_max_iter 30: 1, 2, 3 Newton
#: steps give mean objectives 0.6916 / 0.6965 / 0.6965 at 1.8 / 2.0 / 2.3 ms per frame; run to
#: convergence (20) it was 0.8178 without the proximal term, 0.7679 with it (alpha_prox = 1, at
#: pose_max_iter 20).
RIEMANNIAN_MAX_ITER = 1


def riemannian_alpha(
    gmat: NDArray[np.float64], lin: NDArray[np.float64], model: PoseModel, s0: NDArray[np.float64],
    max_iter: int = 100, tol: float = 1e-10,
) -> AlphaResult:
    """The reduced alpha-step ``min s^T G s - 2 lin^T s`` s.t. ``||C_i mu + C_i U S s||^2 = L_i``
    (the lifted problem of ``model.reduced``) by Riemannian Newton in limb
    coordinates: the free directions eliminated in closed form (:func:`_sphere_setup`), then
    :func:`_sphere_newton` on the product of the 8 limb spheres from the limb vectors of ``s0``.
    Shapes: gmat (r, r) positive definite, lin (r,), s0 (r,). Returns ``s`` (``x``) with its
    objective ``s^T G s - 2 lin^T s``.

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
    cu24, cmu24 = model.kernel_limbs
    lv, it, conv = _sphere_newton(q, rmat @ h, cmu24 + cu24 @ np.asarray(s0, dtype=np.float64), rad,
                                  int(max_iter), float(tol), newton_work(g.shape[0]))
    s = sz + s1 @ lv + s2 @ h
    lin = np.asarray(lin, dtype=np.float64)
    return AlphaResult(objective=float(s @ g @ s - 2.0 * lin @ s), n_iter=int(it), converged=bool(conv), x=s)




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
def _tangent_gradient(l: NDArray[np.float64], ql: NDArray[np.float64], b: NDArray[np.float64],
                      rad: NDArray[np.float64], tb: NDArray[np.float64], mu: NDArray[np.float64],
                      gr: NDArray[np.float64]) -> tuple[float, float]:
    """At the limb vectors ``l`` (24,) with ``ql = Q l``: the orthonormal tangent bases of the 8
    spheres into ``tb`` (24, 2; rows 3i..3i+2 hold sphere i's two vectors), the least-squares
    multipliers into ``mu`` (8,) and the Riemannian gradient in those bases into ``gr`` (16,).
    Returns the squared norms of the Riemannian and the Euclidean gradient."""
    egn = 0.0
    for i in range(24):
        e = 2.0 * (ql[i] - b[i])
        egn += e * e
    gn = 0.0
    for i in range(8):
        u0, u1, u2 = l[3 * i] / rad[i], l[3 * i + 1] / rad[i], l[3 * i + 2] / rad[i]
        g0 = 2.0 * (ql[3 * i] - b[3 * i])  # the Euclidean gradient 2 (Q l - b)
        g1 = 2.0 * (ql[3 * i + 1] - b[3 * i + 1])
        g2 = 2.0 * (ql[3 * i + 2] - b[3 * i + 2])
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
    return gn, egn


@njit
def _newton_step(q: NDArray[np.float64], wk: NewtonWork) -> bool:
    """The modified Newton step (16,) in the tangent bases ``wk.tb``, written into ``wk.step``:
    the Riemannian Hessian ``H = T^T (2 Q) T + 2 diag(mu_i)`` (``wk.mu``; ``wk.w`` (24, 16) and
    ``wk.hr`` (16, 16) its buffers; ``T`` block diagonal, 3 x 2 blocks) shifted by the smallest ``c
    4^k`` that makes it positive definite, solved for the gradient ``wk.gr``; False when no shift in
    60 did. Only the lower triangle of ``H`` is formed (the factorisation reads no other), from
    the part of ``W`` it needs."""
    tb, mu, gr, w, hr = wk.tb, wk.mu, wk.gr, wk.w, wk.hr
    for i in range(8):  # W = 2 Q T: the rows of sphere i, the columns of spheres 0..i
        for row in range(3 * i, 3 * i + 3):
            for j in range(i + 1):
                q0, q1, q2 = q[row, 3 * j], q[row, 3 * j + 1], q[row, 3 * j + 2]
                w[row, 2 * j] = 2.0 * (q0 * tb[3 * j, 0] + q1 * tb[3 * j + 1, 0] + q2 * tb[3 * j + 2, 0])
                w[row, 2 * j + 1] = 2.0 * (q0 * tb[3 * j, 1] + q1 * tb[3 * j + 1, 1] + q2 * tb[3 * j + 2, 1])
    scale = 0.0
    for i in range(8):  # H = T^T W + 2 diag(mu_i), lower triangle
        for e in range(2):
            t0, t1, t2 = tb[3 * i, e], tb[3 * i + 1, e], tb[3 * i + 2, e]
            for col in range(2 * i + e + 1):
                hr[2 * i + e, col] = t0 * w[3 * i, col] + t1 * w[3 * i + 1, col] + t2 * w[3 * i + 2, col]
            hr[2 * i + e, 2 * i + e] += 2.0 * mu[i]
    for i in range(16):
        scale = max(scale, abs(hr[i, i]))
    shift = 0.0
    for _ in range(60):
        for i in range(16):
            hr[i, i] += shift
        ok = _cholesky_into(hr, wk.lo)
        for i in range(16):
            hr[i, i] -= shift
        if ok:
            _cholesky_apply_into(wk.lo, gr, wk.y, wk.step)
            return True
        shift = 1e-6 * max(scale, 1e-300) if shift == 0.0 else 4.0 * shift
    return False


@njit
def _line_search(problem: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
                 l: NDArray[np.float64], d: NDArray[np.float64], f: float, slope: float,
                 cand: NDArray[np.float64], qc: NDArray[np.float64]) -> tuple[bool, float]:
    """Armijo backtracking on ``problem = (Q, b, rad)`` from the limb vectors ``l`` (24,,
    objective ``f``) along ``d`` (24,) with the slope ``slope``, each trial retracted onto the
    spheres: the accepted point into ``cand`` (24,) with ``Q cand`` into ``qc``; returns whether
    one was accepted (steps down to 1e-10) and its objective."""
    q, b, rad = problem
    a = 1.0
    fc = f
    while a > 1e-10:
        for i in range(24):
            cand[i] = l[i] + a * d[i]
        _retract_into(cand, l, rad, cand)
        fc = _quad_into(q, b, cand, qc)
        if fc <= f + 1e-4 * a * slope:
            return True, fc
        a *= 0.5
    return False, fc


@njit
def _sphere_newton(q: NDArray[np.float64], b: NDArray[np.float64], l0: NDArray[np.float64],
                   rad: NDArray[np.float64], max_iter: int, tol: float, wk: NewtonWork
                   ) -> tuple[NDArray[np.float64], int, bool]:
    """Riemannian Newton for ``min_l l^T Q l - 2 b^T l`` over the product of 8 spheres
    ``||l_i|| = rad_i`` (``l`` = the 8 limb vectors, (24,); ``Q`` (24, 24) positive definite).

    Each iteration: the Riemannian gradient (the Euclidean one projected on the tangent
    spaces, i.e. the KKT residual with least-squares multipliers ``mu_i``,
    :func:`_tangent_gradient`), the Riemannian Hessian ``T^T (2 Q + 2 diag(mu_i I_3)) T`` in
    orthonormal tangent bases ``T`` (24, 16), shifted by a multiple of the identity until it is
    positive definite (so the step is a descent direction; :func:`_newton_step`), the step
    retracted onto the spheres by normalisation, and Armijo backtracking on the objective
    (:func:`_line_search`; every iterate is feasible: no merit function, no Maratos effect). Stops
    when ``||grad_R|| <= tol * max(1, ||grad||)`` or when the Newton step predicts a decrease below
    ``1e-13 * max(1, |f|)`` (converged), or when the line search fails (not converged); returns
    ``(l, iterations, converged)``, ``l`` one of the buffers of ``wk`` (:class:`NewtonWork`; ``l0``
    may be ``wk.l0``). Written with scalars and the caller's buffers (it runs once per pose-ADM
    iteration).
    """
    l, ql, cand, qc, d, tb, gr, mu = wk.l, wk.ql, wk.cand, wk.qc, wk.d, wk.tb, wk.gr, wk.mu
    _retract_into(l0, l0, rad, l)
    f = _quad_into(q, b, l, ql)
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        gn, egn = _tangent_gradient(l, ql, b, rad, tb, mu, gr)
        if math.sqrt(gn) <= tol * max(1.0, math.sqrt(egn)):
            converged = True
            it -= 1
            break
        if not _newton_step(q, wk):
            break
        step = wk.step
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
        accepted, fc = _line_search((q, b, rad), l, d, f, slope, cand, qc)
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




class SphereStep(NamedTuple):
    """A pose step's operands of :func:`_riemannian_alpha_kernel`, fixed over its ADM iterations."""

    mus: NDArray[np.float64]  #: (m, r) ``M U S``, the rows' matrix (C-contiguous)
    geom: SphereGeometry  #: the quadratic in limb coordinates (:func:`_sphere_setup`)
    rad: NDArray[np.float64]  #: (8,) the limb lengths in use
    work: NewtonWork  #: the alpha-steps' buffers (:func:`newton_work`)


@njit
def _riemannian_alpha_kernel(d1: NDArray[np.float64], d2: NDArray[np.float64], sk: NDArray[np.float64],
                             step: SphereStep, km: ModelArrays, st: StepSettings,
                             alpha_out: NDArray[np.float64]) -> int:
    """The alpha-step of :func:`pose_step` (limbs on) by :func:`_sphere_newton` in limb
    coordinates (see :func:`_sphere_setup`), started from the limb vectors of the current
    iterate, whose reduced coordinates are ``sk = V^T alpha_k`` (r,). Writes ``alpha`` (k,) into
    ``alpha_out`` and ``s = V^T alpha`` (r,) into ``sk``; returns the Newton iterations (at most
    ``st.alpha_max_iter``, tolerance ``st.alpha_tol``, proximal weight ``st.prox``). Matrices come
    C-contiguous and transposed where that makes every product a sum of rows
    (:func:`_axpy_rows`): ``step.mus = M U S`` (m, r), the model's ``V``, ``V^T``, ``(C U S)^T``
    (:class:`pose_lifter.core.numeric.records.ModelArrays`) and the step's ``geom = (G s0, Q, R^T,
    S1^T, S2^T)`` (:func:`_sphere_setup`)."""
    vc, vt, s0, cu24_t, cmu24 = km.vc, km.vt, km.s0, km.cu24_t, km.cmu24
    gs0, q, rmat_t, s1_t, s2_t = step.geom
    prox = st.prox
    wk = step.work
    vtd2, h, b, l0, s = wk.vtd2, wk.h, wk.b, wk.l0, wk.s
    r = sk.size
    vtd2[:] = 0.0
    _axpy_rows(vc, d2, vtd2)  # V^T d2
    h[:] = 0.0
    _axpy_rows(step.mus, d1, h)  # (M U S)^T d1
    for j in range(r):
        h[j] += vtd2[j] + prox * sk[j] - gs0[j]
    b[:] = 0.0
    _axpy_rows(rmat_t, h, b)
    l0[:] = cmu24
    _axpy_rows(cu24_t, sk, l0)
    lv, it, _ = _sphere_newton(q, b, l0, step.rad, st.alpha_max_iter, st.alpha_tol, wk)
    s[:] = s0
    _axpy_rows(s1_t, lv, s)
    _axpy_rows(s2_t, h, s)
    for j in range(r):
        sk[j] = s[j]
        s[j] -= vtd2[j]
    alpha_out[:] = d2
    _axpy_rows(vt, s, alpha_out)  # d2 + V (s - V^T d2)
    return it
