"""The pose step's three alpha-step solvers side by side on the reference problems.

    .venv/bin/python tools/alpha_solvers.py

The 6 limb-constrained problems of ``tests/core/solve/test_against_reference.py`` (L1WAWS, theta 0.05,
noisy 2D with an outlier and a missing joint, default options otherwise) on PCA bases of 12
directions (too few for the Riemannian step's onto limb map: it falls back to the paper's inner
ADM) and of 30: per solver the mean objective the pose step reaches and its median time per
step (best of 5 calls after a warm-up; wall time, so it depends on the machine).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "core"), str(ROOT / "tests")]

from pose_lifter.core.model.bases import learn_pca_bases  # noqa: E402
from pose_lifter.core.model.pose_model import PoseModel  # noqa: E402
from pose_lifter.core.options import AlphaSolver, LifterOptions  # noqa: E402
from pose_lifter.core.solve.pose_step import pose_step  # noqa: E402
from synthetic_poses import synthetic_poses  # noqa: E402
from test_against_reference import _pose_problem  # noqa: E402

SOLVERS: tuple[AlphaSolver, ...] = ("riemannian", "newton", "admm")


def main() -> None:
    """Print one line per (number of bases, solver)."""
    poses, _ = synthetic_poses(300, seed=1)
    targets = synthetic_poses(20, seed=5)[0]
    print("bases  solver      mean objective  ms per pose step")
    for k in (12, 30):
        bases = learn_pca_bases(poses, n_bases=k, n_starts=3, seed=0)
        model = PoseModel.build(bases, bases.limb_proportions)
        for solver in SOLVERS:
            opts = LifterOptions(variant="L1WAWS", theta=0.05, alpha_solver=solver)
            objs, times = [], []
            for case in range(6):
                x, cam, w = _pose_problem(targets, case)
                res = pose_step(x, cam.projection, cam.translation, w, model, np.zeros(k), opts)
                best = np.inf
                for _ in range(5):
                    t0 = time.perf_counter()
                    pose_step(x, cam.projection, cam.translation, w, model, np.zeros(k), opts)
                    best = min(best, time.perf_counter() - t0)
                objs.append(res.objective)
                times.append(best)
            print(f"{k:5d}  {solver:10s}  {np.mean(objs):14.3f}  {1e3 * np.median(times):16.2f}")


if __name__ == "__main__":
    main()
