"""The tests' numerical tolerances, each stated once with what it bounds.

Imported by name (``from tolerances import ROUND_OFF``): pytest puts ``tests/`` on ``sys.path``
(``pythonpath`` in pyproject.toml), as for the other helper modules here (``detector_poses``,
``synthetic_poses``). A plain module rather than fixtures: the values are constants, used in
module-level tables and parametrisations as well as in test bodies.

The reference solvers' own settings (Clarabel / SCS / SLSQP tolerances) are not here: they are
:data:`pose_lifter.core.reference.TOLERANCES`. Unless said otherwise a tolerance is absolute,
in the units of the quantity (normalised units: right-lower-leg lengths).
"""

from __future__ import annotations

from typing import Final

# ---------------------------------------------------------------- round-off (exact arithmetic)
#: A few float64 operations on O(1) numbers: identities, orthonormality, one number computed two
#: ways (absolute; also used relative, on an objective re-evaluated from the same operands).
ROUND_OFF: Final[float] = 1e-12
#: A longer chain of float64 operations that is exact in exact arithmetic (a normalisation
#: through an SVD, a quadratic form summed over constraints, an orthonormalised rotation).
ROUND_OFF_LONG: Final[float] = 1e-10
#: Many operations, or values far from 1 (millimetres, pixels, metres at 5 m): bag round trips,
#: Procrustes, metric identities, an objective re-evaluated by a different summation (relative).
ROUND_OFF_ACCUMULATED: Final[float] = 1e-9
#: A value that went through float32 (a message field) against its float64 source, relative.
FLOAT32_REL: Final[float] = 1e-6
#: The outputs of a saved learned prior (float32 weights) against the in-memory one, relative.
PRIOR_FLOAT32_REL: Final[float] = 1e-4
#: One CMU trial read from its AMC and from its BVH file (the files' decimal precision), metres.
MOCAP_FORMAT_AGREEMENT: Final[float] = 2e-5

# ---------------------------------------------------------------- what a solver reaches on its own
#: Largest limb-length violation of a converged lift (the lifter's limb constraints; the
#: baseline's single limb condition), right-lower-leg units.
LIFT_LIMB_VIOLATION: Final[float] = 1e-6
#: Two solves of one problem posed two equivalent ways (the image scaled and shifted): pose
#: (normalised units) and camera scale (relative).
SOLVE_REPEAT: Final[float] = 1e-6
#: The compiled pose step against the Python ADM loop around the same alpha-step, one ADM iteration
#: from the same input (iterate and multipliers): the same compiled rows and updates, but the loop
#: forms ``A alpha`` with numpy / BLAS products from ``alpha`` where the kernel sums rows of the
#: carried ``V^T alpha``, so they differ by round-off times the conditioning of the iteration's
#: small solves. Relative, objective, coefficients and multipliers. Worst of 24 problems x 15
#: iterations measured 2e-14 (OpenBLAS Haswell, numba host target); a second Newton step in the
#: alpha-step or a flipped sign moves them by far more.
FUSED_STEP_REL: Final[float] = 1e-9
#: ... and the whole step, 15 iterations and not converged, by what a user sees (objective and
#: pose, relative): round-off grows by up to about 10^5 over 15 iterations of the nonconvex ADM
#: (measured worst 6e-11 on the same 24 problems; the final multipliers, which no user sees, are
#: not compared).
FUSED_VS_LOOP_REL: Final[float] = 1e-6
#: The compiled run (core/solve/run_kernel.py) against ``Runs.run``'s Python loop, the same inputs:
#: both call the same compiled steps and the same compiled objective terms, so they perform the
#: same floating-point operations on any CPU and BLAS (measured 0 on every replayed run); the
#: bound leaves room for nothing but a changed operation, which moves a run by far more (a flipped
#: sign in the kernel's objective: 1e-2 or more); objectives and iterates, relative.
FUSED_RUN_REL: Final[float] = 1e-12
#: SCS (first-order) at eps 1e-9 on the SDP relaxation: its solution's PSD-ness (relative to
#: max |Q|) and its equality constraints (absolute).
SCS_ACCURACY: Final[float] = 1e-6

# ---------------------------------------------------------------- the references on their own
#: Q-step KKT residual and constraint residual, relative to the size of the data.
KKT: Final[float] = 1e-7
#: Equality constraints at a SLSQP / Clarabel solution or at the fast path's alpha-step result.
FEASIBILITY: Final[float] = 1e-7
#: SDP value <= local value + this * (1 + |local value|) (SCS's slack).
SDP_BOUND_REL: Final[float] = 1e-4
#: Camera / pose recovered by a reference from noise-free data.
RECOVERY: Final[float] = 1e-6

# ---------------------------------------------------------------- fast path vs reference
#: Fast camera objective <= reference * (1 + CAMERA_OBJECTIVE_REL) + CAMERA_OBJECTIVE_ABS.
CAMERA_OBJECTIVE_REL: Final[float] = 1e-3
CAMERA_OBJECTIVE_ABS: Final[float] = 1e-5
#: ||R2_fast - R2_ref||_F when the camera optimum is unique.
CAMERA_ROTATION: Final[float] = 1e-3
#: max |Q_fast - Q_ref| of the Q-step (both exact: closed form vs Clarabel).
QSTEP_SOLUTION: Final[float] = 1e-6
#: Convex pose step: |f_fast - f_ref| <= POSE_OBJECTIVE_REL * (1 + f_ref).
POSE_OBJECTIVE_REL: Final[float] = 1e-3
#: Convex pose step: ||alpha_fast - alpha_ref||_inf (unique optimum assumed: L2 with theta > 0 on
#: a full-rank problem).
POSE_ALPHA: Final[float] = 1e-3
#: Limb-constrained alpha-step / pose step (nonconvex: only "not worse than a local reference
#: from the same start"): fast objective <= local * (1 + ..._REL) + ..._ABS.
ALPHA_STEP_OBJECTIVE_REL: Final[float] = 1e-2
ALPHA_STEP_OBJECTIVE_ABS: Final[float] = 1e-4
#: max_i | ||C_i y||^2 - L_i | accepted from one fast pose step (at its stopping tolerance).
POSE_STEP_LIMB_VIOLATION: Final[float] = 1e-3
#: Limb-constrained pose step over a set of problems: fast objective / best local reference
#: (SLSQP from several starts), median and worst case.
NONCONVEX_MEDIAN_RATIO: Final[float] = 1.05
NONCONVEX_MAX_RATIO: Final[float] = 1.3

#: The offline 2D smoother's recursive passes (Rauch-Tung-Striebel) against the batch least
#: squares they solve: the smoothed positions (relative and absolute, values of order 1) ...
SMOOTHER_AGREEMENT: Final[float] = 1e-9
#: ... and their variances (relative): a frame before a series' second measurement has its
#: variance from a barely determined velocity, which the recursive and the batch solutions (and
#: a plain 2 x 2 matrix version of the recursion) compute to ~1e-6 of each other.
SMOOTHER_VARIANCE_AGREEMENT: Final[float] = 1e-5
#: The depth fusion's Gaussian conditioning (a joint without a reading enters its solve with a
#: variance of 1e6 m^2, not infinity) against the textbook formula on the read joints alone:
#: depths (m) and standard deviations (m), absolute.
DEPTH_CONDITIONING: Final[float] = 1e-7

# ---------------------------------------------------------------- accuracy bounds from measurements
# Each bound below is the value it guards, measured on this code (the command and commit named),
# times (1 + ACCURACY_MARGIN), and never above the flat floor of the same frames (no depth at
# all): a lifter that regresses past "no 3D" fails. The margin covers what differs between
# x86-64 machines (summation order in BLAS and the compiled kernels): builds differing only in
# it were measured up to ~12 % apart on a 4-frame bag replay.
#: Relative margin of a measured accuracy bound.
ACCURACY_MARGIN: Final[float] = 0.20


def measured_bound(measured: float, floor: float | None = None) -> float:
    """``measured * (1 + ACCURACY_MARGIN)``, capped 1 % below ``floor`` (when given)."""
    bound = measured * (1.0 + ACCURACY_MARGIN)
    return bound if floor is None else min(bound, 0.99 * floor)


#: tests/offline/test_bags.py REPLAY (frames 0, 10, 20, 30; 3 cold starts; the hybrid default), per bag:
#: (P-MPJPE, MPJPE, flat floor P-MPJPE) mm, measured at 3f1ffe5 with
#: `.venv/bin/python tools/bag_bands.py` (the floors are the bag's, not the lifter's).
BAG_REPLAY_MM: Final[dict[str, tuple[float, float, float]]] = {
    "walk_clean": (66.2, 70.4, 114.9),
    "punch_outliers": (72.7, 128.2, 194.6),
    "two_people": (83.2, 99.9, 99.4),
}
#: tests/ros/test_lifter_graph.py's replay: two_people's first 8 frames, 3 cold starts, warm
#: starts on, no smoothing (the node's answers; equal to the offline lift's): (P-MPJPE, MPJPE,
#: flat floor) mm, measured at 3f1ffe5 by `lift_bag(..., LiftSettings(max_messages=8,
#: smoothing_s=0.0))` + `evaluate_bag`.
NODE_REPLAY_TWO_PEOPLE_MM: Final[tuple[float, float, float]] = (62.1, 75.1, 95.7)
#: The README's core example (normalised P-MPJPE it prints), measured 0.071 at 3f1ffe5
#: (`pytest -s tests/test_readme.py`).
README_EXAMPLE_P_MPJPE: Final[float] = measured_bound(0.071)
#: A yolo_ros DetectionArray adapted and lifted (tests/messages/test_adapters.py, exact input): the
#: reprojection error in pixels, measured 2.77 px (of a 201 px tall person) at 3f1ffe5.
ADAPTED_REPROJECTION_PX: Final[float] = measured_bound(2.77)
#: tests/mocap/test_experiments.py's worker on the noise-free mean pose seen at 30 degrees: the paper's
#: normalised error of the lifter and of the pose step with the true camera (the limb
#: constraints' anthropometric proportions move the pose off the bases' mean), measured 0.586
#: and 1.115 at 3f1ffe5 (`pytest -s`); the P-MPJPE in mm 51.9 and 116.1.
WORKER_MEAN_POSE_ERR: Final[dict[str, float]] = {"L1WAWS": measured_bound(0.586),
                                                  "GT camera": measured_bound(1.115)}
WORKER_MEAN_POSE_MM: Final[dict[str, float]] = {"L1WAWS": measured_bound(51.9),
                                                 "GT camera": measured_bound(116.1)}

#: tests/core/solve/test_against_reference.py test_limb_pose_step_is_feasible_local_minimum: how far
#: above the local minimum SLSQP reaches from its result the default pose step (40 ADM
#: iterations; on its 12-basis model the Riemannian step falls back to the paper's inner ADM) may
#: end, worst of 6 problems. L1WAWS measured +8.76 % (case 2; the same to 1e-14 with
#: OPENBLAS_CORETYPE=Prescott NUMBA_CPU_NAME=generic and with one thread) at this file's commit,
#: `pytest -s` with the gaps printed; L2WAWS ends at the polished minimum (ALPHA_STEP_OBJECTIVE_REL).
DEFAULT_POSE_LOCAL_GAP: Final[dict[str, float]] = {"L1WAWS": measured_bound(0.0876)}

# ---------------------------------------------------------------- the paper's inner ADM (measured)
# These are wider than the solver tolerances above on purpose: the paper's inner ADM never meets
# its own tolerance in its iteration cap on these problems, and on some it ends in a poorer local
# minimum. The problems are the same on every machine (the PCA bases they are built on are signed
# by pose_lifter.core.model.bases' convention, not by the BLAS kernel's SVD).
#: How far above the SLSQP polish of its own output the inner ADM alpha-step may end, on every
#: one of tests/core/solve/test_against_reference.py's 8 problems (within ALPHA_STEP_OBJECTIVE_REL on
#: at least ADMM_ALPHA_CASES_WITHIN_TOL of them). Measured: case 3 at +34.3 %, the other 7 within
#: 0.6 %, the same to 1e-5 with OpenBLAS's Zen, Haswell and Prescott kernels and numba for a
#: generic x86-64 (the test's assertion messages list the 8 gaps).
ADMM_ALPHA_MAX_GAP: Final[float] = measured_bound(0.343)
ADMM_ALPHA_CASES_WITHIN_TOL: Final[int] = 7
#: Worst objective ratio of the inner-ADM pose step to the best local reference over the 4
#: problems of test_limb_pose_step_close_to_best_local_reference: measured L1WAWS 1.001-1.088,
#: L2WAWS 1.268 on case 1 and 1.000 on the others, the same under both kernels named above (the
#: median is bounded by NONCONVEX_MEDIAN_RATIO).
ADMM_POSE_MAX_RATIO: Final[float] = measured_bound(1.268)

# ---------------------------------------------------------------- default options' known gaps (measured)
# The default iteration caps trade the last digits of the convex steps for speed. Each gap is the
# largest measured over the reference problems at 3f1ffe5 (tests/core/solve/test_against_reference.py)
# with ACCURACY_MARGIN; run to convergence the same solvers reach the optimum (tested).
#: The L1 camera ADM at LifterOptions()' cap (100 iterations, tau 10): relative objective gap
#: to the reference optimum, measured 0.0128 (cases 0-4: 0.0096, 0.0010, 0.0128, 0.0015, 0.0086).
CAMERA_L1_DEFAULT_GAP: Final[float] = 0.0128 * (1 + ACCURACY_MARGIN)
#: Its rotation's distance to the optimum's (Frobenius, first two rows), measured max 0.00137
#: (against CAMERA_ROTATION = 1e-3 when converged).
CAMERA_L1_DEFAULT_ROTATION: Final[float] = 0.00137 * (1 + ACCURACY_MARGIN)
#: The convex pose step at LifterOptions()' cap (40 iterations, tol 1e-3): |f - f*| / (1 + f*),
#: measured max over 3 problems: L1NAWS 0.0249, L1NANS 0.158, L2NANS 0.0751 (relative to f*
#: alone: +3.6 %, +26.5 %, +60.7 %). L2NAWS reaches the optimum (POSE_OBJECTIVE_REL).
CONVEX_POSE_DEFAULT_GAP: Final[dict[str, float]] = {
    "L1NAWS": 0.0249 * (1 + ACCURACY_MARGIN),
    "L1NANS": 0.158 * (1 + ACCURACY_MARGIN),
    "L2NANS": 0.0751 * (1 + ACCURACY_MARGIN),
}

#: `pose-lifter experiments --quick` (tests/mocap/test_experiments.py, CMU data): the largest error of
#: any row (any method, floors included) per experiment, (normalised error, P-MPJPE mm), measured
#: at 2f11496 (exp1: the bases' reconstruction error): the worst single lifts are the paper's
#: baseline on outliers (Ramakrishna, 6.83) and the convex variant on noise (3.34).
QUICK_RUN_MAX: Final[dict[str, tuple[float, float]]] = {
    name: (measured_bound(err), measured_bound(mm)) for name, (err, mm) in {
        "exp1_bases": (1.475, 0.0),
        "exp2_factors": (1.944, 182.4),
        "exp3_noise": (3.340, 348.0),
        "exp3_robust": (6.828, 336.5),
        "exp4_angle": (1.944, 182.4),
        "exp5_camera": (1.944, 182.4),
    }.items()
}
