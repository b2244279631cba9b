"""The suite against deliberate changes of behaviour: each planted change must turn `make test` red.

Usage::

    .venv/bin/python tools/behaviour_mutations.py [--only SUBSTRING]

The sibling of tools/kernel_mutations.py (which plants changes in the compiled solver steps):
these change what a user sees. One change at a time is applied to the source tree (restored
afterwards, also on Ctrl-C), the test file of `make test` that must catch it runs, and the tool
prints whether it failed (the loop of tools/kernel_mutations.py). Exit 0 when every change is
caught.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from kernel_mutations import run_mutations  # the same loop (tools/ is the script's path)

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "ros2_ws" / "src" / "pose_lifter" / "pose_lifter"

#: (what, file under the package, text (every occurrence is changed), its replacement, the test)
MUTATIONS = [
    ("a sign in the prior's output (its de-standardisation)", "core/model/prior.py",
     "* self.out_scale + self.out_mean", "* self.out_scale - self.out_mean",
     "tests/mocap/test_prior_training.py"),
    ("the measurement update pushed the wrong way", "core/track/measurement.py",
     "offset[j, c] += k * (obs[j, c] - pose[j, c] - offset[j, c])",
     "offset[j, c] -= k * (obs[j, c] - pose[j, c] - offset[j, c])",
     "tests/core/track/test_measurement_update.py"),
    ("the params file's options ignored", "ros/params.py",
     "options = {k: v for k, v in merged.items() if k in _OPTIONS}", "options: dict[str, Any] = {}",
     "tests/offline/test_lift_cli.py"),
    ("a wrong joint order in an adapter (COCO-17 wrists swapped)", "core/model/layouts.py",
     '"coco17": Layout("coco17", 17, (5, 7, 9, 6, 8, 10,',
     '"coco17": Layout("coco17", 17, (5, 7, 10, 6, 8, 9,',
     "tests/messages/test_adapters.py"),
    ("a zeroed depth in the metric placement", "core/track/placement.py",
     "local = pose * float(leg_length_m)", "local = pose * np.array([1.0, 1.0, 0.0]) * float(leg_length_m)",
     "tests/offline/test_offline.py"),
    ("the perspective correction's sign", "core/track/policy.py",
     "ratio = 1.0 + np.asarray(depths", "ratio = 1.0 - np.asarray(depths",
     "tests/core/track/test_tracking.py"),
    ("a REP-155 body's y axis from the left hip to the right", "messages/body.py",
     "        y = lh - rh\n", "        y = rh - lh\n", "tests/messages/test_body.py"),
    ("a lifted bag's markers never cleared first (not the node's)", "messages/markers.py",
     "clear=not self._cleared", "clear=False", "tests/offline/test_offline.py"),
    ("a split rosbag2 recording read file after file, not in time order", "offline/bags.py",
     "heapq.merge(*parts, key=lambda x: int(x[1]))", "iter([m for p in parts for m in p])",
     "tests/offline/test_rosbag2_dirs.py"),
    ("a REP-155 elbow placed the forearm's length down the upper arm", "messages/body.py",
     "trans[:, chain_rows + 3, 2] = -len1", "trans[:, chain_rows + 3, 2] = -len2",
     "tests/messages/test_body.py"),
    ("a batch of solves hands each its neighbours' runs", "core/lift/batch.py",
     "advance(i, outs[start:start + size])", "advance(i, outs[::-1][start:start + size])",
     "tests/core/lift/test_batch.py"),
    ("a round's prior poses handed to each other's people", "core/lift/batch.py",
     "zip(members, poses, strict=True)", "zip(members, poses[::-1], strict=True)",
     "tests/core/model/test_prior.py"),
    ("a busy node drops the newest waiting frame instead of the oldest", "ros/frame_queue.py",
     "dropped = self._items.popleft() if", "dropped = self._items.pop() if", "tests/ros/test_node_parts.py"),
]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run the changes whose description contains this")
    args = ap.parse_args()
    return run_mutations([m for m in MUTATIONS if args.only in m[0]], PKG)


if __name__ == "__main__":
    sys.exit(main())
