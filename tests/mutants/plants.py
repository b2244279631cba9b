"""The planted regressions of ``make mutants`` (tests/mutants/run.py): each is a change the tests
must catch, the text it replaces in the package, and the tests that must turn red.

A plant whose text is no longer in its file fails the run (exit 2): a refactor moved the code it
plants into, so the plant is rewritten against the new code, not dropped.
"""

from __future__ import annotations

from typing import NamedTuple


class Plant(NamedTuple):
    """One planted regression."""

    what: str  #: the change, as a reader would name the bug
    file: str  #: the module it changes, under ros2_ws/src/pose_lifter/pose_lifter/
    text: str  #: the text it replaces (every occurrence)
    replacement: str
    tests: str  #: the test file that must fail (under the repository)
    select: str = ""  #: a pytest ``-k`` expression within it ("" : every test of the file)


#: The compiled solver steps against their references (each recompiles the kernels of its file).
KERNEL = [
    Plant("a sign in the pose ADM's d1", "core/solve/pose_kernel.py", "d1[i] = c[i] - gi + u1[i]",
          "d1[i] = c[i] - gi - u1[i]", "tests/core/solve/test_against_reference.py"),
    Plant("two Newton steps per alpha-step in the compiled pose step", "core/solve/settings.py",
          "alpha_max_iter=RIEMANNIAN_MAX_ITER,", "alpha_max_iter=2 * RIEMANNIAN_MAX_ITER,",
          "tests/core/solve/test_pose_step.py"),
    Plant("the sign of ||alpha||_1 in the run's objective", "core/solve/run_kernel.py",
          "obj = cobj + th * _sum_abs(alpha)", "obj = cobj - th * _sum_abs(alpha)",
          "tests/core/solve/test_run_kernel.py"),
    Plant("the compiled run keeps its last alternation, not its best", "core/solve/run_kernel.py",
          "if (kept.best_it < 0 and not continued) or obj < kept.best_obj:",
          "if (kept.best_it < 0 and not continued) or obj < kept.best_obj or True:",
          "tests/core/solve/test_run_kernel.py"),
]

#: What a user sees.
BEHAVIOUR = [
    Plant("a sign in the prior's output (its de-standardisation)", "core/model/prior.py",
          "* self.out_scale + self.out_mean", "* self.out_scale - self.out_mean",
          "tests/mocap/test_prior_training.py"),
    Plant("the measurement update pushed the wrong way", "core/track/measurement.py",
          "offset[j, c] += k * (obs[j, c] - pose[j, c] - offset[j, c])",
          "offset[j, c] -= k * (obs[j, c] - pose[j, c] - offset[j, c])",
          "tests/core/track/test_measurement_update.py"),
    Plant("the params file's options ignored", "messages/settings.py",
          "            values[name] = value", "            values[name] = spec.default",
          "tests/offline/test_lift_cli.py"),
    Plant("a wrong joint order in an adapter (COCO-17 wrists swapped)", "messages/layouts.py",
          '"coco17": Layout("coco17", 17, (5, 7, 9, 6, 8, 10,',
          '"coco17": Layout("coco17", 17, (5, 7, 10, 6, 8, 9,',
          "tests/messages/test_adapters.py"),
    Plant("a zeroed depth in the metric placement", "core/track/placement.py",
          "local = poses * np.reshape(np.asarray(leg_m, dtype=np.float64), (-1, 1, 1))",
          "local = poses * np.array([1.0, 1.0, 0.0])"
          " * np.reshape(np.asarray(leg_m, dtype=np.float64), (-1, 1, 1))",
          "tests/offline/test_offline.py"),
    Plant("the perspective correction's sign", "core/track/placement.py",
          "ratio = 1.0 + depths * scale[:, None] / focal[:, None]",
          "ratio = 1.0 - depths * scale[:, None] / focal[:, None]", "tests/core/track/test_tracking.py"),
    Plant("a REP-155 body's y axis from the left hip to the right", "messages/body.py",
          "    y = lh - rh\n", "    y = rh - lh\n", "tests/messages/test_body.py"),
    Plant("a lifted bag's markers never cleared first (not the node's)", "messages/markers.py",
          "clear=not self._cleared", "clear=False", "tests/offline/test_offline.py"),
    Plant("a split rosbag2 recording read file after file, not in time order", "offline/bags.py",
          "heapq.merge(*parts, key=lambda x: int(x[1]))", "iter([m for p in parts for m in p])",
          "tests/offline/test_rosbag2_dirs.py"),
    Plant("a REP-155 elbow placed the forearm's length down the upper arm", "messages/body.py",
          "trans[:, chain_rows + 3, 2] = -limbs.len1", "trans[:, chain_rows + 3, 2] = -limbs.len2",
          "tests/messages/test_body.py"),
    Plant("a batch of runs hands each row its neighbours' runs", "core/lift/runs.py",
          "for i, d in zip(which, done, strict=True):", "for i, d in zip(which, done[::-1], strict=True):",
          "tests/core/lift/test_batch.py"),
    Plant("a round's prior poses handed to each other's people", "core/lift/batch.py",
          "zip(members, poses, strict=True)", "zip(members, poses[::-1], strict=True)",
          "tests/core/model/test_prior.py"),
    Plant("a busy node drops the newest waiting frame instead of the oldest", "ros/frame_queue.py",
          "dropped = self._items.popleft() if", "dropped = self._items.pop() if",
          "tests/ros/test_node_parts.py"),
    Plant("a confident joint without coordinates counts (the NaN read as 0)", "core/validation.py",
          "    weights[bad] = 0.0\n", "", "tests/core/test_validation.py",
          "confident_joint_without_coordinates"),
    Plant("a missing joint keeps the coordinates it came with", "core/validation.py",
          "return np.where((weights > 0.0)[:, :, None], held, centroid[:, None, :]), weights",
          "return np.where(bad[:, :, None], 0.0, points), weights", "tests/core/test_validation.py",
          "where_a_missing_joint_was_put"),
    Plant("the depth readings without the surface-to-joint offset", "core/depth/fuse.py",
          "d = surface + SURFACE_OFFSET_M[None]",
          "d = surface", "tests/core/depth/test_fuse.py",
          "exact_readings"),
    Plant("the published uncertainty doubled", "core/depth/uncertainty.py",
          "return np.asarray(np.hypot(shape, root))", "return np.asarray(2.0 * np.hypot(shape, root))",
          "tests/mocap/test_rgbd_evaluation.py", "published_uncertainty"),
]

PLANTS = KERNEL + BEHAVIOUR
