"""A run of camera/pose alternations as one compiled kernel: the run of the default solver
(:meth:`pose_lifter.core.lift.runs.Runs.run_all`; every person's runs of a stage in one call,
:func:`run_calls`).

Per alternation ``i`` the kernel minimises, for the current camera, the pose objective (the
compiled pose step, :func:`pose_lifter.core.solve.pose_kernel._pose_kernel`) and then, for the new
pose, the camera objective (:func:`pose_lifter.core.solve.camera._camera_solve`), and evaluates the
run's objective::

    F_i = sum_j cw_j |cx_j - M0 Y_j - t|_1 + theta ||alpha||_1
          + sum_j q_j |P_j,z - m3 (y_j - mean_l y_l)|_1              (hybrid: the prior's depths)

(``cx``, ``cw``: the 2D points, stacked with the prior's image positions in hybrid mode, ``Y`` the
pose, stacked twice then); it keeps the lowest-``F`` alternation and stops when
``F_{i-1} - F_i <= alternation_tol * max(|F_{i-1}|, 1e-12)`` (:func:`_alternation_stops`).

Applies with ``camera_solver == pose_solver == "admm"`` and a compiled alpha-step: the Riemannian
one (limbs on, bases whose limb map is onto) or the linear one (the variants without limbs); every
step starts its multipliers at zero (the kernel keeps none). The cvxpy references and the paper's
inner ADM (limbs on smaller bases) run in the Python loop,
:func:`pose_lifter.core.reference.runs.alternation_loop` (the kernel's reference), which calls the
same objective terms and stopping rule.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..numeric.jit import njit, njit_nogil
from ..numeric.records import ModelArrays, StepSettings
from ..numeric.threads import thread_pool
from .camera import CameraDuals, CameraProblem, CameraSolve, _camera_solve
from .pose_kernel import Multipliers, PoseOut, PoseProblem, _depth_term, _n_rows, _pose_kernel, _sum_abs

__all__ = ["RunCall", "RunOut", "RunStatus", "run_calls"]


class RunStatus(IntEnum):
    """How a compiled run ended (:attr:`RunOut.status`)."""

    OK = 0  #: every alternation it did finished
    CAMERA_DIVERGED = 1  #: a camera step gave a non-finite camera (the run stopped there)
    POSE_DIVERGED = 2  #: a pose step gave non-finite coefficients (the run stopped there)


# the codes as the kernel writes them (plain ints: a compile-time constant each)
_OK = int(RunStatus.OK)
_CAMERA_DIVERGED = int(RunStatus.CAMERA_DIVERGED)
_POSE_DIVERGED = int(RunStatus.POSE_DIVERGED)


class RunOut(NamedTuple):
    """What :func:`_run_kernel` returns; the ``best_*`` fields are the kept alternation's."""

    status: int  #: a :class:`RunStatus` (its code inside the kernel)
    done: int  #: alternations done by this call
    it: int  #: the last alternation's index
    converged: bool  #: whether the stopping rule ended the run (not the cap)
    best_it: int  #: the kept alternation's index (-1: none beat the continued run's objective)
    best_obj: float  #: its ``F``
    objs: NDArray[np.float64]  #: (n_alt - it0, 3) per alternation: F, camera and pose objectives
    counts: NDArray[np.int64]  #: (n_alt - it0, 4): camera iterations, converged, pose iterations, converged
    alpha: NDArray[np.float64]  #: (k,)
    pose: NDArray[np.float64]  #: (36,)
    rotation: NDArray[np.float64]  #: (3, 3)
    translation: NDArray[np.float64]  #: (2,)
    scale: float  #: the camera's
    pose_objective: float  #: the kept pose step's objective
    limb_violation: float  #: its largest limb-length error
    camera_objective: float  #: the kept camera step's objective
    pose_iter: int  #: the kept pose step's ADM iterations
    pose_converged: bool
    alpha_iter: int  #: its alpha-step iterations, summed
    camera_iter: int  #: the kept camera step's ADM iterations
    camera_converged: bool


class RunCall(NamedTuple):
    """The operands of one run for :func:`_run_kernel` but the model and the settings, which
    every run of a lifter shares: the normalised 2D and its weights, the prior's target, weights
    and the limb lengths in use (zeros: no prior), the first pose step's start, the start pose and
    camera ``[M | t]``, and for a continued run its best objective and alternations done; the
    alternation cap and the pose and camera steps' iteration caps."""

    xn: NDArray[np.float64]  #: (12, 2)
    w: NDArray[np.float64]  #: (12,)
    xp: NDArray[np.float64]  #: (12, 3)
    pw: NDArray[np.float64]  #: (12, 2)
    rad: NDArray[np.float64]  #: (8,)
    alpha0: NDArray[np.float64]  #: (k,)
    y0: NDArray[np.float64]  #: (36,)
    cam0: NDArray[np.float64]  #: (2, 4)
    obj0: float
    it0: int
    n_alt: int
    pose_max_iter: int
    camera_max_iter: int


@njit
def _run_objective(cobj: float, alpha: NDArray[np.float64], th: float, y: NDArray[np.float64],
                   m0: NDArray[np.float64], xp: NDArray[np.float64], pw: NDArray[np.float64]) -> float:
    """A run's objective ``F`` (module docstring) after an alternation: the camera step's objective
    ``cobj``, ``th ||alpha||_1`` and the prior's depth rows of the pose ``y`` (36,) under the
    camera ``m0`` (2, 3) (none when ``pw[:, 1]`` is all zero)."""
    obj = cobj + th * _sum_abs(alpha)
    if (pw[:, 1] > 0.0).any():
        obj += _depth_term(y, m0, xp, pw)
    return obj


@njit
def _alternation_stops(prev: float, obj: float, tol: float) -> bool:
    """The run's stopping rule: ``F`` fell by no more than ``tol`` relative to the previous
    alternation's (``prev``; ``inf`` before the first, which never stops)."""
    return prev - obj <= tol * max(abs(prev), 1e-12) and math.isfinite(prev)


@njit
def _stack_camera_data(xn: NDArray[np.float64], w: NDArray[np.float64], xp: NDArray[np.float64],
                       pw: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
    """The camera step's 2D points and weights: with prior image rows (``pw[:, 0] > 0``) the
    prior's image positions follow the 2D (n = 24; the pose is then stacked twice, the flag)."""
    if not (pw[:, 0] > 0.0).any():
        return xn, w, False
    nj = xn.shape[0]
    cx = np.empty((2 * nj, 2))
    cw = np.empty(2 * nj)
    for j in range(nj):
        cx[j, 0], cx[j, 1], cw[j] = xn[j, 0], xn[j, 1], w[j]
        cx[nj + j, 0], cx[nj + j, 1], cw[nj + j] = xp[j, 0], xp[j, 1], pw[j, 0]
    return cx, cw, True


@njit
def _camera_for(cx: NDArray[np.float64], cw: NDArray[np.float64], pose: NDArray[np.float64], doubled: bool,
                ycam: NDArray[np.float64], m0: NDArray[np.float64], t: NDArray[np.float64], st: StepSettings,
                max_iter: int) -> CameraSolve:
    """The camera step of a run for the flat pose ``pose`` (36,) from ``[m0 | t]``, its
    multipliers from zero, at most ``max_iter`` iterations: the pose's joints written into
    ``ycam`` (n, 3) (twice, ``doubled``, when ``cx`` (n, 2), ``cw`` (n,) hold the prior's image
    positions after the 2D)."""
    nc = cx.shape[0]
    nj = nc // 2 if doubled else nc
    for j in range(nc):
        jj = j % nj if doubled else j
        for a in range(3):
            ycam[j, a] = pose[3 * jj + a]
    duals = CameraDuals(np.zeros((nc, 2)), np.zeros((2, 3)))
    return _camera_solve(CameraProblem(cx, ycam, cw), m0, t, duals, st, max_iter)


@njit
def _keep(out: RunOut, it: int, obj: float, p: PoseOut, c: CameraSolve) -> RunOut:
    """``out`` with alternation ``it`` (its ``F`` ``obj``, pose step ``p``, camera step ``c``) as
    the kept one: its arrays written in place, its scalars in the returned record."""
    out.alpha[:] = p.alpha
    out.pose[:] = p.pose
    out.rotation[:] = c.rotation
    out.translation[:] = c.translation
    return RunOut(out.status, out.done, out.it, out.converged, it, obj, out.objs, out.counts, out.alpha,
                  out.pose, out.rotation, out.translation, c.scale, p.objective, p.limb_violation,
                  c.objective, p.n_iter, p.converged, p.alpha_iter, c.n_iter, c.converged)


@njit
def _run_kernel(call: RunCall, km: ModelArrays, st: StepSettings) -> RunOut:
    """Alternations ``it0 + 1 .. n_alt`` of the run ``call`` (module docstring; its operands:
    :class:`RunCall`) with the model ``km`` and the steps' settings ``st``
    (:mod:`pose_lifter.core.numeric.records`).

    A new run (``it0 == 0``): a camera step for the pose ``y0`` from the camera ``cam0 = [M | t]``
    comes first. A continued run (``it0 >= 1``, the alternations it has done): ``cam0`` is the
    camera of the first pose step (``y0`` unused) and ``obj0`` the run's best (and last) ``F``.
    """
    xn, w, xp, pw, it0, n_alt = call.xn, call.w, call.xp, call.pw, call.it0, call.n_alt
    continued = it0 > 0
    cx, cw, doubled = _stack_camera_data(xn, w, xp, pw)
    k = call.alpha0.size
    n_rows = _n_rows(pw)  # the pose step's L1 rows (its multipliers' size)
    length = max(n_alt - it0, 0)
    # the kept alternation (none yet: index -1, the continued run's objective to beat)
    kept = RunOut(_OK, 0, it0, False, -1, call.obj0, np.zeros((length, 3)),
                  np.zeros((length, 4), dtype=np.int64), np.zeros(k), np.zeros(3 * xn.shape[0]),
                  np.zeros((3, 3)), np.zeros(2), 0.0, 0.0, 0.0, 0.0, 0, False, 0, 0, False)
    m0 = np.ascontiguousarray(call.cam0[:, :3])
    t = call.cam0[:, 3].copy()
    ycam = np.empty((cx.shape[0], 3))
    status = _OK
    if not continued:
        c = _camera_for(cx, cw, call.y0, doubled, ycam, m0, t, st, call.camera_max_iter)
        if c.finite:
            m0, t = c.scale * c.rotation[:2], c.translation
        else:
            status = _CAMERA_DIVERGED
    alpha = call.alpha0
    prev = call.obj0
    converged = False
    it = it0
    done = 0
    for it in range(it0 + 1, n_alt + 1 if status == _OK else it0 + 1):
        problem = PoseProblem(xn, w, m0, t, xp, pw, call.rad)
        u = Multipliers(np.zeros(n_rows), np.zeros(k))
        p = _pose_kernel(problem, km, st, call.pose_max_iter, alpha, u)
        if not np.all(np.isfinite(p.alpha)):
            status = _POSE_DIVERGED
            break
        alpha = p.alpha
        c = _camera_for(cx, cw, p.pose, doubled, ycam, m0, t, st, call.camera_max_iter)
        if not c.finite:
            status = _CAMERA_DIVERGED
            break
        m0, t = c.scale * c.rotation[:2], c.translation
        obj = _run_objective(c.objective, alpha, st.th, p.pose, m0, xp, pw)
        kept.objs[done, 0], kept.objs[done, 1], kept.objs[done, 2] = obj, c.objective, p.objective
        kept.counts[done, 0], kept.counts[done, 1] = c.n_iter, c.converged
        kept.counts[done, 2], kept.counts[done, 3] = p.n_iter, p.converged
        done += 1
        if (kept.best_it < 0 and not continued) or obj < kept.best_obj:
            kept = _keep(kept, it, obj, p, c)
        if _alternation_stops(prev, obj, st.alt_tol):
            converged = True
            break
        prev = obj
    b = kept
    return RunOut(status, done, it, converged, b.best_it, b.best_obj, b.objs, b.counts, b.alpha, b.pose,
                  b.rotation, b.translation, b.scale, b.pose_objective, b.limb_violation, b.camera_objective,
                  b.pose_iter, b.pose_converged, b.alpha_iter, b.camera_iter, b.camera_converged)


@njit_nogil
def _run_kernel_many(km: ModelArrays, st: StepSettings, ins: tuple[Any, ...], outs: tuple[Any, ...]) -> None:
    """:func:`_run_kernel` for each of ``B`` runs of one model and settings.

    ``ins``: the operands of :class:`RunCall`, in its order, stacked on a first axis of size ``B``
    (``xn`` (B, 12, 2), ..., ``obj0`` (B,), ``it0``, ``n_alt``, ``pose_max_iter``, ``camera_max_iter``
    (B,) int64). ``outs``, written: ``status`` (B,); ``head`` (B, 4): done, it, converged, best_it;
    ``best_obj`` (B,); ``objs`` (B, L, 3) and ``counts`` (B, L, 4) with ``L`` at least every run's
    ``n_alt - it0`` (the first ``done`` rows used); then ``alpha``, ``pose``, ``rotation``,
    ``translation`` as :class:`RunOut`'s with ``B`` in front, ``floats`` (B, 4) and ``ints`` (B, 5) its
    scalars of the kept steps in :func:`_run_out`'s order. Each run is :func:`_run_kernel`'s on its own
    operands, bit for bit (nothing is shared but ``km`` and ``st``); the kernel releases the GIL, so
    threads may run parts of a batch in parallel."""
    xn, w, xp, pw, rad, alpha0, y0, cam0, obj0, it0, n_alt, pose_max_iter, camera_max_iter = ins
    status, head, best_obj, objs, counts, alpha, pose, rotation, translation, floats, ints = outs
    for b in range(xn.shape[0]):
        o = _run_kernel(RunCall(xn[b], w[b], xp[b], pw[b], rad[b], alpha0[b], y0[b], cam0[b], obj0[b], it0[b],
                                n_alt[b], pose_max_iter[b], camera_max_iter[b]), km, st)
        status[b] = o.status
        head[b, 0], head[b, 1], head[b, 2], head[b, 3] = o.done, o.it, o.converged, o.best_it
        best_obj[b] = o.best_obj
        m = o.objs.shape[0]
        objs[b, :m] = o.objs
        counts[b, :m] = o.counts
        alpha[b] = o.alpha
        pose[b] = o.pose
        rotation[b] = o.rotation
        translation[b] = o.translation
        floats[b, 0], floats[b, 1] = o.scale, o.pose_objective
        floats[b, 2], floats[b, 3] = o.limb_violation, o.camera_objective
        ints[b, 0], ints[b, 1], ints[b, 2] = o.pose_iter, o.pose_converged, o.alpha_iter
        ints[b, 3], ints[b, 4] = o.camera_iter, o.camera_converged


def _stacked(arrays: list[NDArray[Any]], dtype: type) -> NDArray[Any]:
    return np.ascontiguousarray(np.stack(arrays), dtype=dtype)


def run_calls(calls: list[RunCall], km: ModelArrays, st: StepSettings, threads: int = 1
              ) -> list[RunOut | Exception]:
    """Every run of ``calls`` (one model and settings) in one compiled pass,
    :func:`_run_kernel_many`, split into ``threads`` contiguous parts run in parallel (the kernel
    releases the GIL): each run's :class:`RunOut` is the one :func:`_run_kernel` gives it alone,
    whatever the batch and the thread count. A run whose kernel raises (numpy's ``LinAlgError``
    on a diverged matrix) gets its exception in its place; the others their results (the batch
    is then run again one call at a time)."""
    n = len(calls)
    if n == 0:
        return []
    try:
        return list(_run_calls(calls, km, st, threads))
    except Exception:
        pass
    out: list[RunOut | Exception] = []
    for c in calls:
        try:
            o = _run_kernel(c, km, st)
            out.append(o._replace(status=RunStatus(o.status)))
        except Exception as err:
            out.append(err)
    return out


def _run_calls(calls: list[RunCall], km: ModelArrays, st: StepSettings, threads: int) -> list[RunOut]:
    """:func:`run_calls` when no kernel raises."""
    n = len(calls)
    k = calls[0].alpha0.size
    length = max(max(c.n_alt - c.it0 for c in calls), 0)
    xn = _stacked([c.xn for c in calls], np.float64)
    ins: tuple[Any, ...] = (
           xn, _stacked([c.w for c in calls], np.float64),
           _stacked([c.xp for c in calls], np.float64), _stacked([c.pw for c in calls], np.float64),
           _stacked([c.rad for c in calls], np.float64), _stacked([c.alpha0 for c in calls], np.float64),
           _stacked([c.y0 for c in calls], np.float64), _stacked([c.cam0 for c in calls], np.float64),
           np.array([c.obj0 for c in calls], dtype=np.float64),
           np.array([c.it0 for c in calls], dtype=np.int64),
           np.array([c.n_alt for c in calls], dtype=np.int64),
           np.array([c.pose_max_iter for c in calls], dtype=np.int64),
           np.array([c.camera_max_iter for c in calls], dtype=np.int64))
    outs: tuple[NDArray[Any], ...] = (
        np.zeros(n, np.int64), np.zeros((n, 4), np.int64), np.zeros(n), np.zeros((n, length, 3)),
        np.zeros((n, length, 4), np.int64), np.zeros((n, k)), np.zeros((n, xn.shape[1] * 3)),
        np.zeros((n, 3, 3)), np.zeros((n, 2)), np.zeros((n, 4)), np.zeros((n, 5), np.int64))
    parts = min(max(threads, 1), n)
    if parts == 1:
        _run_kernel_many(km, st, ins, outs)
    else:
        edges = [round(i * n / parts) for i in range(parts + 1)]

        def part(i: int) -> None:
            lo, hi = edges[i], edges[i + 1]
            _run_kernel_many(km, st, tuple(a[lo:hi] for a in ins), tuple(a[lo:hi] for a in outs))

        list(thread_pool(parts).map(part, range(parts)))
    status, head, best_obj, objs, counts, alpha, pose, rotation, translation, floats, ints = outs
    out = []
    # the scalars as Python numbers, each array's once
    rows = zip(calls, status.tolist(), head.tolist(), best_obj.tolist(), floats.tolist(), ints.tolist(),
               strict=True)
    for b, (c, code, (done, it, conv, best_it), obj, f, i) in enumerate(rows):
        m = max(c.n_alt - c.it0, 0)
        out.append(RunOut(RunStatus(code), done, it, bool(conv), best_it, obj, objs[b, :m], counts[b, :m],
                          alpha[b], pose[b], rotation[b], translation[b], f[0], f[1], f[2], f[3], i[0],
                          bool(i[1]), i[2], i[3], bool(i[4])))
    return out
