"""A run of camera/pose alternations as one compiled kernel (the default path of
:meth:`pose_lifter.core.runs.Runs.run`).

The kernel repeats :meth:`~pose_lifter.core.runs.Runs.run`'s loop on plain float64 arrays, calling
the same compiled steps: the camera step's :func:`pose_lifter.core.camera._camera_solve` and the
pose step's :func:`pose_lifter.core.pose_kernel._riemannian_pose_kernel`. Per alternation ``i``
it minimises, for the current camera, the pose objective and then, for the new pose, the
camera objective, and evaluates the run's objective::

    F_i = sum_j cw_j |cx_j - M0 Y_j - t|_1 + theta ||alpha||_1
          + sum_j q_j |P_j,z - m3 (y_j - mean_l y_l)|_1              (hybrid: the prior's depths)

(``cx``, ``cw``: the 2D points, stacked with the prior's image positions in hybrid mode, ``Y`` the
pose, stacked twice then); it keeps the lowest-``F`` alternation and stops when
``F_{i-1} - F_i <= alternation_tol * max(|F_{i-1}|, 1e-12)``.

Applies with ``camera_solver == pose_solver == "admm"``, the Riemannian alpha-step and
``warm_duals`` off (every step starts its multipliers at zero; the kernel keeps none). The
Python loop stays the reference. Both evaluate every term with the same compiled functions (the
steps, and the objective's ``||alpha||_1`` and depth rows: :func:`pose_lifter.core.pose_kernel._sum_abs`,
:func:`~pose_lifter.core.pose_kernel._depth_term`), so on any machine they perform the same
floating-point operations; ``tests/core/test_run_kernel.py`` checks the kernel's control flow
(best alternation, stopping rule, continued runs) against the loop's.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ._jit import njit
from .camera import _camera_solve
from .pose_kernel import _depth_row, _depth_term, _n_rows, _riemannian_pose_kernel, _sum_abs

__all__ = ["CAMERA_DIVERGED", "OK", "POSE_DIVERGED"]

#: Status codes of :func:`_run_kernel`.
OK, CAMERA_DIVERGED, POSE_DIVERGED = 0, 1, 2


@njit
def _run_kernel(
    xn: NDArray[np.float64], w: NDArray[np.float64], cx: NDArray[np.float64], cw: NDArray[np.float64],
    doubled: bool, mean: NDArray[np.float64], u: NDArray[np.float64], sig: NDArray[np.float64],
    vc: NDArray[np.float64], vt: NDArray[np.float64], comps: NDArray[np.float64],
    limb_matrix: NDArray[np.float64], z: NDArray[np.float64], nmat: NDArray[np.float64],
    s0: NDArray[np.float64], rad: NDArray[np.float64], cu24_t: NDArray[np.float64],
    cmu24: NDArray[np.float64], xp: NDArray[np.float64], pw: NDArray[np.float64], has_prior: bool,
    alpha0: NDArray[np.float64], y0: NDArray[np.float64], m_init: NDArray[np.float64],
    t_init: NDArray[np.float64], continued: bool, best_obj0: float, prev0: float, it0: int, n_alt: int,
    alt_tol: float, th: float, l1: bool, eta: float, eta_growth: float, eta_max: float, pose_max_iter: int,
    pose_tol: float, alpha_max_iter: int, alpha_tol: float, prox: float, cam_max_iter: int, cam_tol: float,
    tau: float,
) -> tuple[int, int, int, bool, int, float, NDArray[np.float64], NDArray[np.int64], NDArray[np.float64],
           NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.int64]]:
    """Alternations ``it0 + 1 .. n_alt`` of a run (module docstring).

    Parameters
    ----------
    xn, w : ndarray, shapes (12, 2), (12,)
        The pose step's 2D points and weights.
    cx, cw : ndarray, shapes (n, 2), (n,)
        The camera step's (``doubled``: n = 24, the 2D then the prior's image positions, matched
        to the pose stacked twice).
    mean ... cmu24 : ndarray
        The model's arrays, as :func:`pose_lifter.core.pose_kernel._riemannian_pose_kernel` takes
        them (``nmat`` its ``n``; ``rad`` (8,) the limb radii in use).
    xp, pw : ndarray, shapes (12, 3), (12, 2)
        The prior's rows (zeros: none); ``has_prior``: its depth term counts in ``F``.
    alpha0 : ndarray, shape (k,)
        The first pose step's start.
    y0, m_init, t_init : ndarray, shapes (36,), (2, 3), (2,)
        A new run (``continued`` False): a camera step for the pose ``y0`` from ``M = m_init``,
        ``t = t_init`` comes first. A continued run: ``m_init``, ``t_init`` are the camera of the
        first pose step (``y0`` unused), ``best_obj0`` the run's best ``F`` so far.
    prev0 : float
        The last alternation's ``F`` (``inf`` for a new run); ``it0`` its index.
    n_alt, alt_tol : int, float
        The alternation cap and the relative-decrease tolerance.
    th ... tau
        The steps' settings (``th``: theta, 0 without sparsity).

    Returns
    -------
    tuple
        ``(status, alternations done, last alternation index, converged, best alternation index
        (-1: none beat best_obj0), its F, objectives (n_alt - it0, 3) [F, camera objective, pose
        objective], counts (n_alt - it0, 4) [camera iterations, camera converged, pose iterations,
        pose converged] (rows beyond the done ones unused), and of the best alternation: alpha
        (k,), pose (36,), rotation (3, 3), translation (2,), [pose objective, limb violation,
        camera objective, scale] (4,), [pose iterations, pose converged, alpha-step iterations,
        camera iterations, camera converged] (5,))``. ``status`` is :data:`OK`, or
        :data:`CAMERA_DIVERGED` / :data:`POSE_DIVERGED` (a non-finite camera or pose; the run
        stopped there).
    """
    k = alpha0.size
    nj = xn.shape[0]
    n_rows = _n_rows(pw)  # the pose step's L1 rows (its multipliers' size)
    nc = cx.shape[0]
    objs = np.zeros((max(n_alt - it0, 0), 3))
    counts = np.zeros((max(n_alt - it0, 0), 4), dtype=np.int64)
    b_alpha = np.zeros(k)
    b_y = np.zeros(3 * nj)
    b_rot = np.zeros((3, 3))
    b_t = np.zeros(2)
    b_f = np.zeros(4)
    b_i = np.zeros(5, dtype=np.int64)
    b_idx = -1
    b_obj = best_obj0
    m0 = np.ascontiguousarray(m_init)
    t = t_init.copy()
    ycam = np.empty((nc, 3))
    status = OK
    if not continued:
        for j in range(nc):
            jj = j % nj if doubled else j
            for a in range(3):
                ycam[j, a] = y0[3 * jj + a]
        rot, scale, t, _, _, _, ok = _camera_solve(cx, ycam, cw, m0, t, np.zeros((nc, 2)), np.zeros((2, 3)),
                                                   l1, cam_max_iter, cam_tol, tau)
        if not ok:
            return (CAMERA_DIVERGED, 0, it0, False, b_idx, b_obj, objs, counts, b_alpha, b_y, b_rot, b_t, b_f,
                    b_i)
        m0 = scale * rot[:2]
    alpha = alpha0
    prev = prev0
    converged = False
    it = it0
    done = 0
    zero3 = np.zeros(3)
    for it in range(it0 + 1, n_alt + 1):
        m3 = _depth_row(m0) if has_prior else zero3
        pa, pobj, viol, y, _, pit, pconv, ait = _riemannian_pose_kernel(
            xn, m0, t, w, mean, u, sig, vc, vt, comps, limb_matrix, z, nmat, s0, rad, cu24_t, cmu24, alpha,
            np.zeros(n_rows), np.zeros(k), th, l1, eta, eta_growth, eta_max, pose_max_iter, pose_tol,
            alpha_max_iter, alpha_tol, prox, xp, pw, m3)
        for i in range(k):
            if not math.isfinite(pa[i]):
                status = POSE_DIVERGED
        if status != OK:
            break
        alpha = pa
        for j in range(nc):
            jj = j % nj if doubled else j
            for a in range(3):
                ycam[j, a] = y[3 * jj + a]
        rot, scale, t_c, cobj, cit, cconv, ok = _camera_solve(cx, ycam, cw, m0, t, np.zeros((nc, 2)),
                                                             np.zeros((2, 3)), l1, cam_max_iter, cam_tol, tau)
        if not ok:
            status = CAMERA_DIVERGED
            break
        m0 = scale * rot[:2]
        t = t_c
        obj = cobj + th * _sum_abs(alpha)
        if has_prior:
            obj += _depth_term(y, m0, xp, pw)
        objs[done, 0], objs[done, 1], objs[done, 2] = obj, cobj, pobj
        counts[done, 0], counts[done, 1], counts[done, 2], counts[done, 3] = cit, cconv, pit, pconv
        done += 1
        if (b_idx < 0 and not continued) or obj < b_obj:
            b_idx, b_obj = it, obj
            b_alpha[:] = pa
            b_y[:] = y
            b_rot[:] = rot
            b_t[:] = t_c
            b_f[0], b_f[1], b_f[2], b_f[3] = pobj, viol, cobj, scale
            b_i[0], b_i[1], b_i[2], b_i[3], b_i[4] = pit, pconv, ait, cit, cconv
        if prev - obj <= alt_tol * max(abs(prev), 1e-12) and math.isfinite(prev):
            converged = True
            break
        prev = obj
    return (status, done, it, converged, b_idx, b_obj, objs, counts, b_alpha, b_y, b_rot, b_t, b_f, b_i)
