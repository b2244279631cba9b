"""pose-lifter experiments: the camera convention, class labels, a worker running each kind of task,
and a --quick run on real data."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import tolerances as tol
from cmu_data import DATA, needs_data
from pose_lifter import cli
from pose_lifter.core.model.skeleton import body_frame
from pose_lifter.mocap.experiment_tasks import BasesTask, LiftSolver, LiftTask, Worker, WorkerInputs, cost
from pose_lifter.mocap.experiments import action_class, camera_rotation, project


@pytest.mark.parametrize("yaw", [0.0, 37.0, 90.0, 180.0, 271.0])
def test_camera_is_a_proper_rotation_to_a_y_down_frame(yaw: float) -> None:
    r = camera_rotation(yaw)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=tol.ROUND_OFF)
    assert np.linalg.det(r) == pytest.approx(1.0)  # never a mirror
    # body y (up) maps to image y down, whatever the yaw
    np.testing.assert_allclose(r @ [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], atol=tol.ROUND_OFF)


def test_frontal_view_keeps_chirality() -> None:
    # a pose in the body frame (x: right hip -> left hip, y up, z = x cross y: forward)
    pose = np.zeros((12, 3))
    pose[6] = [0.5, 0.0, 0.0]   # left hip
    pose[9] = [-0.5, 0.0, 0.0]  # right hip
    pose[0] = [0.6, 2.0, 0.0]   # left shoulder
    pose[3] = [-0.6, 2.0, 0.0]  # right shoulder
    pose[[7, 8]] = pose[6] - [0, 1, 0], pose[6] - [0, 2, 0]
    pose[[10, 11]] = pose[9] - [0, 1, 0], pose[9] - [0, 2, 0]
    pose[[1, 2]] = pose[0] - [0, 1, 0], pose[0] - [0, 2, 0]
    pose[[4, 5]] = pose[3] - [0, 1, 0], pose[3] - [0, 2, 0]
    np.testing.assert_allclose(body_frame(pose), np.eye(3), atol=tol.ROUND_OFF)
    x = project(pose, 0.0)
    # yaw 0: the optical axis is body -z, so the camera faces the person's front and the
    # person's left hip appears on the image's right (a mirror would put it on the left)
    assert x[6, 0] > x[9, 0]
    assert x[0, 1] < x[8, 1]  # shoulders above ankles (image y down)
    # seen from behind (yaw 180) the hips swap sides
    xb = project(pose, 180.0)
    assert xb[6, 0] < xb[9, 0]


def test_action_class_labels() -> None:
    assert action_class("playground - climb, hang, swing") == "swing"
    assert action_class("playground - climb, sit, dangle legs, jump down") == "sit"
    assert action_class("playground - forward jumps, turn around") == "jump"
    assert action_class("playground - climb, go under") == "climb"


def test_a_worker_runs_each_kind_of_task_and_reports_failures_in_the_row() -> None:
    from pose_lifter.core import PoseBases

    sparse = PoseBases.load()
    gt = sparse.mean_pose
    rng = np.random.default_rng(0)
    train = gt + rng.normal(0.0, 0.05, size=(40, 12, 3))
    worker = Worker(WorkerInputs(sparse, sparse, train, np.repeat(["a", "b"], 20), train[:6],
                                 np.full(6, 430.0)))
    x = project(gt, 30.0)
    common = {"exp": "exp2_factors", "cond": "clean", "level": 0.0, "pose": 0, "src": "t:0", "yaw": 30.0,
              "x": x, "conf": None, "gt": gt, "leg_mm": 430.0}
    lift = LiftTask(**common, method="L1WAWS", solver=LiftSolver.LIFTER, variant="L1WAWS", starts=2)
    true_camera = LiftTask(**common, method="GT camera", solver=LiftSolver.GT_CAMERA,
                           rotation=camera_rotation(30.0))
    rows = [worker.run(task) for task in (lift, true_camera)]
    for task, row in zip((lift, true_camera), rows, strict=True):
        assert row["failed"] == "" and row["method"] == task.method and row["exp"] == "exp2_factors"
        assert 0.0 <= row["err"] < tol.WORKER_MEAN_POSE_ERR[task.method], row
        assert 0.0 <= row["pmpjpe_mm"] < tol.WORKER_MEAN_POSE_MM[task.method], row
        assert "x" not in row and "gt" not in row  # rows hold the task's scalars only
    broken = LiftTask(**{**common, "x": np.full((12, 2), np.nan)}, method="L1WAWS", solver=LiftSolver.LIFTER,
                      variant="L1WAWS")
    row = worker.run(broken)
    assert row["failed"] and np.isnan(row["err"]) and np.isnan(row["pmpjpe_mm"])
    pca = worker.run(BasesTask("PCA", 3, 0.1))
    assert pca["failed"] == "" and pca["k"] == 3 and np.isfinite(pca["err"]) and len(pca["active"]) == 6
    assert cost(BasesTask("PCA", 3, 0.1)) > cost(lift) > cost(true_camera)  # slowest first


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


@needs_data
def test_quick_run_writes_sane_outputs(tmp_path: Path) -> None:
    out = tmp_path / "exp"
    assert cli.main(["experiments", "--data", str(DATA), "--out", str(out), "--quick"]) == 0
    for name in ("exp1_bases", "exp2_factors", "exp3_noise", "exp3_robust", "exp4_angle", "exp5_camera"):
        png = (out / f"{name}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
        assert (out / f"{name}.md").read_text().count("|") > 10
        assert _rows(out / f"{name}.csv")
    summary = (out / "summary.md").read_text()
    assert "## Headline" in summary and "QUICK" in summary

    bases = _rows(out / "exp1_bases.csv")
    pca = sorted((int(r["k"]), float(r["err"])) for r in bases if r["method"] == "PCA")
    assert pca[-1][1] < pca[0][1]  # more principal components reconstruct unseen poses better
    assert {r["method"] for r in bases} == {"sparse", "PCA", "class-wise PCA"}
    for r in bases:
        assert 0.0 < float(r["err"]) < tol.QUICK_RUN_MAX["exp1_bases"][0]
        assert 1.0 <= float(r["active_mean"]) <= int(r["k"])

    for name in ("exp2_factors", "exp3_noise", "exp3_robust", "exp4_angle", "exp5_camera"):
        rows = _rows(out / f"{name}_raw.csv")
        assert not [r for r in rows if r["failed"]]
        methods = {r["method"] for r in rows}
        assert {"flat floor", "mean-pose floor"} <= methods
        worst_err, worst_mm = tol.QUICK_RUN_MAX[name]
        for r in rows:
            err, mm = float(r["err"]), float(r["pmpjpe_mm"])
            assert 0.0 < err < worst_err and 0.0 < mm < worst_mm, (name, r["method"], err, mm)
    cam = {r["method"]: float(r["err"]) for r in _rows(out / "exp5_camera_raw.csv")}
    # with the true camera the pose step reconstructs better than the mean pose
    assert cam["GT camera, mean-pose start"] < cam["mean-pose floor"]
    assert "Ramakrishna" in {r["method"] for r in _rows(out / "exp3_noise_raw.csv")}
