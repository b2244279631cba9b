"""The node's parameters: their declarations (:func:`descriptor`), the node's own settings
(:class:`NodeSettings`) and ``config/lifter.yaml`` (:func:`params_yaml`, ``python -m
pose_lifter.ros.node --params-yaml``), from the settings table
(:mod:`pose_lifter.messages.settings`: :data:`PARAMS`, which ``pose-lifter lift``'s flags and the
offline read of a params file come from too).

Nothing here imports ROS at load (the descriptors' message classes are imported when one is
built).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Final

from pose_lifter.core.options import OPTION_PARTS
from pose_lifter.messages.settings import (
    OFFLINE_PARAMS,
    PARAMS,
    SPECS,
    FrameSettings,
    ParamSpec,
    read_params_file,
    unknown_parameters,
)

__all__ = [
    "OFFLINE_PARAMS",
    "PARAMS",
    "SPECS",
    "NodeSettings",
    "ParamSpec",
    "descriptor",
    "params_yaml",
    "read_params_file",
    "unknown_parameters",
]


def descriptor(spec: ParamSpec) -> Any:
    """The ``rcl_interfaces/ParameterDescriptor`` the node declares ``spec`` with."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    d = ParameterDescriptor(name=spec.name, description=spec.description, read_only=spec.read_only,
                            additional_constraints=spec.constraints)
    if spec.low is None or spec.high is None or isinstance(spec.default, bool):
        return d
    if isinstance(spec.default, int):
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    elif isinstance(spec.default, float):
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    return d


@dataclasses.dataclass(frozen=True)
class NodeSettings:
    """The node's own parameters (not solver options), read once per change, not per frame.

    Attributes
    ----------
    frame : FrameSettings
        The frame pipeline's (:mod:`pose_lifter.messages.frame`: the per-track policy, the
        placement, the input caps).
    publish_markers : bool
    frame_id : str
    marker_lifetime : float
    """

    frame: FrameSettings
    publish_markers: bool
    frame_id: str
    marker_lifetime: float

    @classmethod
    def read(cls, get: Callable[[str], Any]) -> NodeSettings:
        """From the node's current parameter values (``get(name)``), converted to each field's type."""
        return cls(FrameSettings.read(get), bool(get("publish_markers")), str(get("frame_id")),
                   float(get("marker_lifetime")))


# --------------------------------------------------------------------------- config/lifter.yaml

_YAML_HEAD: Final[str] = """\
# Parameters of the pose_lifter node (ros2 run pose_lifter lifter --ros-args --params-file <this>).
# Generated from pose_lifter.ros.params.PARAMS (the node's declared defaults; the solver options'
# descriptions and ranges are LifterOptions' field metadata) by
#   python -m pose_lifter.ros.node --params-yaml > config/lifter.yaml
# and checked by tests/ros/test_lifter_graph.py (the node starts with it and reports these values).
# Doubles are written with a decimal point (ROS parameters are typed). Ranges: [a, b] includes
# the bounds, (a, b) refuses them.
/**:
  ros__parameters:
"""

_YAML_TAIL: Final[str] = """\
    # QoS of the topics can be overridden at start-up (QoSOverridingOptions), e.g. a reliable
    # input with a deeper queue for a detector that publishes reliably (with max_waiting_frames
    # as deep, every frame of a bag played faster than the lift is answered):
    # qos_overrides:
    #   /keypoints_2d:
    #     subscription:
    #       reliability: reliable
    #       depth: 20
"""


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float):
        text = repr(value)
        if "e" in text and "." not in text.split("e")[0]:
            mantissa, exponent = text.split("e")
            text = f"{mantissa}.0e{exponent}"
        return text
    return str(value)


#: What a heading of :func:`params_yaml` adds to a part's name.
_PART_NOTES: Final[dict[str, str]] = {
    "paper": " (read only in paper mode: another value than the default is refused in another mode)"}


def params_yaml() -> str:
    """``config/lifter.yaml``: every parameter with its default, description and range; the
    solver options under a heading per part (:data:`~pose_lifter.core.options.OPTION_PARTS`), the
    node's own settings after them."""
    first_of = {names[0]: part for part, names in OPTION_PARTS.items()}
    lines = [_YAML_HEAD]
    for p in PARAMS:
        if p.name in first_of:
            lines.append(f"    # ---- {first_of[p.name]}{_PART_NOTES.get(first_of[p.name], '')}\n")
        elif p.name == "warm_start":
            lines.append("    # ---- the node\n")
        note = " ".join(t for t in (p.description, p.range_text()) if t)
        if p.read_only:
            note += " (read-only: set at start-up)"
        if p.live_only:
            note += f" (live only: {p.live_only})"
        lines.append(f"    # {note}\n    {p.name}: {_yaml_value(p.default)}\n")
    lines.append(_YAML_TAIL)
    return "".join(lines)
