"""The node's parameters YAML, read without ROS, so an offline lift uses a live run's options.

``pose-lifter lift BAG --out OUT --params-file config/lifter.yaml`` reads the same file as
``ros2 run pose_lifter lifter --ros-args --params-file config/lifter.yaml``: the section of the
node (``/**``, ``pose_lifter`` or ``/pose_lifter``, each with ``ros__parameters``) is merged in
that order, like rcl does for a node named ``pose_lifter``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Final

from .core.errors import OptionsError
from .core.options import LifterOptions

__all__ = ["NODE_ONLY", "OfflineParams", "read_params_file"]

#: Node parameters that have no meaning offline (accepted and ignored).
NODE_ONLY: Final[frozenset[str]] = frozenset({
    "publish_markers", "max_skeletons", "max_coordinate", "stats_period", "qos_overrides",
    "frame_id", "marker_lifetime", "use_sim_time",
})
_SECTIONS: Final[tuple[str, ...]] = ("/**", "pose_lifter", "/pose_lifter")


@dataclasses.dataclass(frozen=True)
class OfflineParams:
    """What a params file sets for an offline lift.

    Attributes
    ----------
    options : dict
        :class:`LifterOptions` fields.
    bases_file : str or None
    warm_start, lower_leg_length, default_distance, track_timeout, reinit_ratio : optional
        None when the file does not set them (the last two: the per-track policy,
        :class:`pose_lifter.core.tracking.TrackPolicy`, as in the node).
    ignored : tuple of str
        Unknown parameter names found in the file (node-only ones, :data:`NODE_ONLY`, are not
        listed).
    """

    options: dict[str, Any]
    bases_file: str | None = None
    warm_start: bool | None = None
    lower_leg_length: float | None = None
    default_distance: float | None = None
    ignored: tuple[str, ...] = ()
    track_timeout: float | None = None
    reinit_ratio: float | None = None


def read_params_file(path: str | Path) -> OfflineParams:
    """Read a node params YAML (see the module doc).

    Raises
    ------
    OptionsError
        Unreadable file, no ``pose_lifter`` section, or a value the core refuses.
    """
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise OptionsError(f"cannot read params file {p}: {exc}") from None
    if not isinstance(data, dict):
        raise OptionsError(f"params file {p}: expected a mapping of node names")
    merged: dict[str, Any] = {}
    found = False
    for section in _SECTIONS:
        body = data.get(section)
        if isinstance(body, dict) and isinstance(body.get("ros__parameters"), dict):
            merged.update(body["ros__parameters"])
            found = True
    if not found:
        raise OptionsError(f"params file {p} has no {' / '.join(_SECTIONS)} section with ros__parameters")
    fields = {f.name for f in dataclasses.fields(LifterOptions)}
    options = {k: v for k, v in merged.items() if k in fields}
    try:
        LifterOptions().replace(**options)  # refuse now, with the core's reason
    except OptionsError as exc:
        raise OptionsError(f"params file {p}: {exc}") from None
    own = {"bases_file", "warm_start", "lower_leg_length", "default_distance", "track_timeout",
           "reinit_ratio"}
    ignored = tuple(sorted(k for k in merged if k not in fields and k not in own and k not in NODE_ONLY))

    def get(name: str, kind: type) -> Any:
        if name not in merged:
            return None
        try:
            return kind(merged[name])
        except (TypeError, ValueError):
            raise OptionsError(
                f"params file {p}: {name} = {merged[name]!r} is not a {kind.__name__}") from None

    bases = get("bases_file", str)
    return OfflineParams(options, bases or None, get("warm_start", bool), get("lower_leg_length", float),
                         get("default_distance", float), ignored, get("track_timeout", float),
                         get("reinit_ratio", float))
