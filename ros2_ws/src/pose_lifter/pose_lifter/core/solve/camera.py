"""Camera step (paper eq. 5 and appendix B): robust weak-perspective camera by ADM.

Problem (per joint weights ``w_j >= 0``, points ``x_j in R^2``, pose ``y_j in R^3``)::

    minimise_{M0, t}  sum_j w_j * rho(x_j - M0 y_j - t)
    subject to        M0 = s [r1; r2],  s > 0,  [r1; r2] orthonormal rows

with ``rho = ||.||_1`` (the paper) or ``||.||_2^2`` (the L2 ablations).

Departure from the paper: eq. (5) constrains only ``m1 . m2 = 0``. A weak-perspective camera
also has ``||m1|| = ||m2||``; without it the camera degenerates (one image axis squashed;
measured in ``shared/notes/method-pitfalls.md`` §1). We keep the paper's ADM structure but
split the projection ``N`` (unconstrained, closed-form least squares) from its copy
``M`` on the scaled-orthographic set (closed-form projection by SVD: the nearest
``s [r1; r2]`` to ``N`` in Frobenius norm is ``mean(sigma) U V^T``)::

    min  sum_j w_j rho(R_j)   s.t.  R = X - Y N^T - 1 t^T,   N = M,   M scaled-orthographic

Scaled-form ADM with penalty ``tau``:
    R  <- prox_{rho_w / tau}(X - Y N^T - 1 t^T + U1)        (soft-threshold for L1)
    N,t<- argmin ||X - R + U1 - Y N^T - 1 t^T||^2 + ||N - M + U2||^2   (4x4 normal equations)
    M  <- Proj_scaled-orthographic(N + U2)
    U1 <- U1 + X - Y N^T - 1 t^T - R;   U2 <- U2 + N - M
Translation is a free variable of the camera (x_j ~ M0 y_j + t), so 2D and 3D need no
joint-wise centring; missing joints (w_j = 0) drop out of the loss. On exit ``t`` is
re-optimised exactly for the final ``M`` (weighted median for L1, weighted mean for L2).

The ADM iterations run as a kernel on plain float64 arrays, compiled by numba
(``njit(cache=True)``) when numba is importable and run as the same Python code otherwise.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, SolverError, diverged_as_solver_error
from ..numeric.jit import njit
from ..numeric.records import StepSettings
from ..options import LifterOptions
from ..results import Camera, CameraResult, Duals
from .settings import step_settings

_DEFAULTS = LifterOptions()

__all__ = ["camera_objective", "camera_step", "initial_camera", "project_scaled_orthographic",
           "weighted_median"]


def project_scaled_orthographic(n: NDArray[np.float64]) -> NDArray[np.float64]:
    """Nearest scaled-orthographic 2x3 matrix ``s [r1; r2]`` to ``n`` (Frobenius norm).

    Closed form without an SVD: with ``A = n n^T`` (2x2), ``sqrt(A) = (A + sqrt(det A) I) / t``
    and ``t = tr sqrt(A) = sigma_1 + sigma_2``, the answer ``mean(sigma) U V^T =
    (t / 2) sqrt(A)^{-1} n = (adj(A) + sqrt(det A) I) n / (2 sqrt(det A))``. A (near) rank-1
    ``n`` falls back to the SVD.
    """
    n = np.ascontiguousarray(n, dtype=np.float64)
    if n.shape != (2, 3):
        raise InvalidInputError(f"expected a (2, 3) matrix, got shape {n.shape}")
    return _project_so(n)


@njit
def _project_so(n: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`project_scaled_orthographic` of a C-contiguous (2, 3) float64 array."""
    out = np.empty((2, 3))
    _project_so_into(n, out)
    return out


@njit
def _project_so_into(n: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """:func:`project_scaled_orthographic` of a C-contiguous (2, 3) float64 array, written into
    ``out`` (2, 3) (not ``n``)."""
    a0, a1, a2 = n[0, 0], n[0, 1], n[0, 2]
    b0, b1, b2 = n[1, 0], n[1, 1], n[1, 2]
    a = a0 * a0 + a1 * a1 + a2 * a2
    c = b0 * b0 + b1 * b1 + b2 * b2
    b = a0 * b0 + a1 * b1 + a2 * b2
    det = a * c - b * b
    if det > 1e-8 * (a + c) ** 2:  # else (near) rank 1: cancellation in det, use the SVD
        sd = math.sqrt(det)
        f = 0.5 / sd
        p, q, r = f * (c + sd), -f * b, f * (a + sd)
        out[0, 0], out[0, 1], out[0, 2] = p * a0 + q * b0, p * a1 + q * b1, p * a2 + q * b2
        out[1, 0], out[1, 1], out[1, 2] = q * a0 + r * b0, q * a1 + r * b1, q * a2 + r * b2
        return
    u, s, vt = np.linalg.svd(n, full_matrices=False)
    out[:] = s.mean() * (u @ vt)


def weighted_median(values: NDArray[np.float64], weights: NDArray[np.float64]) -> float:
    """A minimiser of ``sum_j w_j |values_j - m|`` (values, weights: shape (n,)): the first sorted
    value whose cumulative weight reaches half the total, or the midpoint of it and the next when
    it reaches exactly half; the plain median if the weights sum to 0."""
    return _weighted_median_jit(np.ascontiguousarray(values, dtype=np.float64),
                                np.ascontiguousarray(weights, dtype=np.float64))


def camera_objective(
    points: NDArray[np.float64], pose: NDArray[np.float64], weights: NDArray[np.float64],
    m0: NDArray[np.float64], t: NDArray[np.float64], loss: Literal["l1", "l2"],
) -> float:
    """``sum_j w_j rho(x_j - M0 y_j - t)``; points (n,2), pose (n,3), weights (n,)."""
    r = points - pose @ m0.T - t
    if loss == "l1":
        return float(np.sum(weights[:, None] * np.abs(r)))
    return float(np.sum(weights[:, None] * r * r))


def _check(points: NDArray[np.float64], pose: NDArray[np.float64], weights: NDArray[np.float64]) -> None:
    if points.ndim != 2 or points.shape[1] != 2:
        raise InvalidInputError(f"points must be (n, 2), got {points.shape}")
    if pose.shape != (points.shape[0], 3):
        raise InvalidInputError(f"pose must be ({points.shape[0]}, 3), got {pose.shape}")
    if weights.shape != (points.shape[0],):
        raise InvalidInputError(f"weights must be ({points.shape[0]},), got {weights.shape}")
    if not (np.all(np.isfinite(points)) and np.all(np.isfinite(pose)) and np.all(np.isfinite(weights))):
        raise InvalidInputError("camera step inputs must be finite")
    if np.count_nonzero(weights > 0) < 3:
        raise InvalidInputError("the camera step needs at least 3 joints with positive weight")


def camera_step(
    points: NDArray[np.float64],
    pose: NDArray[np.float64],
    weights: NDArray[np.float64],
    options: LifterOptions | None = None,
    init: Camera | None = None,
    duals: Duals | None = None,
) -> CameraResult:
    """Robust scaled-orthographic camera for a fixed 3D pose (see module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    pose : ndarray, shape (n, 3)
    weights : ndarray, shape (n,)
        ``>= 0``; at least 3 positive.
    options : LifterOptions, optional
        The settings (default ``LifterOptions()``): the loss of ``variant`` (L1 or L2),
        ``camera_max_iter`` (iteration cap), ``camera_tol`` (stop when the relative primal
        residuals and the relative change of ``M`` are all below it) and ``tau`` (the ADM's
        constant penalty).
    init : Camera, optional
        Warm start; without it the weighted least-squares affine fit projected onto the
        scaled-orthographic set.
    duals : Duals, optional
        Warm start of the scaled multipliers ``(U1 (n, 2), U2 (2, 3))``, e.g. the previous camera
        step's of the same solve (default zeros).

    Returns
    -------
    CameraResult
        The camera, ``objective = sum_j w_j rho(x_j - M0 y_j - t)``, iterations, converged, and
        the final multipliers.

    Raises
    ------
    InvalidInputError
        Shapes, non-finite inputs or fewer than 3 positive weights.
    SolverError
        The ADM diverged (non-finite camera) on valid input.
    """
    x = np.ascontiguousarray(points, dtype=np.float64)
    y = np.ascontiguousarray(pose, dtype=np.float64)
    w = np.ascontiguousarray(weights, dtype=np.float64)
    _check(x, y, w)
    return camera_step_trusted(x, y, w, _DEFAULTS if options is None else options, init, duals)


def camera_step_trusted(
    x: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64], options: LifterOptions,
    init: Camera | None = None, duals: Duals | None = None, max_iter: int | None = None,
) -> CameraResult:
    """:func:`camera_step` on inputs already checked (C-contiguous float64, finite, shapes as
    documented, >= 3 positive weights): the lifter's per-alternation call (its inputs are checked
    once per lift), at most ``max_iter`` ADM iterations (None: ``options.camera_max_iter``)."""
    n = x.shape[0]
    if init is None:
        m, t = initial_camera(x, y, w)
    else:
        m = np.ascontiguousarray(init.projection, dtype=np.float64)
        t = np.array(init.translation, dtype=np.float64)
    if duals is None:
        u1 = np.zeros((n, 2))
        u2 = np.zeros((2, 3))
    else:
        u1 = np.array(duals.data, dtype=np.float64)
        u2 = np.array(duals.coupling, dtype=np.float64)
    with diverged_as_solver_error("camera step"):
        out = _camera_solve(CameraProblem(x, y, w), m, t, CameraDuals(u1, u2), step_settings(options),
                            options.camera_max_iter if max_iter is None else max_iter)
    if not out.finite:
        raise SolverError("camera step diverged (non-finite camera); check the inputs")
    return CameraResult(objective=out.objective, n_iter=out.n_iter, converged=out.converged,
                        camera=Camera(out.rotation, out.scale, out.translation), duals=Duals(u1, u2))


def initial_camera(x: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The camera step's cold start ``(M (2, 3), t (2,))`` for points ``x`` (n, 2), pose ``y``
    (n, 3), weights ``w`` (n,): the weighted least-squares affine fit projected onto the
    scaled-orthographic set (``[I 0]`` when that degenerates) and the L2-optimal ``t`` for it."""
    n = x.shape[0]
    ya = np.hstack([y, np.ones((n, 1))])  # (n, 4)
    sw = np.sqrt(w)[:, None]
    sol, *_ = np.linalg.lstsq(sw * ya, sw * x, rcond=None)  # (4, 2)
    m = project_scaled_orthographic(sol[:3].T)
    if not np.isfinite(m).all() or np.linalg.norm(m) < 1e-12:
        m = np.hstack([np.eye(2), np.zeros((2, 1))])
    t = np.asarray(w @ (x - y @ m.T) / w.sum())  # the L2-optimal translation for this M
    return m, t


class CameraProblem(NamedTuple):
    """A camera step's data: ``sum_j w_j rho(x_j - M0 y_j - t)`` over ``n`` points."""

    x: NDArray[np.float64]  #: (n, 2) the 2D points
    y: NDArray[np.float64]  #: (n, 3) the pose's joints
    w: NDArray[np.float64]  #: (n,) the weights (0: missing)


class CameraDuals(NamedTuple):
    """The camera ADM's scaled multipliers (updated in place)."""

    u1: NDArray[np.float64]  #: (n, 2) of ``Z = Ya [N; t]^T``
    u2: NDArray[np.float64]  #: (2, 3) of ``N = M``


class CameraSetup(NamedTuple):
    """What the camera ADM's iterations (:func:`_camera_kernel`) take from its set-up in
    :func:`_camera_solve`, for ``n`` points."""

    ya: NDArray[np.float64]  #: (n, 4) the pose's joints with a column of ones
    hat: NDArray[np.float64]  #: (4, n) ``(Ya^T Ya + D)^-1 Ya^T``: the (N, t) step's data term
    lhs3: NDArray[np.float64]  #: (4, 3) ``(Ya^T Ya + D)^-1`` on the splitting's columns
    thr: NDArray[np.float64]  #: (n, 2) the L1 prox thresholds ``w / tau``
    l2fac: NDArray[np.float64]  #: (n, 2) the L2 prox factors ``tau / (2 w + tau)``
    scale_x: float  #: the visible points' spread (the stopping rule's residual scale)


class CameraSolve(NamedTuple):
    """What :func:`_camera_solve` returns."""

    rotation: NDArray[np.float64]  #: (3, 3)
    scale: float
    translation: NDArray[np.float64]  #: (2,)
    objective: float  #: the camera objective at the returned camera
    n_iter: int  #: ADM iterations
    converged: bool  #: whether the stopping rule ended the ADM (not the cap)
    finite: bool  #: rotation, translation and a positive scale all finite


@njit
def _camera_solve(problem: CameraProblem, m: NDArray[np.float64], t: NDArray[np.float64], u: CameraDuals,
                  st: StepSettings, max_iter: int) -> CameraSolve:
    """Set-up, ADM iterations (:func:`_camera_kernel`, at most ``max_iter``) and finish
    (:func:`_camera_finish`) of the camera step of ``problem`` from ``M`` (2, 3), ``t`` (2,), the
    multipliers ``u`` (updated in place) and the settings ``st`` (the loss, ``cam_tol``, ``tau``)."""
    x, y, w = problem.x, problem.y, problem.w
    tau = st.tau
    n = x.shape[0]
    ya = np.ones((n, 4))
    ya[:, :3] = y
    # normal equations of the (N, t) step: (Ya^T Ya + D) v = Ya^T Z + D (M - U2)
    lhs = ya.T @ ya
    for i in range(3):
        lhs[i, i] += 1.0
    lhs_inv = np.linalg.inv(lhs)
    hat = np.ascontiguousarray(lhs_inv @ ya.T)  # (4, n)
    lhs3 = np.ascontiguousarray(lhs_inv[:, :3])  # (4, 3)
    # spread of the visible points (the residual scale of the stopping rule)
    cx, cy, nv = 0.0, 0.0, 0
    for j in range(n):
        if w[j] > 0:
            cx += x[j, 0]
            cy += x[j, 1]
            nv += 1
    cx /= nv
    cy /= nv
    ss = 0.0
    for j in range(n):
        if w[j] > 0:
            ss += (x[j, 0] - cx) ** 2 + (x[j, 1] - cy) ** 2
    scale_x = max(math.sqrt(ss), 1e-12)
    thr = np.empty((n, 2))
    l2fac = np.empty((n, 2))
    for j in range(n):
        for c in range(2):
            thr[j, c] = w[j] / tau
            l2fac[j, c] = tau / (2.0 * w[j] + tau)
    setup = CameraSetup(ya, hat, lhs3, thr, l2fac, scale_x)
    m, it, converged = _camera_kernel(x, setup, m, t, u, st, max_iter)
    rot, scale, t_out, obj = _camera_finish(x, y, w, m, st.l1)
    ok = bool(np.all(np.isfinite(rot)) and np.all(np.isfinite(t_out)) and math.isfinite(scale) and scale > 0)
    return CameraSolve(rot, scale, t_out, obj, it, converged, ok)


@njit
def _weighted_median_jit(values: NDArray[np.float64], weights: NDArray[np.float64]) -> float:
    """:func:`weighted_median` (its implementation; also called inside the compiled kernels)."""
    order = np.argsort(values, kind="mergesort")  # stable, as numpy's "stable"
    total = 0.0
    for i in range(values.size):
        total += weights[i]
    if total <= 0.0:
        return float(np.median(values))
    half = 0.5 * total
    cw = 0.0
    for k in range(values.size):
        cw += weights[order[k]]
        if cw >= half:  # numpy.searchsorted(cw, half) (side "left")
            if abs(cw - half) <= 1e-8 + 1e-5 * abs(half) and k + 1 < values.size:  # numpy.isclose
                return float(0.5 * (values[order[k]] + values[order[k + 1]]))
            return float(values[order[k]])
    return float(values[order[values.size - 1]])


@njit
def _camera_finish(x: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64],
                   m: NDArray[np.float64], l1: bool
                   ) -> tuple[NDArray[np.float64], float, NDArray[np.float64], float]:
    """From the ADM's scaled-orthographic ``M`` (2, 3): the nearest ``scale * R[:2]`` (with
    ``M = U diag(s) V^T``: ``R[:2] = U V^T``, ``scale = mean(s)``, ``R[2] = R[0] x R[1]``), the
    optimal translation for it (weighted median per axis for L1, weighted mean for L2) and the
    objective ``sum_j w_j rho(x_j - M0 y_j - t)``."""
    u, sv, vt = np.linalg.svd(m, full_matrices=False)
    r2 = u @ vt
    scale = 0.5 * (sv[0] + sv[1])
    m0 = scale * r2
    rot = np.empty((3, 3))
    rot[:2] = r2
    rot[2, 0] = r2[0, 1] * r2[1, 2] - r2[0, 2] * r2[1, 1]
    rot[2, 1] = r2[0, 2] * r2[1, 0] - r2[0, 0] * r2[1, 2]
    rot[2, 2] = r2[0, 0] * r2[1, 1] - r2[0, 1] * r2[1, 0]
    t = _optimal_translation(x, y, w, m0, l1)
    obj = 0.0
    for j in range(x.shape[0]):
        for c in range(2):
            r = x[j, c] - (y[j, 0] * m0[c, 0] + y[j, 1] * m0[c, 1] + y[j, 2] * m0[c, 2]) - t[c]
            obj += w[j] * (abs(r) if l1 else r * r)
    return rot, scale, t, obj


@njit
def _optimal_translation(x: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64],
                         m0: NDArray[np.float64], l1: bool) -> NDArray[np.float64]:
    """The ``t`` (2,) minimising ``sum_j w_j rho(x_j - M0 y_j - t)`` for a fixed ``M0`` (2, 3):
    per axis the weighted median (L1) or the weighted mean (L2) of ``x_j - M0 y_j``."""
    n = x.shape[0]
    t = np.empty(2)
    col = np.empty(n)
    for c in range(2):
        for j in range(n):
            col[j] = x[j, c] - (y[j, 0] * m0[c, 0] + y[j, 1] * m0[c, 1] + y[j, 2] * m0[c, 2])
        if l1:
            t[c] = _weighted_median_jit(col, w)
        else:
            e, wsum = 0.0, 0.0
            for j in range(n):
                e += w[j] * col[j]
                wsum += w[j]
            t[c] = e / wsum
    return t


@njit
def _camera_kernel(x: NDArray[np.float64], setup: CameraSetup, m: NDArray[np.float64], t: NDArray[np.float64],
                   u: CameraDuals, st: StepSettings, max_iter: int) -> tuple[NDArray[np.float64], int, bool]:
    """The ADM iterations of :func:`camera_step` on plain arrays (compiled by numba when
    available) for the points ``x`` (n, 2) from ``M`` (2, 3), ``t`` (2,), the loss and tolerance of
    ``st``, at most ``max_iter`` iterations: ``(M, iterations, converged)``; the multipliers ``u``
    are updated in place. Written as loops over the (n, 2) arrays: at these sizes array expressions
    cost more in temporaries than in arithmetic."""
    ya, hat, lhs3, thr, l2fac, scale_x = setup
    u1, u2 = u.u1, u.u2
    l1, tol = st.l1, st.cam_tol
    n = x.shape[0]
    converged = False
    it = 0
    sol = np.empty((4, 2))  # [N^T; t]
    sol[:3] = m.T
    sol[3] = t
    proj = np.empty((n, 2))
    for j in range(n):
        for c in range(2):
            proj[j, c] = (ya[j, 0] * sol[0, c] + ya[j, 1] * sol[1, c] + ya[j, 2] * sol[2, c]
                          + ya[j, 3] * sol[3, c])
    z = np.empty((n, 2))
    r = np.empty((n, 2))
    nmat = np.empty((2, 3))
    m_bufs = (np.empty((2, 3)), np.empty((2, 3)))  # the projections, written in turn (never the caller's M)
    tol2 = tol * tol
    for it in range(1, max_iter + 1):
        for j in range(n):
            for c in range(2):
                xu = x[j, c] + u1[j, c]
                vv = xu - proj[j, c]
                if l1:
                    rr = vv - min(max(vv, -thr[j, c]), thr[j, c])
                else:
                    rr = l2fac[j, c] * vv
                r[j, c] = rr
                z[j, c] = xu - rr
        # sol = hat @ z + lhs3 @ (M - U2)^T
        for a in range(4):
            for c in range(2):
                e = 0.0
                for j in range(n):
                    e += hat[a, j] * z[j, c]
                for b in range(3):
                    e += lhs3[a, b] * (m[c, b] - u2[c, b])
                sol[a, c] = e
        for c in range(2):
            for b in range(3):
                nmat[c, b] = sol[b, c] + u2[c, b]
        m_prev = m
        m = m_bufs[it % 2]
        _project_so_into(nmat, m)
        res1_sq = 0.0
        for j in range(n):
            for c in range(2):
                p = (ya[j, 0] * sol[0, c] + ya[j, 1] * sol[1, c] + ya[j, 2] * sol[2, c]
                     + ya[j, 3] * sol[3, c])
                proj[j, c] = p
                e = x[j, c] - p - r[j, c]
                u1[j, c] += e
                res1_sq += e * e
        res2_sq = 0.0
        mn2 = 0.0
        dm2 = 0.0
        for c in range(2):
            for b in range(3):
                e = sol[b, c] - m[c, b]
                u2[c, b] += e
                res2_sq += e * e
                mn2 += m[c, b] * m[c, b]
                dm2 += (m[c, b] - m_prev[c, b]) ** 2
        mn2 = max(mn2, 1e-24)
        if res1_sq < tol2 * scale_x * scale_x and res2_sq < tol2 * mn2 and dm2 < tol2 * mn2:
            converged = True
            break
    return m, it, converged
