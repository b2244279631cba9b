"""The paper's experiments (Wang et al. 2014, Sec. 4), regenerated from raw CMU mocap.

``pose-lifter experiments --out DIR [--quick]`` writes, for each experiment, a PNG plot, a CSV
(aggregated table), a per-sample CSV (``*_raw.csv``) and a markdown table, plus ``summary.md``
with the headline numbers:

1. ``exp1_bases``: basis learning (Fig. 3): reconstruction error of the unseen test actions vs
   the number of bases for sparse / PCA / class-wise PCA bases learned on the training split,
   and the cumulative distribution of active bases per pose.
2. ``exp2_factors``: the three factors (Fig. 4): cumulative error distribution of the 8 variants.
3. ``exp3_noise``: inaccurate 2D (Fig. 5): error vs Gaussian noise std 0.1..1.0 (right lower
   leg units) for variants and Ramakrishna et al. 2012; ``exp3_robust``: detector-like gross
   outliers and missing joints.
4. ``exp4_angle``: human-camera angle (Fig. 6): error vs yaw 0..180 degrees (body frame).
5. ``exp5_camera``: camera estimation (Fig. 8): ground-truth camera (pose step only) vs the
   estimated camera from the mean-pose start and from 30 cluster starts.

Inputs are clean weak-perspective projections of normalised test poses (right lower leg = 1,
body frame); the camera is ``Rx(180 deg) @ Ry(yaw)``, a proper rotation from the y-up body
frame to the y-down optical frame (never a mirror). Errors: the paper's ``||y - y_hat||_2`` in
right-lower-leg units (:func:`pose_lifter.core.model.metrics.normalised_error`) and P-MPJPE in mm
(each pose's own leg length). Every accuracy table also lists the flat floor (the 2D input with
zero depth) and the mean-pose floor. Lifts run in a ``multiprocessing`` pool (one BLAS thread
per worker: :mod:`pose_lifter.mocap.experiment_tasks`); the tables and plots:
:mod:`pose_lifter.mocap.experiment_output`.
"""

from __future__ import annotations

import json
import os
import platform
import time
import warnings
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pose_lifter.mocap.experiment_output import cell, exp1_output, lift_output
from pose_lifter.mocap.experiment_tasks import (
    VARIANTS,
    BasesTask,
    LiftSolver,
    LiftTask,
    Task,
    WorkerInputs,
    cost,
    run_task,
    start_worker,
)

if TYPE_CHECKING:
    from pose_lifter.core.model.bases import PoseBases

__all__ = ["FULL", "QUICK", "ExperimentConfig", "action_class", "project", "run_experiments"]

_TEST_ACTIONS: tuple[str, ...] = ("walk", "run", "punch")


@dataclass(frozen=True)
class ExperimentConfig:
    """Sample sizes and solver settings of one run.

    Attributes
    ----------
    n_factors, n_noise, n_robust, n_angle, n_camera : int
        Test poses per cell of experiments 2-5.
    factor_variants : tuple of str
        Variants of experiment 2 (all 8 in the full run).
    noise_levels : tuple of float
        Gaussian 2D noise std (right lower leg units), the paper's ten levels.
    noise_variants, robust_variants : tuple of str
        Variants in the noise / outlier experiments (Ramakrishna is always added).
    outlier_counts, missing_counts : tuple of int
        Joints displaced far / set missing in the robustness experiment.
    angles : tuple of float
        Yaw angles (degrees) of experiment 4.
    n_starts, n_refine : int
        Cold multi-start of the lifter (experiment 5 also runs 1 and ``camera_starts``).
    camera_starts : int
        Cluster starts of experiment 5 (paper: 30).
    train_step, test_step : int
        Frame steps of the 120 Hz training / test trials in experiment 1.
    sparse_ks, classwise_per_class : tuple of int
        Basis counts of the sparse curve; components per class of the class-wise PCA curve.
    dl_iter : int
        Dictionary-learning epochs of experiment 1's sparse bases.
    theta_rec : float
        L1 weight of the reconstruction codes (all three basis types).
    seed : int
    """

    n_factors: int = 48
    n_noise: int = 12
    n_robust: int = 12
    n_angle: int = 12
    n_camera: int = 30
    factor_variants: tuple[str, ...] = VARIANTS
    noise_levels: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(1, 11))
    noise_variants: tuple[str, ...] = ("L1WAWS", "L2WAWS", "L2NAWS", "L1NANS", "L2NANS")
    robust_variants: tuple[str, ...] = ("L1WAWS", "L2WAWS", "L1NAWS", "L2NAWS")
    outlier_counts: tuple[int, ...] = (1, 3)
    missing_counts: tuple[int, ...] = (2, 4)
    angles: tuple[float, ...] = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0)
    n_starts: int = 10
    n_refine: int = 3
    camera_starts: int = 30
    train_step: int = 16
    test_step: int = 60
    sparse_ks: tuple[int, ...] = (6, 12, 24, 48, 100, 200)
    classwise_per_class: tuple[int, ...] = (1, 2, 3, 5, 8, 12, 20, 35)
    dl_iter: int = 20
    theta_rec: float = 0.1
    seed: int = 0


FULL = ExperimentConfig()
QUICK = ExperimentConfig(
    n_factors=2, n_noise=1, n_robust=1, n_angle=1, n_camera=1, factor_variants=("L1WAWS", "L2NANS"),
    noise_levels=(0.2, 1.0), noise_variants=("L2NANS",), robust_variants=("L1NAWS",), outlier_counts=(2,),
    missing_counts=(2,), angles=(90.0,), n_starts=2, n_refine=1, camera_starts=3,
    train_step=64, test_step=480, sparse_ks=(6, 24),
    classwise_per_class=(1, 3), dl_iter=2,
)


# --------------------------------------------------------------------------- data


def action_class(description: str) -> str:
    """Action class of a CMU subject-01 playground trial from its description.

    The paper trains on "climb", "swing", "sit" and "jump"; every playground trial climbs,
    so a trial is labelled by the most specific action it contains (swing > sit > jump),
    otherwise climb. Used as the class labels of class-wise PCA.
    """
    d = description.lower()
    for c in ("swing", "sit", "jump"):
        if c in d:
            return c
    return "climb"


def project(pose: NDArray[np.float64], yaw_deg: float) -> NDArray[np.float64]:
    """Weak-perspective image (scale 1) of a body-frame pose seen at ``yaw_deg``.

    Camera rotation ``Rx(180) @ Ry(yaw)``: proper, y-up body frame -> y-down optical frame.

    Parameters
    ----------
    pose : ndarray, shape (12, 3)
    yaw_deg : float

    Returns
    -------
    ndarray, shape (12, 2)
    """
    return np.asarray(pose @ camera_rotation(yaw_deg)[:2].T)


def camera_rotation(yaw_deg: float) -> NDArray[np.float64]:
    """``Rx(180 deg) @ Ry(yaw)``, shape (3, 3), det +1."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_euler("x", 180, degrees=True) * Rotation.from_euler("y", yaw_deg, degrees=True)
    return np.asarray(rot.as_matrix())


@dataclass
class _Data:
    train: NDArray[np.float64]  # (N, 12, 3) normalised
    train_labels: NDArray[Any]
    train_trials: list[str]
    test_rec: NDArray[np.float64]  # (M, 12, 3) normalised, experiment 1
    test_rec_leg_mm: NDArray[np.float64]
    bank: NDArray[np.float64]  # (P, 12, 3) normalised, experiments 2-5
    bank_leg_mm: NDArray[np.float64]
    bank_src: list[str]
    test_trials: list[str] = field(default_factory=list)


def _load_data(data_dir: str | Path | None, cfg: ExperimentConfig, n_bank: int) -> _Data:
    from pose_lifter.core.model.skeleton import limb_lengths, normalise_pose
    from pose_lifter.mocap import cmu as mocap

    d = mocap.resolve_data_dir(data_dir)
    rows = mocap.read_manifest(d)
    train_rows = {t.trial: t for t in rows if t.paper_split == "train"}
    if not train_rows:
        raise mocap.MocapDataError(f"no paper_split=train trials in {d / 'MANIFEST.csv'}")
    train_trials = sorted(train_rows)
    clips = [normalise_pose(mocap.load_trial(t, d, step=cfg.train_step)) for t in train_trials]
    labels = np.concatenate([np.full(len(c), action_class(train_rows[t].description))
                             for c, t in zip(clips, train_trials, strict=True)])
    test_rows = {t.trial: t for t in rows if t.paper_split == "test"}
    test_trials = sorted(test_rows)
    raw = {t: mocap.load_trial(t, d, step=1) for t in test_trials}
    rec = np.concatenate([raw[t][:: cfg.test_step] for t in test_trials])
    # experiments 2-5: poses drawn round-robin over the actions, random trial and frame
    rng = np.random.default_rng(cfg.seed)
    by_action: dict[str, list[str]] = defaultdict(list)
    for t in test_trials:
        by_action[test_rows[t].action].append(t)
    actions = [a for a in _TEST_ACTIONS if by_action.get(a)] or sorted(by_action)
    bank, src = [], []
    for i in range(n_bank):
        trials = by_action[actions[i % len(actions)]]
        t = trials[int(rng.integers(len(trials)))]
        f = int(rng.integers(len(raw[t])))
        bank.append(raw[t][f])
        src.append(f"{t}:{f}")
    bank_a = np.stack(bank)
    return _Data(
        train=np.concatenate(clips), train_labels=labels, train_trials=train_trials,
        test_rec=normalise_pose(rec), test_rec_leg_mm=1000.0 * limb_lengths(rec)[:, 7],
        bank=normalise_pose(bank_a), bank_leg_mm=1000.0 * limb_lengths(bank_a)[:, 7], bank_src=src,
        test_trials=test_trials,
    )


# --------------------------------------------------------------------------- tasks


_Method = tuple[str, LiftSolver, dict[str, Any]]  # row label, solver, the LiftTask fields it sets


def _lift_tasks(data: _Data, cfg: ExperimentConfig,
                mean_pose: NDArray[np.float64]) -> tuple[list[LiftTask], list[dict[str, Any]]]:
    """All lift tasks of experiments 2-5, plus the floor rows (computed here, cheap; the mean-pose
    floor is ``mean_pose``, shape (12, 3))."""
    from pose_lifter.core.errors import InvalidInputError
    from pose_lifter.core.model.metrics import normalised_error, p_mpjpe

    rng = np.random.default_rng(cfg.seed + 1)
    tasks: list[LiftTask] = []
    floors: list[dict[str, Any]] = []

    def add(exp: str, cond: str, level: float, i: int, x: NDArray[np.float64], conf: Any, yaw: float,
            methods: Iterable[_Method]) -> None:
        gt, leg = data.bank[i], float(data.bank_leg_mm[i])
        base = {"exp": exp, "cond": cond, "level": level, "pose": i, "src": data.bank_src[i], "yaw": yaw,
                "gt": gt, "leg_mm": leg}
        for name, solver, extra in methods:
            tasks.append(LiftTask(**base, method=name, solver=solver, x=x, conf=conf, **extra))
        vis = np.ones(12, bool) if conf is None else np.asarray(conf) > 0
        flat = np.c_[np.where(vis[:, None], x, x[vis].mean(0)), np.zeros(12)]
        for name, pred in (("flat floor", flat), ("mean-pose floor", mean_pose)):
            try:
                err, failed = float(normalised_error(pred, gt)), ""
            except InvalidInputError:  # both right-leg joints missing: the flat floor has no leg
                err, failed = float("nan"), "degenerate right lower leg"
            floors.append({**{k: v for k, v in base.items() if k != "gt"}, "kind": "floor", "method": name,
                           "err": err, "pmpjpe_mm": float(leg * p_mpjpe(pred, gt)),
                           "failed": failed, "time_s": 0.0})

    def ours(variants: Iterable[str]) -> list[_Method]:
        return [(v, LiftSolver.LIFTER, {"variant": v, "starts": cfg.n_starts, "refine": cfg.n_refine})
                for v in variants]

    rama: list[_Method] = [("Ramakrishna", LiftSolver.RAMAKRISHNA, {})]
    yaws = rng.uniform(0.0, 360.0, size=len(data.bank))
    # 2. three factors
    for i in range(cfg.n_factors):
        x = project(data.bank[i], yaws[i])
        add("exp2_factors", "clean", 0.0, i, x, None, yaws[i], ours(cfg.factor_variants))
    # 3. noise
    for i in range(cfg.n_noise):
        x0 = project(data.bank[i], yaws[i])
        for s in cfg.noise_levels:
            x = x0 + rng.normal(0.0, s, size=x0.shape)
            add("exp3_noise", "gaussian", s, i, x, None, yaws[i], ours(cfg.noise_variants) + rama)
    # 3b. outliers and missing joints
    for i in range(cfg.n_robust):
        x0 = project(data.bank[i], yaws[i])
        conds: list[tuple[str, int]] = [("clean", 0)]
        conds += [("outliers", n) for n in cfg.outlier_counts] + [("missing", n) for n in cfg.missing_counts]
        for cond, n in conds:
            x, conf = x0.copy(), np.ones(12)
            idx = rng.choice(12, size=n, replace=False)
            if cond == "outliers":  # confidently wrong: 1.5..3 leg lengths away
                ang = rng.uniform(0, 2 * np.pi, n)
                x[idx] += rng.uniform(1.5, 3.0, n)[:, None] * np.c_[np.cos(ang), np.sin(ang)]
            elif cond == "missing":
                conf[idx] = 0.0
                x[idx] = 0.0
            add("exp3_robust", cond, float(n), i, x, conf, yaws[i], ours(cfg.robust_variants) + rama)
    # 4. human-camera angle
    for i in range(cfg.n_angle):
        for a in cfg.angles:
            add("exp4_angle", "clean", a, i, project(data.bank[i], a), None, a, ours(["L1WAWS"]) + rama)
    # 5. camera estimation
    for i in range(cfg.n_camera):
        rot = camera_rotation(yaws[i])
        add("exp5_camera", "clean", 0.0, i, project(data.bank[i], yaws[i]), None, yaws[i], [
            ("GT camera, mean-pose start", LiftSolver.GT_CAMERA, {"starts": 1, "rotation": rot}),
            ("estimated, mean-pose start", LiftSolver.LIFTER,
             {"variant": "L1WAWS", "starts": 1, "refine": 1}),
            (f"estimated, {cfg.camera_starts} cluster starts", LiftSolver.LIFTER,
             {"variant": "L1WAWS", "starts": cfg.camera_starts, "refine": cfg.n_refine}),
        ])
    return tasks, floors


def _bases_tasks(cfg: ExperimentConfig, n_classes: int) -> list[BasesTask]:
    """The tasks of experiment 1: the sparse, PCA and class-wise PCA curves."""
    tasks = [BasesTask("sparse", k, cfg.theta_rec, dl_iter=cfg.dl_iter, seed=cfg.seed) for k in cfg.sparse_ks]
    tasks += [BasesTask("PCA", k, cfg.theta_rec)
              for k in sorted({min(k, 36) for k in (1, 2, 3, 4, 6, 9, 12, 18, 24, 30, 36)})]
    tasks += [BasesTask("class-wise PCA", n_classes * (n + 1), cfg.theta_rec, per_class=n)
              for n in cfg.classwise_per_class]
    return tasks


# --------------------------------------------------------------------------- main


def _run_tasks(tasks: list[Task], inputs: WorkerInputs, processes: int) -> list[dict[str, Any]]:
    """Every task's result row, in ``processes`` worker processes (fork on Linux), the costliest
    first."""
    from tqdm import tqdm

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    ctx = get_context("fork" if platform.system() == "Linux" else "spawn")
    with ctx.Pool(max(1, processes), initializer=start_worker, initargs=(inputs,)) as pool:
        return list(tqdm(pool.imap_unordered(run_task, tasks), total=len(tasks), desc="experiments",
                         mininterval=5))


def _headline_rows(cfg: ExperimentConfig, agg2: list[dict[str, Any]], agg3: list[dict[str, Any]],
                   agg3b: list[dict[str, Any]], agg4: list[dict[str, Any]]) -> list[str]:
    """The summary's headline table (markdown rows): each method's error in experiments 2-4 at
    their extreme settings."""

    def c(agg: list[dict[str, Any]], m: str, col: str = "err_mean", **w: Any) -> str:
        v = cell(agg, m, col, **w)
        return "nan" if not np.isfinite(v) else f"{v:.3f}" if col.startswith("err") else f"{v:.0f}"

    hi, lo = max(cfg.noise_levels), min(cfg.noise_levels)
    head = ["| experiment | setting | " + " | ".join(["L1WAWS (ours)", "L2WAWS", "L1NANS", "L2NANS",
                                                      "Ramakrishna", "flat floor", "mean-pose floor"]) + " |",
            "|---|---|" + "---|" * 7]
    ms = ["L1WAWS", "L2WAWS", "L1NANS", "L2NANS", "Ramakrishna", "flat floor", "mean-pose floor"]
    head.append(f"| 2 factors (n={cfg.n_factors}) | clean, error (leg) | "
                + " | ".join(c(agg2, m) for m in ms) + " |")
    head.append(f"| 2 factors (n={cfg.n_factors}) | clean, P-MPJPE mm | "
                + " | ".join(c(agg2, m, "pmpjpe_mean") for m in ms) + " |")
    for lev in (lo, hi):
        head.append(f"| 3 noise (n={cfg.n_noise}) | std {lev:g}, error (leg) | "
                    + " | ".join(c(agg3, m, level=lev) for m in ms) + " |")
    for cond, n in (("outliers", max(cfg.outlier_counts)), ("missing", max(cfg.missing_counts))):
        head.append(f"| 3b robust (n={cfg.n_robust}) | {n} {cond}, error (leg) | "
                    + " | ".join(c(agg3b, m, cond=cond, level=float(n)) for m in ms) + " |")
    for a in (cfg.angles[0], cfg.angles[len(cfg.angles) // 2]):
        head.append(f"| 4 angle (n={cfg.n_angle}) | yaw {a:g}, error (leg) | "
                    + " | ".join(c(agg4, m, level=a) for m in ms) + " |")
    return head


def _lift_sections(out: Path, by_exp: dict[str, list[dict[str, Any]]], cfg: ExperimentConfig, solver: str,
                   n_bases: int) -> tuple[tuple[str, ...], tuple[list[dict[str, Any]], ...]]:
    """Experiments 2-5 written out (:func:`lift_output`): their markdown sections and aggregated
    rows, in order."""
    poses = "poses drawn round-robin from the unseen test actions (walk, run, punch), random trial and frame"
    md2, agg2 = lift_output(
        out, "exp2_factors", by_exp["exp2_factors"], ["method"], "2. Three factors (Fig. 4): clean 2D",
        f"{cfg.n_factors} {poses}, each at a random yaw; {solver}")
    md3, agg3 = lift_output(
        out, "exp3_noise", by_exp["exp3_noise"], ["level", "method"],
        "3. Inaccurate 2D (Fig. 5): Gaussian noise",
        f"{cfg.n_noise} poses x {len(cfg.noise_levels)} noise levels (std in right-lower-leg "
        f"units, same noise "
        f"for every method); {solver}")
    md3b, agg3b = lift_output(
        out, "exp3_robust", by_exp["exp3_robust"], ["cond", "level", "method"],
        "3b. Detector-like errors: gross outliers and missing joints",
        f"{cfg.n_robust} poses; 'outliers': that many joints displaced 1.5-3 leg lengths in a "
        f"random direction "
        f"(confidence kept at 1); 'missing': that many joints with confidence 0. {solver}")
    md4, agg4 = lift_output(
        out, "exp4_angle", by_exp["exp4_angle"], ["level", "method"], "4. Human-camera angle (Fig. 6)",
        f"{cfg.n_angle} poses x {len(cfg.angles)} yaw angles (level = yaw in degrees, "
        f"body frame: 0 = frontal, "
        f"90 = profile); {solver}")
    md5, agg5 = lift_output(
        out, "exp5_camera", by_exp["exp5_camera"], ["method"], "5. Camera estimation (Fig. 8)",
        f"{cfg.n_camera} poses at random yaw. GT camera: the pose step alone "
        f"(core.solve.pose_step.pose_step, {n_bases} bases, L1WAWS, mean-pose start, "
        f"up to 100 ADM iterations) with the true camera; "
        f"estimated: the full alternation (L1WAWS, screened to {cfg.n_refine} starts).")

    return (md2, md3, md3b, md4, md5), (agg2, agg3, agg3b, agg4, agg5)


@dataclass(frozen=True)
class _Run:
    """What :func:`run_experiments` computed, before it writes anything.

    Attributes
    ----------
    data : _Data
    sparse : PoseBases
        The lifter's (the packaged sparse bases).
    classwise : PoseBases
        Ramakrishna's: class-wise PCA bases learned on ``data.train``.
    n_classes : int
        Action classes of the training poses.
    n_tasks : int
    by_exp : dict of str to list of dict
        The result rows and floor rows of each experiment.
    failures : int
        Failed solves among the result rows.
    seconds : float
        Run time from loading the data to the last result.
    """

    data: _Data
    sparse: PoseBases
    classwise: PoseBases
    n_classes: int
    n_tasks: int
    by_exp: dict[str, list[dict[str, Any]]]
    failures: int
    seconds: float


def _run(data_dir: str | Path | None, cfg: ExperimentConfig, processes: int) -> _Run:
    """Load the data, learn Ramakrishna's bases and run every task of the five experiments in
    ``processes`` worker processes."""
    from pose_lifter.core import PoseBases
    from pose_lifter.core.model.bases import learn_classwise_pca_bases

    t_start = time.perf_counter()
    n_bank = max(cfg.n_factors, cfg.n_noise, cfg.n_robust, cfg.n_angle, cfg.n_camera)
    data = _load_data(data_dir, cfg, n_bank)
    sparse = PoseBases.load()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Objective did not converge")
        classwise = learn_classwise_pca_bases(data.train, data.train_labels, n_per_class=8, n_starts=1)
    lift_tasks, floors = _lift_tasks(data, cfg, sparse.mean_pose)
    n_cls = len(np.unique(data.train_labels))
    tasks: list[Task] = sorted([*_bases_tasks(cfg, n_cls), *lift_tasks], key=cost, reverse=True)
    inputs = WorkerInputs(sparse, classwise, data.train, data.train_labels, data.test_rec,
                          data.test_rec_leg_mm)
    results = _run_tasks(tasks, inputs, processes)
    t_run = time.perf_counter() - t_start

    by_exp: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in results + floors:
        by_exp[r["exp"]].append(r)
    failures = sum(1 for r in results if r["failed"])
    return _Run(data, sparse, classwise, n_cls, len(tasks), by_exp, failures, t_run)


def _summary(cfg: ExperimentConfig, run: _Run, command: str, processes: int, headline: str,
             sections: list[str]) -> str:
    """``summary.md``: the run, the best basis of each kind, the ``headline`` table and the
    experiments' markdown ``sections``."""
    sparse_rows = [r for r in run.by_exp["exp1_bases"] if not r["failed"]]
    best = {m: min((r for r in sparse_rows if r["method"] == m), key=lambda r: r["err"], default=None)
            for m in ("sparse", "PCA", "class-wise PCA")}
    b1 = "; ".join(f"{m} {r['err']:.3f} at k={r['k']} ({r['active_mean']:.1f} active)"
                   for m, r in best.items() if r is not None)
    return (
        "# The paper's experiments on CMU mocap (Wang et al. 2014, Sec. 4)\n\n"
        f"Command: `{command or 'pose-lifter experiments'}`"
        f"{' (QUICK: tiny sample sizes)' if cfg is QUICK else ''}. "
        f"Runtime {run.seconds:.0f} s with {processes} worker processes; {run.n_tasks} tasks, "
        f"{run.failures} failed solves "
        "(counted in the tables' `failed` column, excluded from the means).\n\n"
        "Errors: the paper's ||y - y_hat||_2 (36-vector, right lower leg = 1, rotation-aligned) and "
        "P-MPJPE in mm "
        "(similarity-aligned). Training: CMU subject 01 playground trials ("
        f"{', '.join(run.data.train_trials)}); testing: unseen walk/run/punch trials. Clean "
        "weak-perspective 2D unless stated.\n\n## Headline\n\n"
        f"Basis learning (lowest reconstruction error per method): {b1}.\n\n"
        + headline + "\n\n"
        + "\n".join(sections)
        + "\n## Configuration\n\n```json\n" + json.dumps(asdict(cfg), indent=1) + "\n```\n"
    )


def run_experiments(data_dir: str | Path | None = None, out_dir: str | Path = "out/experiments",
                    quick: bool = False, processes: int = 2, command: str = "",
                    config: ExperimentConfig | None = None) -> Path:
    """Run all five experiments and write their outputs to ``out_dir``.

    Parameters
    ----------
    data_dir : path, optional
        CMU data (default ``../shared/data/cmu`` or ``$POSE_LIFTER_CMU_DATA``).
    out_dir : path
    quick : bool
        The tiny :data:`QUICK` configuration (tests) instead of :data:`FULL`.
    processes : int
        Worker processes.
    command : str
        The command line, recorded in ``summary.md``.
    config : ExperimentConfig, optional
        Overrides ``quick``.

    Returns
    -------
    Path
        ``out_dir / "summary.md"``.
    """
    cfg = config or (QUICK if quick else FULL)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = _run(data_dir, cfg, processes)
    ns, nr = cfg.n_starts, cfg.n_refine
    solver = (f"lifter: packaged sparse bases (k={run.sparse.n_bases}), {ns} cold k-means starts screened "
              f"to {nr}; "
              f"Ramakrishna et al. 2012: class-wise PCA bases ({run.classwise.n_bases} = "
              f"{run.n_classes} classes x (1 offset + 8 components)) on the same training data.")
    n_test, n_train = len(run.data.test_rec), len(run.data.train)
    md1 = exp1_output(out, run.by_exp["exp1_bases"], n_test, (
        f"Bases learned on {n_train} training poses (paper split, every {cfg.train_step}th frame); "
        f"reconstruction of {n_test} unseen test poses (every {cfg.test_step}th frame of the test trials) "
        f"by L1-regularised least squares (theta = {cfg.theta_rec}). Error = mean ||y - y_hat||_2 over "
        f"the 36-vector in right-lower-leg units; MPJPE in mm (no alignment). Sparse bases: "
        f"{cfg.dl_iter} dictionary-learning epochs."))
    (md2, md3, md3b, md4, md5), (agg2, agg3, agg3b, agg4, agg5) = _lift_sections(
        out, run.by_exp, cfg, solver, run.sparse.n_bases)
    head = _headline_rows(cfg, agg2, agg3, agg3b, agg4)
    cam = [f"\n\nCamera estimation (n={cfg.n_camera}), mean error (leg) / P-MPJPE mm: "
           + "; ".join(f"{r['method']}: {r['err_mean']:.3f} / {r['pmpjpe_mean']:.0f}" for r in agg5) + "."]
    summary = _summary(cfg, run, command, processes, "\n".join(head) + "".join(cam),
                       [md1, md2, md3, md3b, md4, md5])
    path = out / "summary.md"
    path.write_text(summary)
    print(f"experiments: {run.n_tasks} tasks ({run.failures} failed) in {run.seconds:.0f} s -> {out}")
    return path
