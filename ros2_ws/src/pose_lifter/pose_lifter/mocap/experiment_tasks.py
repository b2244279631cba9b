"""The units of work of the paper's experiments (:mod:`pose_lifter.mocap.experiments`) and the pool
worker that runs them.

A task is a :class:`LiftTask` (one 2D input, one method: the lifter in a variant, the lifter's
pose step with the true camera, or Ramakrishna et al. 2012) or a :class:`BasesTask` (learn one
set of bases, reconstruct the unseen test poses). Each worker process gets what every task needs
once, a :class:`WorkerInputs` handed to the pool initialiser, and keeps it with its lifters in a
:class:`Worker`; a task's result is a row (a dict of the task's scalars and its errors) for the
tables.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["VARIANTS", "BasesTask", "LiftSolver", "LiftTask", "Task", "Worker", "WorkerInputs", "cost",
           "run_task", "start_worker"]

VARIANTS: tuple[str, ...] = ("L1WAWS", "L1WANS", "L1NAWS", "L1NANS", "L2WAWS", "L2WANS", "L2NAWS", "L2NANS")


class LiftSolver(Enum):
    """What solves a :class:`LiftTask`."""

    LIFTER = "lifter"  # the full alternation, in ``variant`` with ``starts`` / ``refine``
    GT_CAMERA = "pose step with the true camera"  # ``starts`` starts, camera ``rotation``
    RAMAKRISHNA = "Ramakrishna et al. 2012"  # class-wise PCA bases


@dataclass(frozen=True)
class LiftTask:
    """Lift one 2D input with one method and score it against the ground truth.

    Attributes
    ----------
    exp, cond : str
        Experiment (``"exp2_factors"``, ...) and condition (``"clean"``, ``"outliers"``, ...).
    level : float
        The condition's level (noise std, outlier count, yaw).
    pose : int
        Index in the pose bank; ``src`` its ``"trial:frame"``.
    src : str
    yaw : float
        Yaw of the view (degrees).
    method : str
        Row label (a variant, ``"Ramakrishna"``, ``"GT camera, ..."``).
    solver : LiftSolver
    x : ndarray, shape (12, 2)
    conf : ndarray, shape (12,), or None
    gt : ndarray, shape (12, 3)
        Normalised ground-truth pose; ``leg_mm`` its right lower leg in mm.
    leg_mm : float
    variant : str
        Lifter variant (``LIFTER``).
    starts, refine : int
        Cold starts and refined starts (``LIFTER``); starts of the pose step (``GT_CAMERA``).
    rotation : ndarray, shape (3, 3), or None
        True camera rotation (``GT_CAMERA``).
    """

    exp: str
    cond: str
    level: float
    pose: int
    src: str
    yaw: float
    method: str
    solver: LiftSolver
    x: NDArray[np.float64]
    conf: NDArray[np.float64] | None
    gt: NDArray[np.float64]
    leg_mm: float
    variant: str = ""
    starts: int = 1
    refine: int = 1
    rotation: NDArray[np.float64] | None = None

    def row(self) -> dict[str, Any]:
        """The task's scalars, the start of its result row."""
        return {"exp": self.exp, "cond": self.cond, "level": self.level, "pose": self.pose, "src": self.src,
                "yaw": self.yaw, "leg_mm": self.leg_mm, "kind": "lift", "method": self.method,
                "variant": self.variant, "starts": self.starts, "refine": self.refine}


@dataclass(frozen=True)
class BasesTask:
    """Learn one set of bases on the training poses and reconstruct the unseen test poses.

    Attributes
    ----------
    method : str
        ``"sparse"``, ``"PCA"`` or ``"class-wise PCA"``.
    k : int
        Bases (sparse, PCA components) or the expected count (class-wise: classes x (per_class+1)).
    theta : float
        L1 weight of the reconstruction codes.
    dl_iter, seed : int
        Dictionary-learning epochs and seed (sparse).
    per_class : int
        Components per class (class-wise PCA).
    """

    method: str
    k: int
    theta: float
    dl_iter: int = 0
    seed: int = 0
    per_class: int = 0
    exp: str = "exp1_bases"

    def row(self) -> dict[str, Any]:
        """The task's scalars, the start of its result row."""
        return {"kind": "bases", "exp": self.exp, "method": self.method, "k": self.k, "theta": self.theta}


Task = LiftTask | BasesTask


def cost(task: Task) -> float:
    """Rough relative cost, to start the slowest tasks first."""
    if isinstance(task, BasesTask):
        return 10.0 + float(task.k) / 20.0
    if task.solver is not LiftSolver.LIFTER:
        return 0.5
    limbs = task.variant[2:4] == "WA"
    return float(task.starts) * (0.3 if limbs else 0.05)


@dataclass(frozen=True)
class WorkerInputs:
    """What every task needs, handed once to each pool worker.

    Attributes
    ----------
    sparse : PoseBases
        The packaged sparse bases (the lifter's).
    classwise : PoseBases
        Class-wise PCA bases (Ramakrishna et al.).
    train : ndarray, shape (N, 12, 3)
        Normalised training poses; ``labels`` their action classes, shape (N,).
    labels : ndarray
    test_rec : ndarray, shape (M, 12, 3)
        Normalised unseen test poses of experiment 1; ``leg_mm`` their right lower legs, shape (M,).
    leg_mm : ndarray
    """

    sparse: Any
    classwise: Any
    train: NDArray[np.float64]
    labels: NDArray[Any]
    test_rec: NDArray[np.float64]
    leg_mm: NDArray[np.float64]


@dataclass
class Worker:
    """A worker process's inputs and the lifters it built (one per variant and start counts)."""

    inputs: WorkerInputs
    lifters: dict[tuple[str, int, int], Any] = field(default_factory=dict)
    blas_limit: Any = None  # threadpoolctl's limit, kept for the worker's lifetime

    def lifter(self, variant: str, n_starts: int, n_refine: int) -> Any:
        """The paper-mode lifter of ``variant`` with these starts (built once)."""
        from pose_lifter.core import Lifter, LifterOptions

        key = (variant, n_starts, n_refine)
        if key not in self.lifters:
            opts = LifterOptions(mode="paper", variant=variant, n_starts=n_starts, n_refine=n_refine)
            self.lifters[key] = Lifter(self.inputs.sparse, opts)
        return self.lifters[key]

    def run(self, task: Task) -> dict[str, Any]:
        """Run one task; its result row (never raises: a failure is the row's ``failed`` text)."""
        t0 = time.perf_counter()
        out = task.row()
        try:
            if isinstance(task, BasesTask):
                out.update(self._bases(task))
            else:
                pred = self._lift(task)
                out["err"], out["pmpjpe_mm"] = _errors(pred, task.gt, task.leg_mm)
            out["failed"] = ""
        except Exception as exc:
            out.update(err=float("nan"), pmpjpe_mm=float("nan"), failed=f"{type(exc).__name__}: {exc}")
        out["time_s"] = time.perf_counter() - t0
        return out

    def _lift(self, task: LiftTask) -> NDArray[np.float64]:
        x, conf = task.x, task.conf
        if task.solver is LiftSolver.RAMAKRISHNA:
            from pose_lifter.core.baselines.ramakrishna import ramakrishna_lift

            return np.asarray(ramakrishna_lift(x, conf, self.inputs.classwise).pose)
        if task.solver is LiftSolver.GT_CAMERA:
            from pose_lifter.core.solve.pose_step import pose_step

            assert task.rotation is not None
            lf = self.lifter("L1WAWS", 1, 1)
            o = lf.options.replace(variant="L1WAWS")
            best = None
            for alpha0 in self.inputs.sparse.with_starts(task.starts):
                res = pose_step(x, task.rotation[:2], np.zeros(2), np.ones(12), lf.model, alpha0, o,
                                max_iter=5 * o.pose_max_iter)
                if best is None or res.objective < best.objective:
                    best = res
            assert best is not None
            return np.asarray(best.pose)
        lf = self.lifter(task.variant, task.starts, task.refine)
        return np.asarray(lf.lift(x, conf).pose)

    def _bases(self, task: BasesTask) -> dict[str, Any]:
        from pose_lifter.core.model.bases import (
            learn_classwise_pca_bases,
            learn_pca_bases,
            learn_sparse_bases,
            sparse_codes,
        )

        train, y = self.inputs.train, self.inputs.test_rec
        k = int(task.k)
        if task.method == "sparse":
            b = learn_sparse_bases(train, n_bases=k, n_iter=task.dl_iter, n_starts=1, seed=task.seed)
            mean, comps = b.mean, b.components
        elif task.method == "PCA":
            b = learn_pca_bases(train, n_bases=36, n_starts=1)
            mean, comps = b.mean, b.components[:, :k]
        else:
            b = learn_classwise_pca_bases(train, self.inputs.labels, n_per_class=task.per_class, n_starts=1)
            mean, comps = b.mean, b.components
        alpha = sparse_codes(y, mean, comps, task.theta)
        rec = (mean + alpha @ comps.T).reshape(-1, 12, 3)
        err = np.linalg.norm((rec - y).reshape(len(y), -1), axis=1)
        mm = self.inputs.leg_mm * np.linalg.norm(rec - y, axis=2).mean(axis=1)
        active = np.count_nonzero(np.abs(alpha) > 1e-8, axis=1)
        return {"k": int(comps.shape[1]), "err": float(err.mean()), "err_median": float(np.median(err)),
                "mpjpe_mm": float(mm.mean()), "active_mean": float(active.mean()),
                "active": active.tolist(), "pmpjpe_mm": float("nan")}


def _errors(pred: NDArray[np.float64], gt: NDArray[np.float64], leg_mm: float) -> tuple[float, float]:
    from pose_lifter.core.model.metrics import normalised_error, p_mpjpe

    return float(normalised_error(pred, gt)), float(leg_mm * p_mpjpe(pred, gt))


#: The Worker of this worker process (set by :func:`start_worker`; None in the parent): the pool
#: calls a plain function per task, which finds the worker's state here.
_worker: Worker | None = None


def start_worker(inputs: WorkerInputs) -> None:
    """Pool initialiser: one BLAS thread, the worker's inputs kept for its lifetime."""
    from threadpoolctl import threadpool_limits

    global _worker
    _worker = Worker(inputs, blas_limit=threadpool_limits(limits=1))
    warnings.filterwarnings("ignore", message="Objective did not converge")


def run_task(task: Task) -> dict[str, Any]:
    """Run ``task`` in this worker process (see :func:`start_worker`)."""
    assert _worker is not None, "called outside a worker of run_experiments"
    return _worker.run(task)
