"""Independent reference solvers for every subproblem of the method (the paper used CVX).

Each function here solves one subproblem of the fast path (``solve/camera.py``, ``solve/pose_step.py``) by a
different route, so the two can check each other:

* convex problems are written in cvxpy and solved by Clarabel (LPs and QPs) or SCS (the SDP
  relaxation; Clarabel densifies a large PSD cone, see ``shared/notes/ros2-from-pip.md``);
* nonconvex problems (the camera rotation, the limb-constrained alpha-step and pose step)
  get *local* references: scipy searches / SLSQP from given starts. They certify nothing
  globally; they are a second, independently coded local solver.

Conventions are those of the fast path: a 2D pose is ``points`` (n, 2), a 3D pose ``pose``
(n, 3) or the paper's ``y = pose.reshape(-1)``; ``weights`` (n,) >= 0 per joint (0 =
missing); ``loss`` is ``"l1"`` (sum of per-coordinate absolute values, weighted per joint)
or ``"l2"`` (weighted squared Euclidean norms). The camera is scaled orthographic,
``x_j = s R[:2] y_j + t`` (``shared/notes/method-pitfalls.md`` section 1).

One module per subproblem: :mod:`.camera` (the camera step), :mod:`.alpha` (the Q-step, the
SDP relaxation and a local solver of the alpha-step), :mod:`.pose` (the pose step, convex and
limb-constrained), :mod:`.runs` (a run of alternations in Python around the steps, the compiled
run's reference); :mod:`._common` holds what they share, among it the solvers' settings
(:data:`TOLERANCES`). cvxpy is imported inside the functions: the core imports without it.
The tests' tolerances (fast path vs these references) are in ``tests/tolerances.py``.
"""

from __future__ import annotations

from ._common import TOLERANCES, ReferenceSolverError
from .alpha import (
    limb_omegas,
    reference_alpha_local,
    reference_alpha_sdp,
    reference_qstep,
    top_eigenvalue_share,
)
from .camera import camera_objective, reference_camera, reference_camera_given_rotation
from .pose import pose_objective, reference_pose_convex, reference_pose_limbs_local

__all__ = [
    "TOLERANCES",
    "ReferenceSolverError",
    "camera_objective",
    "limb_omegas",
    "pose_objective",
    "reference_alpha_local",
    "reference_alpha_sdp",
    "reference_camera",
    "reference_camera_given_rotation",
    "reference_pose_convex",
    "reference_pose_limbs_local",
    "reference_qstep",
    "top_eigenvalue_share",
]
