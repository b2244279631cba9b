"""The settings table: the node's parameters and ``pose-lifter lift``'s flags, in one table, and
the frame pipeline's settings (:class:`FrameSettings`) that many of them are.

:data:`PARAMS` is every parameter of the lifter node. The solver options among them are
:class:`~pose_lifter.core.options.LifterOptions` fields and take their default, description and
range from the field's metadata (:data:`~pose_lifter.core.options.OPTION_META`), so the node
and the core accept the same values; the node's own settings are declared here (those of the
frame pipeline take their defaults from :class:`FrameSettings`). From this one table come:

* the node's parameter declarations and ``config/lifter.yaml`` (:mod:`pose_lifter.ros.params`);
* ``pose-lifter lift``'s flags (:func:`pose_lifter.offline.flags.add_parameter_flags`): each
  parameter the offline lift honours (:data:`OFFLINE_PARAMS`) is the flag ``--`` + its name with
  ``_`` -> ``-`` (a bool also has its ``--no-`` form), with the node's default and range;
* the offline lift's settings (:meth:`pose_lifter.offline.settings.LiftSettings.from_parameters`)
  and the offline read of a node params file (:func:`read_params_file`): ``pose-lifter lift BAG
  --out OUT --params-file config/lifter.yaml`` reads the same file as ``ros2 run pose_lifter
  lifter --ros-args --params-file config/lifter.yaml``; the section of the node (``/**``,
  ``pose_lifter`` or ``/pose_lifter``, each with ``ros__parameters``) is merged in that order,
  like rcl does for a node named ``pose_lifter``. A key the offline lift cannot honour (a
  parameter of the live node only, :attr:`ParamSpec.live_only`, set to another value than its
  default; an unknown name) is an error naming it.

An option that only the paper mode reads (:data:`~pose_lifter.core.options.MODE_OPTIONS`) says
so in its description, and the core refuses it in another mode (the node's parameter callback
and the CLI alike). This module loads neither numpy nor the solver nor ROS, so the node, the
offline lift and ``pose-lifter --help`` import it cheaply.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Final

from pose_lifter.core.errors import OptionsError
from pose_lifter.core.options import NODE_OPTIONS, OPTION_DEFAULTS, OPTION_META, check_option
from pose_lifter.core.track.defaults import DEFAULT_REINIT_RATIO, DEFAULT_TRACK_TIMEOUT_S, MAX_LAG
from pose_lifter.core.track.placement import DEFAULT_DISTANCE_M, DEFAULT_LEG_LENGTH_M, LEG_LENGTH_RANGE_M

#: Seconds between a frame's stamp and its depth image's at most: a depth stream at 30 Hz has an
#: image within 17 ms of any frame, and 0.02 s never pairs one a whole frame (33 ms) away.
DEFAULT_DEPTH_TOLERANCE_S: Final[float] = 0.02

__all__ = [
    "DEFAULT_DEPTH_TOLERANCE_S",
    "OFFLINE_PARAMS",
    "PARAMS",
    "SPECS",
    "FrameSettings",
    "ParamSpec",
    "read_params_file",
    "unknown_parameters",
]


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
    depth_topic : str
        The depth image registered to the keypoints' camera (:mod:`pose_lifter.messages.depth`;
        ``""``: none live, the bag's one depth topic offline).
    depth_tolerance : float
        Seconds: a frame's depth partner is the image of the nearest stamp at most this far.
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
    depth_topic: str = ""
    depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE_S

    @classmethod
    def read(cls, get: Callable[[str], Any]) -> FrameSettings:
        """From parameter values (``get(name)``), converted to each field's type."""
        kinds = {"bool": bool, "int": int, "float": float, "str": str}
        return cls(**{f.name: kinds[str(f.type)](get(f.name)) for f in fields(cls)})


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """A node parameter: default, description and range; a ``pose-lifter lift`` flag unless
    ``live_only`` (the node declares it with :func:`pose_lifter.ros.params.descriptor`).

    Attributes
    ----------
    name : str
    default : bool, int, float or str
        Its type is the parameter's ROS type.
    description : str
    low, high : float or None
        The descriptor's (closed) range of a number parameter.
    constraints : str
        What the range cannot say (the descriptor's ``additional_constraints``): open bounds,
        choices.
    option : bool
        A :class:`LifterOptions` field: live changes are validated by ``LifterOptions.replace``.
    read_only : bool
        Set at start-up only.
    live_only : str
        Why the offline lift has no such setting (``""``: it honours the parameter, a flag of
        ``pose-lifter lift`` and a key of its params file).
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    constraints: str = ""
    option: bool = False
    read_only: bool = False
    live_only: str = ""

    @classmethod
    def from_option(cls, name: str) -> ParamSpec:
        """The parameter of the :class:`LifterOptions` field ``name``, from its metadata."""
        meta = OPTION_META[name]
        return cls(name, OPTION_DEFAULTS[name], meta.doc, meta.low, meta.high, meta.constraint_text(),
                   option=True)

    @property
    def flag(self) -> str:
        """Its ``pose-lifter lift`` flag: ``--`` + the name with ``_`` -> ``-``."""
        return "--" + self.name.replace("_", "-")

    @property
    def choices(self) -> tuple[str, ...]:
        """The values a choice option takes, exactly as written (``()``: not a choice, or one
        checked otherwise, as ``variant``'s case-insensitive names)."""
        meta = OPTION_META[self.name] if self.option else None
        return meta.choices if meta is not None and meta.check is None else ()

    def range_text(self) -> str:
        """``"[0, 1]"``, ``"(0, 1)"``, ... (``""`` without a range)."""
        if self.option:
            return OPTION_META[self.name].range_text()
        return "" if self.low is None or self.high is None else f"[{self.low:g}, {self.high:g}]"

    def checked(self, value: Any) -> Any:
        """``value`` as the parameter's type (an int where a float is due becomes one), or
        :class:`OptionsError` naming the parameter when its type or range refuses it."""
        kind = type(self.default)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if self.option:
            check_option(self.name, value)
            return value
        ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
        if ok and kind in (int, float):
            ok = (value == value and (self.low is None or value >= self.low)
                  and (self.high is None or value <= self.high))
        if not ok:
            what = f"a{'n' if kind is int else ''} {kind.__name__}"
            raise OptionsError(f"{self.name} must be {what}"
                               f"{' in ' + self.range_text() if self.range_text() else ''}, got {value!r}")
        return value


_FRAME: Final[FrameSettings] = FrameSettings()
#: Pixels of a depth image at most (:data:`pose_lifter.messages.depth.MAX_DEPTH_PIXELS`, not
#: imported: this module loads without numpy).
_MAX_DEPTH_SIDE: Final[str] = "4096 x 4096"

#: Every parameter of the node, in the order of ``config/lifter.yaml``: the bases, the solver
#: options (:data:`~pose_lifter.core.options.NODE_OPTIONS`), then the node's own settings (the frame
#: pipeline's, :class:`~pose_lifter.messages.settings.FrameSettings`, take their defaults from it).
PARAMS: Final[tuple[ParamSpec, ...]] = (
    ParamSpec("bases_file", "", "Pose basis file (.npz, PoseBases.save); empty = the packaged bases of "
              "the mode (paper: subject 01 playground; hybrid: training split, varied proportions)."),
    *(ParamSpec.from_option(name) for name in NODE_OPTIONS),
    ParamSpec("warm_start", _FRAME.warm_start, "Start each tracked person's solve from its previous frame."),
    ParamSpec("track_timeout", _FRAME.track_timeout, "Seconds (input stamps) after which an unseen track is "
              "forgotten.", 0.0, 3600.0),
    ParamSpec("reinit_ratio", _FRAME.reinit_ratio, "A warm solve whose objective exceeds this times the "
              "track's recent median is redone cold (0 = never).", 0.0, 1000.0),
    ParamSpec("lower_leg_length", _FRAME.lower_leg_length, "Right lower-leg (knee-ankle) length in metres: "
              "the metric scale.", *LEG_LENGTH_RANGE_M),
    ParamSpec("default_distance", _FRAME.default_distance, "Depth of the skeleton centroid in metres "
              "when no camera_info has been received.", 0.01, 1000.0),
    ParamSpec("depth_topic", _FRAME.depth_topic, "Depth image registered to the keypoints' camera, e.g. "
              "RealSense's /camera/camera/aligned_depth_to_color/image_raw (sensor_msgs/Image: 16UC1 "
              "millimetres or 32FC1 metres; a name ending in /compressedDepth: image_transport's "
              "compressedDepth CompressedImage). Each frame is paired with the image of the nearest stamp "
              "within depth_tolerance and its people placed in metres on the depth; a frame without one, "
              "or with a refused image (other encoding, size other than camera_info's, no readings, "
              f"absurd range, over {_MAX_DEPTH_SIDE} pixels, corrupt), is lifted from the 2D alone "
              "(counted in /diagnostics). Needs camera_info. Empty: no depth. Offline: empty = the bag's "
              "one Image or CompressedImage topic whose name holds 'depth' (none or several: no depth), "
              "'none' = no depth.", read_only=True),
    ParamSpec("depth_tolerance", _FRAME.depth_tolerance, "Seconds between a frame's header stamp and its "
              "depth image's at most: farther, the frame has no depth partner.", 0.0, 1.0),
    ParamSpec("output_lag", 0, "Frames each answer waits before it is published (0 = none, at once). "
              "Waiting, each skeleton's pose is refined over the frames that came after it, as "
              "pose-lifter lift refines a recording (the measurement update of the smoothed 2D, a "
              "centred window); from 6 frames the lift itself also reads the next 3 (the offline "
              "prior). 3 frames (0.1 s at 30 Hz) take most of the offline accuracy, 6 all of it "
              "(docs/node.md). Held answers are published when the input stops.", 0, MAX_LAG,
              read_only=True),
    ParamSpec("publish_markers", True, "Publish skeleton_markers (visualization_msgs/MarkerArray)."),
    ParamSpec("publish_hri", True, "Publish the tracked people as REP-155 bodies (/humans/bodies/...) and "
              "their frames on /tf.", read_only=True),
    ParamSpec("max_skeletons", _FRAME.max_skeletons, "People lifted per frame at most: of a larger crowd "
              "the largest in the image (the box of their confident joints) are lifted, the rest skipped.",
              1, 10000),
    ParamSpec("max_coordinate", _FRAME.max_coordinate, "Keypoints farther than this from the image origin "
              "(pixels) are absurd: the skeleton is skipped.", 1.0, 1.0e9),
    ParamSpec("solver_threads", 1, "Threads over which each round of a frame's runs of alternations and "
              "the prior's rows are split (the compiled kernels release the GIL; results do not depend on "
              "it); 0 = one per CPU core the node may use. More pay only with cores to spare beside the "
              "detector.",
              0, 256, read_only=True,
              live_only="the offline lift splits its work over processes (pose-lifter lift --workers)"),
    ParamSpec("max_waiting_frames", 1, "Frames that may wait to be lifted; a newer frame drops the oldest "
              "waiting one whole (counted in /diagnostics), so an answer is never more than this many "
              "lifts behind its frame.", 1, 1000, read_only=True,
              live_only="the offline lift answers every frame: none waits"),
    ParamSpec("stats_period", 10.0, "Seconds between statistics log lines (0 = never).", 0.0, 3600.0,
              read_only=True, live_only="the live node's log; the offline lift prints a summary"),
    ParamSpec("frame_id", "camera_optical_frame", "frame_id of the outputs of an input whose header has an "
              "empty one (RViz cannot show an empty frame).",
              live_only="the offline lift copies each input header as it is"),
    ParamSpec("marker_lifetime", 1.0, "Seconds a skeleton marker stays on screen without an update "
              "(0 = until deleted: markers outlive the node).", 0.0, 3600.0),
    ParamSpec("diagnostics_period", 1.0, "Seconds between /diagnostics updates (0 = none).", 0.0, 3600.0,
              read_only=True, live_only="the live node's /diagnostics"),
    # caps on what reaches an output or a log: over-cap input is skipped with a warning
    ParamSpec("max_frame_id_length", _FRAME.max_frame_id_length, "Input header.frame_id longer than this "
              "(characters): the frame is skipped, unanswered (it would be copied into every output "
              "message).", 1, 65536),
    ParamSpec("max_layout_length", _FRAME.max_layout_length, "Input layout names longer than this: the frame "
              "is skipped.", 1, 4096),
    ParamSpec("max_keypoints", _FRAME.max_keypoints, "Skeletons with more keypoints than this are skipped.",
              1, 100000),
    ParamSpec("strict_parameters", False, "Refuse to start when a parameter given at start-up is not one "
              "of the node's (a misspelt name); false: a warning.", read_only=True,
              live_only="the offline lift always refuses an unknown name"),
)
#: :data:`PARAMS` by name.
SPECS: Final[dict[str, ParamSpec]] = {p.name: p for p in PARAMS}
#: The parameters the offline lift honours: ``pose-lifter lift``'s flags and the keys of its
#: params file, in the order of :data:`PARAMS`.
OFFLINE_PARAMS: Final[tuple[ParamSpec, ...]] = tuple(p for p in PARAMS if not p.live_only)
#: Names a ROS params file may hold besides the node's parameters (rcl's own).
_ROS_NAMES: Final[frozenset[str]] = frozenset({"qos_overrides", "use_sim_time"})


def unknown_parameters(names: Iterable[str]) -> str:
    """The warning for start-up parameters that are not the node's (a misspelt name is otherwise
    ignored), with the closest declared name of each; ``""`` when every name is known."""
    unknown = sorted(n for n in names if n not in SPECS and n != "use_sim_time"
                     and not n.startswith("qos_overrides."))
    if not unknown:
        return ""
    hints = []
    for n in unknown:
        close = difflib.get_close_matches(n, list(SPECS), n=1)
        hints.append(f"{n} (did you mean {close[0]}?)" if close else n)
    return f"unknown parameter{'s' if len(unknown) > 1 else ''}: {', '.join(hints)}"


# --------------------------------------------------------------------------- offline


_SECTIONS: Final[tuple[str, ...]] = ("/**", "pose_lifter", "/pose_lifter")


def read_params_file(path: str | Path) -> dict[str, Any]:
    """Read a node params YAML for an offline lift (see the module doc).

    Returns
    -------
    dict
        The parameters of :data:`OFFLINE_PARAMS` the file sets, each checked by its
        :class:`ParamSpec` (type and range; whether the mode reads an option is checked when the
        options are built, with the command line's flags).

    Raises
    ------
    OptionsError
        Unreadable file, no ``pose_lifter`` section, a value a parameter refuses, an unknown
        name, or a parameter of the live node only set to another value than its default (the
        offline lift cannot honour it).
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
    unknown = unknown_parameters(k for k in merged if k not in _ROS_NAMES)
    if unknown:
        raise OptionsError(f"params file {p}: {unknown}")
    values: dict[str, Any] = {}
    for name, value in merged.items():
        spec = SPECS.get(name)
        if spec is None:  # rcl's own
            continue
        try:
            value = spec.checked(value)
        except OptionsError as exc:
            raise OptionsError(f"params file {p}: {exc}") from None
        if not spec.live_only:
            values[name] = value
        elif value != spec.default:
            raise OptionsError(f"params file {p}: {name} = {value!r} cannot be honoured offline "
                               f"({spec.live_only}); remove it or set it to its default {spec.default!r}")
    return values
