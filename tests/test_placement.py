"""The metric-placement defaults (0.43 m leg, 5 m distance) are one constant for every entry point."""

from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path

from pose_lifter import cli
from pose_lifter.core import placement
from pose_lifter.offline import lift as offline
from pose_lifter.ros.params import read_params_file

REPO = Path(__file__).resolve().parents[1]


def test_offline_and_cli_use_the_placement_defaults() -> None:
    for fn in (offline.lift_messages, offline.lift_bag):
        params = inspect.signature(fn).parameters
        assert params["leg_length_m"].default == placement.DEFAULT_LEG_LENGTH_M
        assert params["default_distance_m"].default == placement.DEFAULT_DISTANCE_M
    assert offline.DEFAULT_LEG_LENGTH_M is placement.DEFAULT_LEG_LENGTH_M  # still importable there
    args = cli.build_parser().parse_args(["lift", "in.mcap", "--out", "out.mcap"])
    assert args.leg_length == placement.DEFAULT_LEG_LENGTH_M == args.lift_defaults["leg_length"]


def test_the_node_params_file_states_the_same_defaults() -> None:
    params = read_params_file(REPO / "ros2_ws" / "src" / "pose_lifter" / "config" / "lifter.yaml")
    assert params.lower_leg_length == placement.DEFAULT_LEG_LENGTH_M
    assert params.default_distance == placement.DEFAULT_DISTANCE_M


def test_the_placement_module_loads_nothing_else() -> None:
    code = ("import sys, pose_lifter.core.placement; "
            "print(sorted(m for m in sys.modules if m.startswith(('pose_lifter.', 'numpy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['pose_lifter.core.placement']"
