"""The metric-placement defaults (0.43 m leg, 5 m distance) are one constant for every entry point."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pose_lifter import cli
from pose_lifter.core.track import placement
from pose_lifter.messages.frame import FrameSettings
from pose_lifter.offline.lift import frame_settings
from pose_lifter.offline.settings import LiftSettings
from pose_lifter.ros.params import SPECS, read_params_file

REPO = Path(__file__).resolve().parents[3]


def test_offline_and_cli_use_the_placement_defaults() -> None:
    frame = frame_settings(LiftSettings())
    assert frame.lower_leg_length == placement.DEFAULT_LEG_LENGTH_M == FrameSettings().lower_leg_length
    assert frame.default_distance == placement.DEFAULT_DISTANCE_M == FrameSettings().default_distance
    assert SPECS["lower_leg_length"].default == placement.DEFAULT_LEG_LENGTH_M
    assert SPECS["default_distance"].default == placement.DEFAULT_DISTANCE_M
    args = cli.build_parser().parse_args(["lift", "in.mcap", "--out", "out.mcap"])
    assert args.lower_leg_length == placement.DEFAULT_LEG_LENGTH_M


def test_the_node_params_file_states_the_same_defaults() -> None:
    params = read_params_file(REPO / "ros2_ws" / "src" / "pose_lifter" / "config" / "lifter.yaml")
    assert params["lower_leg_length"] == placement.DEFAULT_LEG_LENGTH_M
    assert params["default_distance"] == placement.DEFAULT_DISTANCE_M


@pytest.mark.parametrize("module", ["placement", "defaults"])
def test_the_defaults_modules_load_nothing_else(module: str) -> None:
    """The CLI's parser and the offline settings read the defaults without numpy or the solver
    (``pose_lifter.core`` itself imports its members lazily)."""
    code = (f"import sys, pose_lifter.core.track.{module}; "
            "print(sorted(m for m in sys.modules if m.startswith(('pose_lifter.', 'numpy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == f"['pose_lifter.core', 'pose_lifter.core.track', 'pose_lifter.core.track.{module}']"


def test_a_frames_people_are_corrected_for_perspective_as_each_alone() -> None:
    """perspective_corrected_rows: each row is what ``m + (x - m)(1 + z s / f)`` gives it, and a
    row whose depths would put a joint behind the camera (or are not finite) keeps its 2D."""
    from pose_lifter.core.track.placement import perspective_corrected_rows

    rng = np.random.default_rng(2)
    n = 5
    x = rng.normal(300.0, 50.0, (n, 12, 2))
    depths = rng.normal(0.0, 0.5, (n, 12))
    scale, focal = rng.uniform(50.0, 200.0, n), rng.uniform(500.0, 900.0, n)
    centre = x.mean(axis=1)
    depths[1, 3] = -0.95 * focal[1] / scale[1]  # the joint's depth a twentieth of the centroid's
    depths[3, 0] = np.nan
    got = perspective_corrected_rows(x, focal, depths, scale, centre)
    for i in range(n):
        if i in (1, 3):
            assert np.array_equal(got[i], x[i])
            continue
        ratio = 1.0 + depths[i] * scale[i] / focal[i]
        np.testing.assert_allclose(got[i], centre[i] + (x[i] - centre[i]) * ratio[:, None], rtol=1e-14)
        assert not np.allclose(got[i], x[i])
