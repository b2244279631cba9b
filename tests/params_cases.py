"""A params file of non-default values, one of every parameter type, shared by the node's graph
test (tests/ros/test_lifter_graph.py) and the offline lift's (tests/offline/test_lift_cli.py): each must
reach the lifter, so code that ignored the file would fail both."""

from __future__ import annotations

from typing import Any, Final

#: The node's section of the file (as ``ros2 run ... --params-file`` and ``--params-file`` take it):
#: parameters the offline lift honours too.
NON_DEFAULT_PARAMS: Final[dict[str, Any]] = {
    "warm_start": False, "outlier_passes": 1, "variant": "L1WANS", "default_distance": 4.25,
    "lower_leg_length": 0.41, "max_keypoints": 100, "publish_markers": False,
}
#: Parameters of the live node only, at non-default values: the node takes them, the offline
#: lift refuses each by name (it cannot honour it).
LIVE_ONLY_PARAMS: Final[dict[str, Any]] = {"frame_id": "yaml_frame"}
