"""The frame pipeline's settings (:class:`FrameSettings`): the per-track policy, the metric
placement and the input caps, as the node and the offline lift both read them.

One class: the node's parameters of these names (:mod:`pose_lifter.ros.params`) and the offline
lift's settings (:class:`pose_lifter.offline.settings.LiftSettings` ``frame``) hold one of it.
This module loads neither numpy nor the solver, so the settings table and ``pose-lifter --help``
import it cheaply.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

from pose_lifter.core.track.defaults import DEFAULT_REINIT_RATIO, DEFAULT_TRACK_TIMEOUT_S
from pose_lifter.core.track.placement import DEFAULT_DISTANCE_M, DEFAULT_LEG_LENGTH_M

__all__ = ["FrameSettings"]


@dataclass(frozen=True)
class FrameSettings:
    """The pipeline's settings: node parameters of the same names (their defaults are these).

    Attributes
    ----------
    warm_start, track_timeout, reinit_ratio
        The per-track policy (:class:`~pose_lifter.core.track.policy.TrackPolicy`).
    lower_leg_length, default_distance : float
        Metres, the placement (:func:`~pose_lifter.core.track.placement.place_in_camera`).
    max_skeletons, max_coordinate, max_frame_id_length, max_layout_length, max_keypoints
        Caps on the input (see :mod:`pose_lifter.messages.frame`).
    """

    warm_start: bool = True
    track_timeout: float = DEFAULT_TRACK_TIMEOUT_S
    reinit_ratio: float = DEFAULT_REINIT_RATIO
    lower_leg_length: float = DEFAULT_LEG_LENGTH_M
    default_distance: float = DEFAULT_DISTANCE_M
    max_skeletons: int = 64
    max_coordinate: float = 1.0e5
    max_frame_id_length: int = 256
    max_layout_length: int = 64
    max_keypoints: int = 512

    @classmethod
    def read(cls, get: Callable[[str], Any]) -> FrameSettings:
        """From parameter values (``get(name)``), converted to each field's type."""
        kinds = {"bool": bool, "int": int, "float": float, "str": str}
        return cls(**{f.name: kinds[str(f.type)](get(f.name)) for f in fields(cls)})
