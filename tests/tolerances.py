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
#: The compiled run (core/run_kernel.py) against ``Runs.run``'s Python loop, the same inputs:
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
