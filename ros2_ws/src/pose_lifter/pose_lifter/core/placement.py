"""Defaults of the metric placement of a lifted pose, shared by the node, the offline lift and the CLI.

A lifted pose is in units of its right lower leg; :func:`pose_lifter.messages.convert.place_in_camera`
makes it metric with a leg length and puts its centroid at the depth the camera scale gives, or
at a default distance when no camera intrinsics are known. This module imports nothing, so the
CLI's parser can read the defaults without loading the solver.
"""

from __future__ import annotations

from typing import Final

__all__ = ["DEFAULT_DISTANCE_M", "DEFAULT_LEG_LENGTH_M", "LEG_LENGTH_RANGE_M"]

#: Right lower leg (knee-ankle) in metres that makes lifted poses metric (CMU adults: 0.41-0.44).
DEFAULT_LEG_LENGTH_M: Final[float] = 0.43
#: Accepted leg lengths in metres (the node's ``lower_leg_length`` and ``--leg-length``).
LEG_LENGTH_RANGE_M: Final[tuple[float, float]] = (0.05, 2.0)
#: Depth of the pose centroid in metres when no CameraInfo is available.
DEFAULT_DISTANCE_M: Final[float] = 5.0
