"""How far the pose step's fused kernel and its Python loop drift apart under this machine's BLAS.

Usage::

    .venv/bin/python tools/fused_vs_loop.py [--problems N]
    OPENBLAS_CORETYPE=Prescott NUMBA_CPU_NAME=generic .venv/bin/python tools/fused_vs_loop.py

The problems of ``tests/core/test_pose_step.py`` (random in-model poses, noise, two missing joints,
with and without the prior's rows and per-person limb lengths), solved both ways:

* one ADM iteration from the same input (the start, then the loop's own iterate and multipliers
  after k = 1..14 iterations): the worst relative difference of objective, coefficients and
  multipliers (bounded in the tests by ``tolerances.FUSED_STEP_REL``);
* the whole step, 15 iterations, not converged: objective and pose (``FUSED_VS_LOOP_REL``).

Prints the BLAS kernel and numba target it ran with, so runs under several set-ups can be set side
by side.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO / "tests"), str(REPO / "tests" / "core")]

from lift_hash import _machine  # noqa: E402  (tools/ is on sys.path when run as a script)
from pose_lifter.core.bases import PoseBases, default_bases_path  # noqa: E402
from pose_lifter.core.options import LifterOptions  # noqa: E402
from pose_lifter.core.pose_model import PoseModel  # noqa: E402
from pose_lifter.core.pose_step import pose_step  # noqa: E402
from test_pose_step import _prior_rows, _problem  # noqa: E402


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    diff = np.abs(np.asarray(a) - np.asarray(b)).max()
    return float(diff / max(float(np.abs(np.asarray(b)).max()), 1e-300))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--problems", type=int, default=12, help="seeds (each with and without a prior)")
    args = ap.parse_args(argv)
    bases = PoseBases.load(default_bases_path("hybrid"))
    model = PoseModel.build(bases, bases.limb_proportions)
    opts = LifterOptions(theta=0.1, pose_tol=1e-12, alpha_solver="riemannian")
    step = {"objective": 0.0, "coefficients": 0.0, "multipliers": 0.0}
    whole = {"objective": 0.0, "pose": 0.0}
    for seed in range(args.problems):
        for with_prior in (False, True):
            x, m0, t, w, pose = _problem(model, seed)
            prior = _prior_rows(model, seed, pose, m0, t) if with_prior else None
            start = np.zeros(model.n_bases)
            state = None
            for k in range(15):
                if k:
                    state = pose_step(x, m0, t, w, model, start, opts, max_iter=k, prior=prior, fused=False)
                a0 = start if state is None else state.alpha
                duals = None if state is None else state.duals
                one = {"max_iter": 1, "prior": prior, "duals": duals}
                f = pose_step(x, m0, t, w, model, a0, opts, **one)  # type: ignore[arg-type]
                lp = pose_step(x, m0, t, w, model, a0, opts, fused=False, **one)  # type: ignore[arg-type]
                assert f.duals is not None and lp.duals is not None
                step["objective"] = max(step["objective"], _rel(lp.objective, f.objective))
                step["coefficients"] = max(step["coefficients"], _rel(lp.alpha, f.alpha))
                step["multipliers"] = max(step["multipliers"], _rel(lp.duals.data, f.duals.data))
            f = pose_step(x, m0, t, w, model, start, opts, max_iter=15, prior=prior)
            lp = pose_step(x, m0, t, w, model, start, opts, max_iter=15, prior=prior, fused=False)
            whole["objective"] = max(whole["objective"], _rel(lp.objective, f.objective))
            whole["pose"] = max(whole["pose"], _rel(lp.pose, f.pose))
    print(f"fused_vs_loop: {2 * args.problems} problems; {_machine()}")
    print("  one iteration from the same input (x15), worst relative: "
          + ", ".join(f"{k} {v:.1e}" for k, v in step.items()))
    print("  whole step, 15 iterations unconverged, worst relative:   "
          + ", ".join(f"{k} {v:.1e}" for k, v in whole.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
