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
right-lower-leg units (:func:`pose_lifter.core.metrics.normalised_error`) and P-MPJPE in mm
(each pose's own leg length). Every accuracy table also lists the flat floor (the 2D input with
zero depth) and the mean-pose floor. Lifts run in a ``multiprocessing`` pool (one BLAS thread
per worker).
"""

from __future__ import annotations

import csv
import json
import os
import platform
import time
import warnings
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["FULL", "QUICK", "ExperimentConfig", "action_class", "project", "run_experiments"]

_VARIANTS: tuple[str, ...] = ("L1WAWS", "L1WANS", "L1NAWS", "L1NANS", "L2WAWS", "L2WANS", "L2NAWS", "L2NANS")
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
    factor_variants: tuple[str, ...] = _VARIANTS
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
    from pose_lifter.core.skeleton import limb_lengths, normalise_pose
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


# --------------------------------------------------------------------------- workers

_W: dict[str, Any] = {}


def _init_worker(sparse: Any, classwise: Any, train: NDArray[np.float64], labels: NDArray[Any],
                 test_rec: NDArray[np.float64], leg_mm: NDArray[np.float64]) -> None:
    from threadpoolctl import threadpool_limits

    _W["limits"] = threadpool_limits(limits=1)  # kept alive for the worker's lifetime
    _W.update(sparse=sparse, classwise=classwise, train=train, labels=labels, test_rec=test_rec,
              leg_mm=leg_mm, lifters={})
    warnings.filterwarnings("ignore", message="Objective did not converge")


def _lifter(variant: str, n_starts: int, n_refine: int) -> Any:
    from pose_lifter.core import Lifter, LifterOptions

    key = (variant, n_starts, n_refine)
    if key not in _W["lifters"]:
        opts = LifterOptions(mode="paper", variant=variant, n_starts=n_starts, n_refine=n_refine)
        _W["lifters"][key] = Lifter(_W["sparse"], opts)
    return _W["lifters"][key]


def _errors(pred: NDArray[np.float64], gt: NDArray[np.float64], leg_mm: float) -> tuple[float, float]:
    from pose_lifter.core.metrics import normalised_error, p_mpjpe

    return float(normalised_error(pred, gt)), float(leg_mm * p_mpjpe(pred, gt))


def _task(task: dict[str, Any]) -> dict[str, Any]:
    """Run one unit of work in a worker; returns a result row (never raises)."""
    t0 = time.perf_counter()
    out = {k: v for k, v in task.items() if k not in ("x", "conf", "gt", "rotation")}
    try:
        if task["kind"] == "bases":
            out.update(_bases_task(task))
        else:
            pred = _lift_task(task)
            out["err"], out["pmpjpe_mm"] = _errors(pred, task["gt"], task["leg_mm"])
        out["failed"] = ""
    except Exception as exc:
        out.update(err=float("nan"), pmpjpe_mm=float("nan"), failed=f"{type(exc).__name__}: {exc}")
    out["time_s"] = time.perf_counter() - t0
    return out


def _lift_task(task: dict[str, Any]) -> NDArray[np.float64]:
    method = task["method"]
    x, conf = task["x"], task.get("conf")
    if method == "Ramakrishna":
        from pose_lifter.core.baselines.ramakrishna import ramakrishna_lift

        return np.asarray(ramakrishna_lift(x, conf, _W["classwise"]).pose)
    if method.startswith("GT camera"):
        from pose_lifter.core.pose_step import pose_step

        lf = _lifter("L1WAWS", 1, 1)
        o = lf.options.replace(variant="L1WAWS")
        best = None
        for alpha0 in _W["sparse"].with_starts(task["starts"]):
            res = pose_step(x, task["rotation"][:2], np.zeros(2), np.ones(12), lf.model, alpha0, o,
                            max_iter=5 * o.pose_max_iter)
            if best is None or res.objective < best.objective:
                best = res
        assert best is not None
        return np.asarray(best.pose)
    lf = _lifter(task["variant"], task["starts"], task["refine"])
    return np.asarray(lf.lift(x, conf).pose)


def _bases_task(task: dict[str, Any]) -> dict[str, Any]:
    from pose_lifter.core.bases import (
        learn_classwise_pca_bases,
        learn_pca_bases,
        learn_sparse_bases,
        sparse_codes,
    )

    train, y = _W["train"], _W["test_rec"]
    method, k = task["method"], int(task["k"])
    if method == "sparse":
        b = learn_sparse_bases(train, n_bases=k, n_iter=task["dl_iter"], n_starts=1, seed=task["seed"])
        mean, comps = b.mean, b.components
    elif method == "PCA":
        b = learn_pca_bases(train, n_bases=36, n_starts=1)
        mean, comps = b.mean, b.components[:, :k]
    else:
        b = learn_classwise_pca_bases(train, _W["labels"], n_per_class=task["per_class"], n_starts=1)
        mean, comps = b.mean, b.components
    alpha = sparse_codes(y, mean, comps, task["theta"])
    rec = (mean + alpha @ comps.T).reshape(-1, 12, 3)
    err = np.linalg.norm((rec - y).reshape(len(y), -1), axis=1)
    mm = _W["leg_mm"] * np.linalg.norm(rec - y, axis=2).mean(axis=1)
    active = np.count_nonzero(np.abs(alpha) > 1e-8, axis=1)
    return {"k": int(comps.shape[1]), "err": float(err.mean()), "err_median": float(np.median(err)),
            "mpjpe_mm": float(mm.mean()), "active_mean": float(active.mean()),
            "active": active.tolist(), "pmpjpe_mm": float("nan")}


# --------------------------------------------------------------------------- tasks


def _lift_tasks(data: _Data, cfg: ExperimentConfig) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """All lift tasks of experiments 2-5, plus the floor rows (computed here, cheap)."""
    from pose_lifter.core.errors import InvalidInputError
    from pose_lifter.core.metrics import normalised_error, p_mpjpe

    rng = np.random.default_rng(cfg.seed + 1)
    mean_pose = _W_main["sparse"].mean_pose
    tasks: list[dict[str, Any]] = []
    floors: list[dict[str, Any]] = []

    def add(exp: str, cond: str, level: float, i: int, x: NDArray[np.float64], conf: Any, yaw: float,
            methods: Iterable[tuple[str, dict[str, Any]]]) -> None:
        gt, leg = data.bank[i], float(data.bank_leg_mm[i])
        base = {"exp": exp, "cond": cond, "level": level, "pose": i, "src": data.bank_src[i], "yaw": yaw,
                "gt": gt, "leg_mm": leg}
        for name, extra in methods:
            tasks.append({**base, "kind": "lift", "method": name, "x": x, "conf": conf, **extra})
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

    def ours(variants: Iterable[str]) -> list[tuple[str, dict[str, Any]]]:
        return [(v, {"variant": v, "starts": cfg.n_starts, "refine": cfg.n_refine}) for v in variants]

    rama: list[tuple[str, dict[str, Any]]] = [("Ramakrishna", {})]
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
            ("GT camera, mean-pose start", {"starts": 1, "rotation": rot}),
            ("estimated, mean-pose start", {"variant": "L1WAWS", "starts": 1, "refine": 1}),
            (f"estimated, {cfg.camera_starts} cluster starts",
             {"variant": "L1WAWS", "starts": cfg.camera_starts, "refine": cfg.n_refine}),
        ])
    return tasks, floors


_W_main: dict[str, Any] = {}


def _cost(task: dict[str, Any]) -> float:
    """Rough relative cost, to start the slowest tasks first."""
    if task["kind"] == "bases":
        return 10.0 + float(task["k"]) / 20.0
    if task["method"] == "Ramakrishna" or task["method"].startswith("GT"):
        return 0.5
    limbs = task["variant"][2:4] == "WA"
    return float(task["starts"]) * (0.3 if limbs else 0.05)


# --------------------------------------------------------------------------- output


def _write_csv(path: Path, rows: Sequence[dict[str, Any]], cols: Sequence[str]) -> None:
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(cols), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: (f"{r[c]:.4f}" if isinstance(r.get(c), float) else r.get(c, "")) for c in cols})


def _md_table(rows: Sequence[dict[str, Any]], cols: Sequence[str], heads: Sequence[str] | None = None) -> str:
    heads = list(heads or cols)

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return "nan" if not np.isfinite(v) else (f"{v:.1f}" if abs(v) >= 10 else f"{v:.3f}")
        return str(v)

    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _aggregate(rows: Sequence[dict[str, Any]], keys: Sequence[str]) -> list[dict[str, Any]]:
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[tuple(r[k] for k in keys)].append(r)
    out = []
    for key, rs in groups.items():
        e = np.array([r["err"] for r in rs], float)
        m = np.array([r["pmpjpe_mm"] for r in rs], float)
        ok = np.isfinite(e)
        out.append({**dict(zip(keys, key, strict=True)), "n": int(ok.sum()), "failed": int((~ok).sum()),
                    "err_mean": float(e[ok].mean()) if ok.any() else float("nan"),
                    "err_median": float(np.median(e[ok])) if ok.any() else float("nan"),
                    "pmpjpe_mean": float(m[ok].mean()) if ok.any() else float("nan"),
                    "pmpjpe_median": float(np.median(m[ok])) if ok.any() else float("nan"),
                    "time_s": float(np.mean([r["time_s"] for r in rs]))})
    return out


# Curves over a condition show mean P-MPJPE: the leg-unit error rescales each estimate by its own
# right lower leg, so one short-legged estimate can dominate a mean over few poses (see tables).
_MM_LABEL = "mean P-MPJPE (mm, similarity-aligned)"


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _method_order(names: Iterable[str]) -> list[str]:
    order = [*_VARIANTS, "Ramakrishna", "flat floor", "mean-pose floor"]
    names = set(names)
    return [n for n in order if n in names] + sorted(n for n in names if n not in order)


def _style(name: str) -> dict[str, Any]:
    if name.endswith("floor"):
        return {"color": "0.6", "ls": ":" if name.startswith("flat") else "--", "lw": 1.2}
    if name == "Ramakrishna":
        return {"color": "k", "ls": "-.", "lw": 1.8}
    if name == "L1WAWS":
        return {"color": "C3", "lw": 2.4}
    return {"lw": 1.2, "ls": "-" if name.startswith("L1") else "--"}


def _cdf(ax: Any, values: NDArray[np.float64], label: str, **kw: Any) -> None:
    v = np.sort(values[np.isfinite(values)])
    if len(v):
        ax.step(np.r_[0.0, v], np.r_[0.0, np.arange(1, len(v) + 1) / len(v)], where="post", label=label, **kw)


def _exp1_output(out: Path, rows: list[dict[str, Any]], cfg: ExperimentConfig, n_test: int,
                 n_train: int) -> str:
    plt = _plt()
    rows = sorted(rows, key=lambda r: (r["method"], r["k"]))
    cols = ["method", "k", "err", "err_median", "mpjpe_mm", "active_mean", "failed"]
    _write_csv(out / "exp1_bases.csv", rows, cols)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for m, st in (("sparse", "C3-o"), ("PCA", "C0-s"), ("class-wise PCA", "C2-^")):
        rs = [r for r in rows if r["method"] == m and not r["failed"]]
        if not rs:
            continue
        a1.plot([r["k"] for r in rs], [r["err"] for r in rs], st, label=m, ms=4)
        biggest = max(rs, key=lambda r: r["k"])
        _cdf(a2, np.asarray(biggest["active"], float), f"{m} (k={biggest['k']})", color=st[:2])
    a1.set(xlabel="number of bases k", ylabel="reconstruction error ||y - y_hat||_2 (leg units)",
           title=f"Fig. 3a: unseen test poses (n={n_test})", xscale="log")
    a2.set(xlabel="active bases per pose", ylabel="fraction of poses", title="Fig. 3b: active bases (CDF)")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend()
    fig.tight_layout()
    fig.savefig(out / "exp1_bases.png", dpi=90)
    plt.close(fig)
    md = (f"### 1. Basis learning (Fig. 3)\n\nBases learned on {n_train} training poses (paper split, every "
          f"{cfg.train_step}th frame); reconstruction of {n_test} unseen test poses (every {cfg.test_step}th "
          f"frame of the test trials) by L1-regularised least squares (theta = {cfg.theta_rec}). "
          f"Error = mean "
          f"||y - y_hat||_2 over the 36-vector in right-lower-leg units; MPJPE in mm (no alignment). Sparse "
          f"bases: {cfg.dl_iter} dictionary-learning epochs.\n\n")
    heads = ["method", "k", "error (leg)", "median", "MPJPE mm", "active bases (mean)"]
    md += _md_table(rows, cols[:-1], heads)
    (out / "exp1_bases.md").write_text(md)
    return md


def _lift_output(out: Path, name: str, rows: list[dict[str, Any]], keys: list[str], title: str,
                 intro: str) -> tuple[str, list[dict[str, Any]]]:
    plt = _plt()
    _write_csv(out / f"{name}_raw.csv", rows, ["exp", "cond", "level", "pose", "src", "yaw", "method", "err",
                                              "pmpjpe_mm", "time_s", "failed"])
    agg = _aggregate(rows, keys)
    order = _method_order(r["method"] for r in agg)
    agg.sort(key=lambda r: (*(r[k] for k in keys if k != "method"), order.index(r["method"])))
    cols = [*keys, "n", "failed", "err_mean", "err_median", "pmpjpe_mean", "pmpjpe_median", "time_s"]
    _write_csv(out / f"{name}.csv", agg, cols)
    heads = [*keys, "n", "failed", "error mean (leg)", "error median", "P-MPJPE mean mm", "P-MPJPE median mm",
             "s/pose"]
    md = f"### {title}\n\n{intro}\n\n" + _md_table(agg, cols, heads)
    (out / f"{name}.md").write_text(md)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    if keys == ["method"]:  # cumulative distributions
        for m in order:
            _cdf(ax, np.array([r["err"] for r in rows if r["method"] == m], float), m, **_style(m))
        ax.set(xlabel="||y - y_hat||_2 (right lower leg units)", ylabel="fraction of poses")
    elif name == "exp3_robust":
        conds = list(dict.fromkeys((r["cond"], r["level"]) for r in agg))
        xs = np.arange(len(conds))
        for m in order:
            cell = {(r["cond"], r["level"]): r["pmpjpe_mean"] for r in agg if r["method"] == m}
            ys = [cell.get(c, np.nan) for c in conds]
            ax.plot(xs, ys, marker="o", label=m, **_style(m))
        ax.set_xticks(xs, [c if c == "clean" else f"{int(n)} {c}" for c, n in conds], rotation=20)
        ax.set(ylabel=_MM_LABEL)
    else:
        for m in order:
            rs = sorted((r for r in agg if r["method"] == m), key=lambda r: r["level"])
            ax.plot([r["level"] for r in rs], [r["pmpjpe_mean"] for r in rs], marker="o", ms=3, label=m,
                    **_style(m))
        ax.set(xlabel="2D noise std (right lower leg units)" if name == "exp3_noise" else "yaw (degrees)",
               ylabel=_MM_LABEL)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out / f"{name}.png", dpi=90)
    plt.close(fig)
    return md, agg


def _cell(agg: list[dict[str, Any]], method: str, col: str = "err_mean", **where: Any) -> float:
    for r in agg:
        if r["method"] == method and all(r.get(k) == v for k, v in where.items()):
            return float(r[col])
    return float("nan")


# --------------------------------------------------------------------------- main


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
    from tqdm import tqdm

    from pose_lifter.core import PoseBases
    from pose_lifter.core.bases import learn_classwise_pca_bases

    cfg = config or (QUICK if quick else FULL)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    n_bank = max(cfg.n_factors, cfg.n_noise, cfg.n_robust, cfg.n_angle, cfg.n_camera)
    data = _load_data(data_dir, cfg, n_bank)
    sparse = PoseBases.load()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Objective did not converge")
        classwise = learn_classwise_pca_bases(data.train, data.train_labels, n_per_class=8, n_starts=1)
    _W_main["sparse"] = sparse
    lift_tasks, floors = _lift_tasks(data, cfg)
    base_tasks: list[dict[str, Any]] = []
    for k in cfg.sparse_ks:
        base_tasks.append({"kind": "bases", "exp": "exp1_bases", "method": "sparse", "k": k,
                           "dl_iter": cfg.dl_iter, "seed": cfg.seed, "theta": cfg.theta_rec})
    for k in sorted({min(k, 36) for k in (1, 2, 3, 4, 6, 9, 12, 18, 24, 30, 36)}):
        base_tasks.append({"kind": "bases", "exp": "exp1_bases", "method": "PCA", "k": k,
                           "theta": cfg.theta_rec})
    n_cls = len(np.unique(data.train_labels))
    for n in cfg.classwise_per_class:
        base_tasks.append({"kind": "bases", "exp": "exp1_bases", "method": "class-wise PCA",
                           "k": n_cls * (n + 1),
                           "per_class": n, "theta": cfg.theta_rec})
    tasks = sorted(base_tasks + lift_tasks, key=_cost, reverse=True)
    results: list[dict[str, Any]] = []
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    ctx = get_context("fork" if platform.system() == "Linux" else "spawn")
    init_args = (sparse, classwise, data.train, data.train_labels, data.test_rec, data.test_rec_leg_mm)
    with ctx.Pool(max(1, processes), initializer=_init_worker, initargs=init_args) as pool:
        for r in tqdm(pool.imap_unordered(_task, tasks), total=len(tasks), desc="experiments", mininterval=5):
            results.append(r)
    t_run = time.perf_counter() - t_start

    by_exp: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in results + floors:
        by_exp[r["exp"]].append(r)
    failures = sum(1 for r in results if r["failed"])
    ns, nr = cfg.n_starts, cfg.n_refine
    solver = (f"lifter: packaged sparse bases (k={sparse.n_bases}), {ns} cold k-means starts screened "
              f"to {nr}; "
              f"Ramakrishna et al. 2012: class-wise PCA bases ({classwise.n_bases} = "
              f"{n_cls} classes x (1 offset + 8 components)) on the same training data.")
    md1 = _exp1_output(out, by_exp["exp1_bases"], cfg, len(data.test_rec), len(data.train))
    poses = "poses drawn round-robin from the unseen test actions (walk, run, punch), random trial and frame"
    md2, agg2 = _lift_output(
        out, "exp2_factors", by_exp["exp2_factors"], ["method"], "2. Three factors (Fig. 4): clean 2D",
        f"{cfg.n_factors} {poses}, each at a random yaw; {solver}")
    md3, agg3 = _lift_output(
        out, "exp3_noise", by_exp["exp3_noise"], ["level", "method"],
        "3. Inaccurate 2D (Fig. 5): Gaussian noise",
        f"{cfg.n_noise} poses x {len(cfg.noise_levels)} noise levels (std in right-lower-leg "
        f"units, same noise "
        f"for every method); {solver}")
    md3b, agg3b = _lift_output(
        out, "exp3_robust", by_exp["exp3_robust"], ["cond", "level", "method"],
        "3b. Detector-like errors: gross outliers and missing joints",
        f"{cfg.n_robust} poses; 'outliers': that many joints displaced 1.5-3 leg lengths in a "
        f"random direction "
        f"(confidence kept at 1); 'missing': that many joints with confidence 0. {solver}")
    md4, agg4 = _lift_output(
        out, "exp4_angle", by_exp["exp4_angle"], ["level", "method"], "4. Human-camera angle (Fig. 6)",
        f"{cfg.n_angle} poses x {len(cfg.angles)} yaw angles (level = yaw in degrees, "
        f"body frame: 0 = frontal, "
        f"90 = profile); {solver}")
    md5, agg5 = _lift_output(
        out, "exp5_camera", by_exp["exp5_camera"], ["method"], "5. Camera estimation (Fig. 8)",
        f"{cfg.n_camera} poses at random yaw. GT camera: the pose step alone (core.pose_step.pose_step, "
        f"{sparse.n_bases} bases, L1WAWS, mean-pose start, up to 100 ADM iterations) with the true camera; "
        f"estimated: the full alternation (L1WAWS, screened to {cfg.n_refine} starts).")

    def c(agg: list[dict[str, Any]], m: str, col: str = "err_mean", **w: Any) -> str:
        v = _cell(agg, m, col, **w)
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
    cam = [f"\n\nCamera estimation (n={cfg.n_camera}), mean error (leg) / P-MPJPE mm: "
           + "; ".join(f"{r['method']}: {r['err_mean']:.3f} / {r['pmpjpe_mean']:.0f}" for r in agg5) + "."]
    sparse_rows = [r for r in by_exp["exp1_bases"] if not r["failed"]]
    best = {m: min((r for r in sparse_rows if r["method"] == m), key=lambda r: r["err"], default=None)
            for m in ("sparse", "PCA", "class-wise PCA")}
    b1 = "; ".join(f"{m} {r['err']:.3f} at k={r['k']} ({r['active_mean']:.1f} active)"
                   for m, r in best.items() if r is not None)
    summary = (
        "# The paper's experiments on CMU mocap (Wang et al. 2014, Sec. 4)\n\n"
        f"Command: `{command or 'pose-lifter experiments'}`"
        f"{' (QUICK: tiny sample sizes)' if cfg is QUICK else ''}. "
        f"Runtime {t_run:.0f} s with {processes} worker processes; {len(tasks)} tasks, {failures} failed "
        "solves "
        "(counted in the tables' `failed` column, excluded from the means).\n\n"
        "Errors: the paper's ||y - y_hat||_2 (36-vector, right lower leg = 1, rotation-aligned) and "
        "P-MPJPE in mm "
        "(similarity-aligned). Training: CMU subject 01 playground trials ("
        f"{', '.join(data.train_trials)}); testing: unseen walk/run/punch trials. Clean weak-perspective 2D "
        "unless stated.\n\n## Headline\n\n"
        f"Basis learning (lowest reconstruction error per method): {b1}.\n\n"
        + "\n".join(head) + "".join(cam) + "\n\n"
        + "\n".join([md1, md2, md3, md3b, md4, md5])
        + "\n## Configuration\n\n```json\n" + json.dumps(asdict(cfg), indent=1) + "\n```\n"
    )
    path = out / "summary.md"
    path.write_text(summary)
    print(f"experiments: {len(tasks)} tasks ({failures} failed) in {t_run:.0f} s -> {out}")
    return path
