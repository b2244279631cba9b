"""The live lifter: a ROS 2 node that lifts every 2D skeleton it receives to 3D.

One frame, from subscription to publication (:meth:`LifterNode.on_keypoints`):

1. ``keypoints_2d`` (``pose_lifter_msgs/Skeleton2DArray``, sensor-data QoS) arrives.
2. Each skeleton is converted to the paper's 12 joints (:func:`messages.skeleton2d_to_arrays`),
   checked, and lifted by the core :class:`~pose_lifter.core.Lifter`: warm-started from the same
   track's previous solution when there is one, cold (multi-start) otherwise.
3. The lift is placed in the camera optical frame in metres (:func:`messages.place_in_camera`:
   depth from the weak-perspective scale and ``camera_info``'s focal length, or a parameter
   distance without ``camera_info``).
4. ``skeletons_3d`` (``Skeleton3DArray``) is published with the input's header (stamp and
   frame), then ``skeleton_markers`` (``visualization_msgs/MarkerArray``).

Every input frame gets exactly one ``Skeleton3DArray`` answer with the same header. A skeleton
that cannot be lifted (bad input or a failed solve) is left out of it with one rate-limited
warning; the other skeletons of the frame are still published, and a frame with no liftable
skeleton is answered with an empty array. Nothing non-finite is ever published.

Parameters (declared once, with ranges; see ``config/lifter.yaml``) are validated on every live
change by the same :class:`~pose_lifter.core.LifterOptions` the core uses; a bad value is refused
with the core's reason.
"""

from __future__ import annotations

import difflib
import os
import signal
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any, Final, NoReturn

import numpy as np
import rclpy
from numpy.typing import NDArray
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.signals import SignalHandlerOptions

from . import diagnostics, messages, placement
from .core import Lifter, LifterOptions, PoseBases, PoseLifterError
from .core._jit import HAVE_NUMBA
from .core.bases import default_bases_path
from .core.errors import InvalidInputError
from .core.layouts import Layout, get_layout
from .core.tracking import OutOfOrderFrameError, TrackPolicy

__all__ = ["PARAMS", "LifterNode", "ParamSpec", "main", "params_yaml"]

NODE_NAME: Final[str] = "pose_lifter"
MARKER_NS: Final[str] = "pose_lifter"
#: Seconds between two warnings of one kind (each kind is warned at least once per period).
WARN_PERIOD: Final[float] = 5.0
#: Characters of a warning at most (input-derived text is never logged whole).
MAX_WARNING_CHARS: Final[int] = 300


class StartupError(Exception):
    """The node cannot start (bad parameter, basis file): one [FATAL] line and exit code 1."""


class SkipSkeleton(Exception):
    """One skeleton of a frame is left out of the answer.

    Parameters
    ----------
    kind : str
        Short category, counted in the statistics line (e.g. ``"duplicate track id"``).
    text : str
        The warning.
    """

    def __init__(self, kind: str, text: str) -> None:
        super().__init__(text)
        self.kind = kind


@dataclass(frozen=True)
class ParamSpec:
    """A node parameter: default, description and range.

    ``option`` parameters carry the name of a :class:`LifterOptions` field; their default is
    that field's default and their live changes are validated by ``LifterOptions.replace``.
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    option: bool = False
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, description=self.description, read_only=self.read_only)
        if self.low is not None and self.high is not None:
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)]
            elif isinstance(self.default, float):
                d.floating_point_range = [
                    FloatingPointRange(from_value=float(self.low), to_value=float(self.high), step=0.0)
                ]
        return d


_DEFAULT_OPTIONS: Final[LifterOptions] = LifterOptions()


def _opt(name: str, description: str, low: float | None = None, high: float | None = None) -> ParamSpec:
    return ParamSpec(name, getattr(_DEFAULT_OPTIONS, name), description, low, high, option=True)


#: Every parameter of the node, in the order of ``config/lifter.yaml``.
PARAMS: Final[tuple[ParamSpec, ...]] = (
    ParamSpec("bases_file", "", "Pose basis file (.npz, PoseBases.save); empty = the packaged bases of "
              "the mode (paper: subject 01 playground; hybrid: training split, varied proportions)."),
    _opt("variant", "Paper variant: 'full' (= L1WAWS) or L1WAWS, L1WANS, ..., L2NANS."),
    _opt("theta", "Weight of ||alpha||_1 (sparsity), right-lower-leg units.", 0.0, 100.0),
    _opt("max_alternations", "Camera/pose alternations per solve.", 1, 1000),
    _opt("alternation_tol", "Stop alternating below this relative objective decrease, in (0, 1).", 0.0, 1.0),
    _opt("pose_max_iter", "Iteration cap of the pose-step ADM.", 1, 10000),
    _opt("pose_tol", "Relative residual tolerance of the pose-step ADM, in (0, 1).", 0.0, 1.0),
    _opt("inner_max_iter", "Iteration cap of the inner alpha-step ADM.", 1, 10000),
    _opt("inner_tol", "Tolerance of the inner alpha-step ADM, in (0, 1).", 0.0, 1.0),
    _opt("camera_max_iter", "Iteration cap of the camera-step ADM.", 1, 10000),
    _opt("camera_tol", "Tolerance of the camera-step ADM, in (0, 1).", 0.0, 1.0),
    _opt("n_starts", "Starts of a cold (multi-start) solve; 1 = mean pose only.", 1, 1000),
    _opt("n_refine", "Cold starts continued to convergence after one screening alternation each.", 1, 1000),
    _opt("screen_pose_max_iter", "Pose-ADM iteration cap of the screening alternation of cold starts.",
         1, 10000),
    _opt("warm_flip", "Warm solves also try the depth-mirrored previous pose (weak-perspective ambiguity)."),
    _opt("warm_flip_screen",
         "The mirrored start is continued only if one alternation already beats the warm one."),
    _opt("confidence_threshold", "Keypoints with lower confidence are treated as missing.", 0.0, 1.0),
    _opt("min_visible_joints", "Skip a skeleton with fewer visible model joints.", 3, 12),
    _opt("limb_proportions", "Limb-length targets: 'bases' (training mean) or 'anthropometric'."),
    _opt("alpha_solver", "Alpha-step solver: 'riemannian' (Newton on the limb spheres), 'newton' (SQP) "
         "or 'admm' (the paper's lifted inner ADM)."),
    _opt("alpha_prox", "Proximal weight of the 'riemannian' alpha-step (0 = none).", 0.0, 1000.0),
    _opt("mode", "'hybrid' (the learned prior inside the paper's robust fit), 'paper' (the paper's "
         "method alone) or 'learned' (the prior alone)."),
    _opt("prior_file", "Learned prior weights (.npz, PosePrior.save); empty = the packaged default."),
    _opt("temporal_prior", "Hybrid/learned, tracked: frames that follow a track's previous ones use the "
         "causal temporal prior (last 4 frames, trained at 30 Hz)."),
    _opt("temporal_prior_file", "Temporal prior weights (.npz); empty = the packaged default."),
    _opt("prior_weight_xy", "Hybrid: weight of the prior's image positions in the L1 objective.",
         0.0, 1000.0),
    _opt("prior_weight_z", "Hybrid: weight of the prior's depths in the L1 objective.", 0.0, 1000.0),
    _opt("outlier_threshold", "Hybrid: reprojection residual (leg lengths) above which a visible joint "
         "is dropped as a confident outlier and the prior re-run without it (0 = off).", 0.0, 1000.0),
    _opt("outlier_threshold_gated", "Hybrid: outlier_threshold on tracked frames the outlier gate screened.",
         0.0, 1000.0),
    _opt("hybrid_alternations", "Hybrid: alternations of each run at most.", 1, 1000),
    _opt("hybrid_pose_max_iter", "Hybrid: pose-step ADM iterations at most per alternation.", 1, 100000),
    _opt("hybrid_flip_warm", "Hybrid: also score the depth-mirrored hypothesis on warm frames."),
    _opt("outlier_passes", "Hybrid: outlier passes at most.", 1, 100),
    _opt("temporal_weight", "Hybrid, tracked: weight of the previous frame's pose in the prior "
         "target (scaled by the track's 2D noise).", 0.0, 1000.0),
    _opt("missing_temporal_weight", "Hybrid, tracked: weight of the previous frame's pose in the prior "
         "target of a joint missing on this frame (0 = as the others).", 0.0, 1000.0),
    _opt("outlier_gate", "Hybrid, tracked: a joint farther than this (leg lengths) from where the track "
         "puts it is missing for that frame (0 = off).", 0.0, 1000.0),
    _opt("fill_missing_frames", "Hybrid, tracked: a joint missing for at most this many frames in a row "
         "is given to the learned prior where the track predicts it (0 = off).", 0, 1000),
    _opt("prior_limbs", "Hybrid, tracked: limb constraints with the track's estimated proportions."),
    _opt("warm_competes", "Hybrid: warm solves also start from the previous frame's pose (screened)."),
    ParamSpec("warm_start", True, "Start each tracked person's solve from its previous frame."),
    ParamSpec("track_timeout", 1.0, "Seconds (input stamps) after which an unseen track is forgotten.",
              0.0, 3600.0),
    ParamSpec("reinit_ratio", 2.0, "A warm solve whose objective exceeds this times the track's recent "
              "median is redone cold (0 = never).", 0.0, 1000.0),
    ParamSpec("lower_leg_length", placement.DEFAULT_LEG_LENGTH_M,
              "Right lower-leg (knee-ankle) length in metres: the metric scale.",
              *placement.LEG_LENGTH_RANGE_M),
    ParamSpec("default_distance", placement.DEFAULT_DISTANCE_M, "Depth of the skeleton centroid in metres "
              "when no camera_info has been received.", 0.01, 1000.0),
    ParamSpec("publish_markers", True, "Publish skeleton_markers (visualization_msgs/MarkerArray)."),
    ParamSpec("max_skeletons", 64, "Skeletons lifted per frame at most; the rest are skipped.", 1, 10000),
    ParamSpec("max_coordinate", 1.0e5, "Keypoints farther than this from the image origin (pixels) "
              "are absurd: the skeleton is skipped.", 1.0, 1.0e9),
    ParamSpec("stats_period", 10.0, "Seconds between statistics log lines (0 = never).", 0.0, 3600.0,
              read_only=True),
    ParamSpec("frame_id", "camera_optical_frame", "frame_id of the outputs of an input whose header has an "
              "empty one (RViz cannot show an empty frame)."),
    ParamSpec("marker_lifetime", 1.0, "Seconds a skeleton marker stays on screen without an update "
              "(0 = until deleted: markers outlive the node).", 0.0, 3600.0),
    ParamSpec("diagnostics_period", 1.0, "Seconds between /diagnostics updates (0 = none).", 0.0, 3600.0,
              read_only=True),
    # caps on what reaches an output or a log (issue 10): over-cap input is skipped with a warning
    ParamSpec("max_frame_id_length", 256, "Input header.frame_id longer than this (characters): the frame "
              "is skipped, unanswered (it would be copied into every output message).", 1, 65536),
    ParamSpec("max_layout_length", 64, "Input layout names longer than this: the frame is skipped.", 1, 4096),
    ParamSpec("max_keypoints", 512, "Skeletons with more keypoints than this are skipped.", 1, 100000),
    ParamSpec("strict_parameters", False, "Refuse to start when a parameter given at start-up is not one "
              "of the node's (a misspelt name); false: a warning.", read_only=True),
)
_SPECS: Final[dict[str, ParamSpec]] = {p.name: p for p in PARAMS}

_YAML_HEAD: Final[str] = """\
# Parameters of the pose_lifter node (ros2 run pose_lifter lifter --ros-args --params-file <this>).
# Generated from pose_lifter.node.PARAMS (the node's declared defaults) by
#   python -m pose_lifter.node --params-yaml > config/lifter.yaml
# and checked by tests/ros/test_lifter_graph.py (the node starts with it and reports these values).
# Doubles are written with a decimal point (ROS parameters are typed).
/**:
  ros__parameters:
"""

_YAML_TAIL: Final[str] = """\
    # QoS of the topics can be overridden at start-up (QoSOverridingOptions), e.g. a reliable
    # input with a deeper queue for a detector that publishes reliably:
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


def params_yaml() -> str:
    """``config/lifter.yaml``: every parameter with its default, description and range."""
    lines = [_YAML_HEAD]
    for p in PARAMS:
        note = p.description
        if p.low is not None and p.high is not None:
            note += f" [{p.low:g}, {p.high:g}]"
        if p.read_only:
            note += " (read-only: set at start-up)"
        lines.append(f"    # {note}\n    {p.name}: {_yaml_value(p.default)}\n")
    lines.append(_YAML_TAIL)
    return "".join(lines)


@dataclass(frozen=True)
class NodeSettings:
    """The node's own parameters (not solver options), read once per change, not per frame."""

    warm_start: bool
    track_timeout: float
    reinit_ratio: float
    lower_leg_length: float
    default_distance: float
    publish_markers: bool
    max_skeletons: int
    max_coordinate: float
    frame_id: str
    marker_lifetime: float
    max_frame_id_length: int
    max_layout_length: int
    max_keypoints: int



@dataclass
class FrameStats:
    """Counters between two statistics log lines."""

    started: float = field(default_factory=time.monotonic)
    frames: int = 0
    lifted: int = 0
    warm: int = 0
    latencies: list[float] = field(default_factory=list)
    solve_times: list[float] = field(default_factory=list)
    skipped: Counter[str] = field(default_factory=Counter)
    clipped: int = 0  # skeletons lifted with confidences clipped into [0, 1]


def _all_finite(*values: Any) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(v, dtype=np.float64)))) for v in values)


class LifterNode(Node):
    """Lifts ``keypoints_2d`` to ``skeletons_3d`` (+ ``skeleton_markers``), see the module doc.

    Parameters
    ----------
    **kwargs
        Passed to :class:`rclpy.node.Node` (e.g. ``parameter_overrides``).
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._types = messages.rclpy_types()
        for spec in PARAMS:
            self.declare_parameter(spec.name, spec.default, spec.descriptor())
        self._last_warned: dict[str, float] = {}  # kind -> monotonic time of its last warning
        self._check_unknown_parameters()
        self._callbacks_added = False
        if not self._deferred_start():  # the lifecycle node configures and activates on request
            self.configure_lifter()
            self.activate_lifter()

    def _deferred_start(self) -> bool:
        """False: the plain node starts lifting in its constructor (see lifecycle_node.py)."""
        return False

    def configure_lifter(self) -> None:
        """Load the bases, build the solver (compile or load its kernels), create the publishers."""
        # Invalid start-up values are fatal with the core's message (there is nothing to run).
        options = _DEFAULT_OPTIONS.replace(**{p.name: self._param(p.name) for p in PARAMS if p.option})
        self._bases = self._load_bases(self._param("bases_file"), options.mode)
        self._lifter = Lifter(self._bases, options)
        # compile (first start after an install: ~25 s) or load the solver kernels before the
        # topics exist, so the first frame is not the one that pays for it
        kernels = "numba-compiled" if HAVE_NUMBA else "plain Python (pip install numba: ~3x faster)"
        self.get_logger().info(f"solver ready in {self._lifter.warm_up():.1f} s, {kernels} kernels")
        self._pending: tuple[PoseBases, Lifter] | None = None
        self._settings = self._read_settings()

        self._policy = self._make_policy()
        self._shown_tracks: set[int] = set()  # track ids with markers on screen
        self._shown_untracked = 0  # untracked skeletons with markers on screen
        self._intrinsics: tuple[tuple[float, float], tuple[float, float]] | None = None
        self._stats = FrameStats()

        qos_override = QoSOverridingOptions.with_default_policies()
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._pub_skeletons = self.create_publisher(
            self._types.Skeleton3DArray, "skeletons_3d", reliable, qos_overriding_options=qos_override)
        self._pub_markers = self.create_publisher(
            self._types.MarkerArray, "skeleton_markers", reliable, qos_overriding_options=qos_override)
        self._markers_cleared = False  # the first MarkerArray starts with DELETEALL
        self._diagnostics = diagnostics.LifterDiagnostics(self, float(self._param("diagnostics_period")))
        if not self._callbacks_added:
            self.add_on_set_parameters_callback(self._validate_parameters)
            self.add_post_set_parameters_callback(self._apply_parameters)
            self._callbacks_added = True

    def activate_lifter(self) -> None:
        """Subscribe to the inputs (and start the statistics timer): lifting starts."""
        qos_override = QoSOverridingOptions.with_default_policies()
        options = self._lifter.options
        # camera_info first: when an image's camera_info and keypoints are both waiting, the
        # executor serves subscriptions in creation order, so the keypoints see that camera_info
        self._sub_camera_info = self.create_subscription(
            self._types.CameraInfo, "camera_info", self.on_camera_info, qos_profile_sensor_data,
            qos_overriding_options=qos_override)
        self._sub_keypoints = self.create_subscription(
            self._types.Skeleton2DArray, "keypoints_2d", self.on_keypoints, qos_profile_sensor_data,
            qos_overriding_options=qos_override)
        period = float(self._param("stats_period"))
        self._stats_timer = self.create_timer(period, self._log_stats) if period > 0 else None
        self.get_logger().info(
            f"lifting {self._sub_keypoints.topic_name} -> {self._pub_skeletons.topic_name}: "
            f"{self._bases.method} bases (k={self._bases.n_bases}), variant {options.variant}, "
            f"{options.n_starts} cold starts, warm start {'on' if self._param('warm_start') else 'off'}"
        )

    def deactivate_lifter(self) -> None:
        """Unsubscribe (the solver and the publishers stay: activating again is immediate)."""
        for entity in (self._sub_keypoints, self._sub_camera_info):
            self.destroy_subscription(entity)
        if self._stats_timer is not None:
            self.destroy_timer(self._stats_timer)
            self._stats_timer = None
        self._policy.clear()

    def cleanup_lifter(self) -> None:
        """Destroy the publishers and the diagnostics (back to the state after the constructor)."""
        self._diagnostics.close()
        for pub in (self._pub_skeletons, self._pub_markers):
            self.destroy_publisher(pub)
        self._policy.clear()

    # ------------------------------------------------------------------ parameters

    def _param(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _read_settings(self) -> NodeSettings:
        return NodeSettings(
            warm_start=bool(self._param("warm_start")),
            track_timeout=float(self._param("track_timeout")),
            reinit_ratio=float(self._param("reinit_ratio")),
            lower_leg_length=float(self._param("lower_leg_length")),
            default_distance=float(self._param("default_distance")),
            publish_markers=bool(self._param("publish_markers")),
            max_skeletons=int(self._param("max_skeletons")),
            max_coordinate=float(self._param("max_coordinate")),
            frame_id=str(self._param("frame_id")),
            marker_lifetime=float(self._param("marker_lifetime")),
            max_frame_id_length=int(self._param("max_frame_id_length")),
            max_layout_length=int(self._param("max_layout_length")),
            max_keypoints=int(self._param("max_keypoints")),
        )

    def _make_policy(self) -> TrackPolicy:
        """The core's per-track policy (warm starts, re-initialisation, expiry) with the
        current lifter and settings."""
        st = self._settings
        return TrackPolicy(self._lifter, st.track_timeout, st.warm_start, st.reinit_ratio)

    @staticmethod
    def _load_bases(path: str, mode: str) -> PoseBases:
        """``bases_file``, or the packaged bases of ``mode`` when it is empty."""
        return PoseBases.load(Path(path).expanduser() if path else default_bases_path(mode))

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: build the new options (and bases) or refuse with the reason."""
        ours = [p for p in params if p.name in _SPECS]
        if not ours:
            return SetParametersResult(successful=True)
        try:
            bases = self._bases
            changes = {p.name: p.value for p in ours if _SPECS[p.name].option}
            options = self._lifter.options.replace(**changes) if changes else self._lifter.options
            new_file = next((str(p.value) for p in ours if p.name == "bases_file"), None)
            path = self._param("bases_file") if new_file is None else new_file
            if new_file is not None or (not path and options.mode != self._lifter.options.mode):
                # a new file, or the packaged bases of another mode
                bases = self._load_bases(path, options.mode)
            if options.n_starts > bases.start_alphas.shape[0]:
                # not an error: the lifter uses the starts it has
                self.get_logger().info(
                    f"n_starts={options.n_starts} but the bases carry {bases.start_alphas.shape[0]} starts")
            # built here, not in the post-set callback: whatever the new bases and options
            # refuse (e.g. limb targets) is refused now, and the running solver stays as it was
            lifter = (Lifter(bases, options) if bases is not self._lifter.bases
                      or options != self._lifter.options else self._lifter)
        except Exception as err:  # nothing may raise out of a parameter callback (it kills the node)
            self._pending = None
            reason = str(err) if isinstance(err, PoseLifterError | OSError | ValueError) else repr(err)
            self.get_logger().warning(f"parameter change refused: {reason[:1000]}")
            return SetParametersResult(successful=False, reason=reason)
        self._pending = (bases, lifter)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Post-set callback: switch to what :meth:`_validate_parameters` built (cannot fail)."""
        self._settings = self._read_settings()
        if self._pending is None:
            return
        bases, lifter = self._pending
        self._pending = None
        if bases is not self._bases:
            self._bases = bases
            self._policy.clear()  # coefficients of other bases are meaningless
        self._lifter = lifter
        st = self._settings
        self._policy.configure(self._lifter, st.track_timeout, st.warm_start, st.reinit_ratio)
        names = ", ".join(f"{p.name}={p.value!r}" for p in params if p.name in _SPECS)
        if names:
            self.get_logger().info(f"parameters changed: {names}")

    # ------------------------------------------------------------------ callbacks

    def on_camera_info(self, msg: Any) -> None:
        """Keep the latest intrinsics (a bad CameraInfo is ignored with a warning)."""
        try:
            self._intrinsics = messages.intrinsics_from_camera_info(msg)
        except (InvalidInputError, ValueError, TypeError) as err:
            self._warn_skip("camera_info", str(err))

    def on_keypoints(self, msg: Any) -> None:
        """Lift one frame and publish its answer (always, even when every skeleton is skipped)."""
        received = time.perf_counter()
        if self._over_cap(msg):
            return
        if not msg.header.frame_id:  # RViz cannot place an empty frame: the frame_id parameter
            msg.header.frame_id = self._settings.frame_id
        stamp_ns = messages.stamp_to_ns(msg.header.stamp)
        if stamp_ns == 0:  # detectors that leave the stamp empty: use the arrival time
            stamp_ns = self.get_clock().now().nanoseconds
        lifted: list[Any] = []
        shown: list[tuple[int, NDArray[np.float64]]] = []
        try:
            layout = get_layout(str(msg.layout))
            skeletons: Sequence[Any] = msg.skeletons
            limit = self._settings.max_skeletons
            if len(skeletons) > limit:
                self._warn_skip("too many skeletons", f"{len(skeletons)} skeletons in one frame, "
                                f"lifting the first {limit} (max_skeletons)")
                skeletons = skeletons[:limit]
            seen: set[int] = set()
            for skel in skeletons:
                try:
                    out, joints = self._lift_one(skel, layout, stamp_ns, seen)
                except SkipSkeleton as err:
                    self._warn_skip(err.kind, f"skeleton skipped: {err}")
                    continue
                except PoseLifterError as err:
                    self._warn_skip(type(err).__name__, f"skeleton skipped: {err}")
                    continue
                except Exception as err:  # a solver bug must not cost the other skeletons
                    self._warn_skip("unexpected", f"skeleton skipped after an unexpected error: {err!r}")
                    continue
                lifted.append(out)
                shown.append((int(out.track_id), joints))
        except PoseLifterError as err:  # e.g. unknown layout: the whole frame is unusable
            self._warn_skip(type(err).__name__, f"frame skipped: {err}")
        except Exception as err:  # never let one frame kill the node
            self._warn_skip("unexpected", f"frame skipped after an unexpected error: {err!r}")
        self._policy.expire(stamp_ns)

        self._pub_skeletons.publish(messages.skeletons3d_array(msg.header, lifted, self._types))
        if self._settings.publish_markers:
            self._publish_markers(msg.header, shown)
        self._stats.frames += 1
        self._stats.lifted += len(lifted)
        self._stats.warm += sum(1 for s in lifted if s.warm_started)
        self._stats.solve_times.extend(float(s.solve_time) for s in lifted)
        self._stats.latencies.append(time.perf_counter() - received)
        self._diagnostics.frame(lifted, time.perf_counter() - received)

    def _lift_one(
        self, skel: Any, layout: Layout, stamp_ns: int, seen: set[int]
    ) -> tuple[Any, NDArray[np.float64]]:
        """Lift one skeleton -> (``Skeleton3D``, metric joints (12, 3)); raise to skip it."""
        track_id = int(skel.track_id)
        if len(skel.keypoints) > self._settings.max_keypoints:
            raise SkipSkeleton("too many keypoints", f"track {track_id}: {len(skel.keypoints)} keypoints, "
                               f"more than max_keypoints={self._settings.max_keypoints}")
        if track_id >= 0:
            if track_id in seen:
                raise SkipSkeleton("duplicate track id",
                                   f"duplicate track id {track_id} in one frame: later copy skipped")
            seen.add(track_id)
        points, confidence = messages.skeleton2d_to_arrays(skel, layout.name)
        confidence = self._clip_confidence(confidence, track_id)
        visible = confidence >= self._lifter.options.confidence_threshold
        if not np.any(visible):
            raise SkipSkeleton("no confident keypoints",
                               f"track {track_id}: no keypoint above the confidence threshold")
        limit = self._settings.max_coordinate
        if np.max(np.abs(points[visible])) > limit:
            raise SkipSkeleton("absurd coordinates",
                               f"track {track_id}: keypoints beyond {limit:g} px (max_coordinate)")

        start = time.perf_counter()
        try:
            tracked = self._policy.lift(track_id, stamp_ns, points, confidence)
        except OutOfOrderFrameError as err:
            raise SkipSkeleton("out-of-order stamp", str(err)) from err
        solve_time = time.perf_counter() - start
        result = tracked.result
        if not _all_finite(result.pose_camera, result.alpha, result.camera.rotation, result.camera.scale,
                           result.camera.translation, result.objective, result.reprojection_error):
            raise SkipSkeleton("non-finite result", f"track {track_id}: the solve returned non-finite values")
        focal, centre = self._intrinsics if self._intrinsics is not None else (None, None)
        joints = messages.place_in_camera(result, self._settings.lower_leg_length, focal, centre,
                                          self._settings.default_distance)
        if not _all_finite(joints):
            raise SkipSkeleton("non-finite result", f"track {track_id}: non-finite metric joints")
        out = messages.result_to_skeleton3d(result, track_id, joints, self._types,
                                            solve_time=solve_time, warm_started=tracked.warm_started)
        return out, joints

    def _publish_markers(self, header: Any, shown: list[tuple[int, NDArray[np.float64]]]) -> None:
        tracked = {t for t, _ in shown if t >= 0}
        untracked = sum(1 for t, _ in shown if t < 0)
        gone = sorted(self._shown_tracks - tracked)
        markers = messages.skeleton_markers(header, shown, MARKER_NS, self._settings.marker_lifetime,
                                            self._types, deleted_track_ids=gone)
        if not self._markers_cleared:  # what an earlier run left on screen goes first
            markers.markers[:0] = messages.delete_all_markers(header, MARKER_NS, self._types)
            self._markers_cleared = True
        # untracked skeletons have ids -1, -2, ... by position: delete the positions now unused
        for position in range(untracked, self._shown_untracked):
            for kind in ("joints", "bones"):
                markers.markers.append(self._types.Marker(
                    header=header, ns=f"{MARKER_NS}/{kind}", id=-1 - position,
                    action=self._types.Marker.DELETE))
        self._shown_tracks = tracked
        self._shown_untracked = untracked
        self._pub_markers.publish(markers)

    # ------------------------------------------------------------------ diagnostics

    def _warn_skip(self, kind: str, text: str) -> None:
        """Count a skipped input and warn, rate-limited per kind (each kind at least once a period)."""
        self._stats.skipped[kind] += 1
        self._diagnostics.skipped(kind)
        self._warn_kind(kind, text)

    def _warn_kind(self, kind: str, text: str) -> None:
        now = time.monotonic()
        last = self._last_warned.get(kind)
        if last is not None and now - last < WARN_PERIOD:
            return
        self._last_warned[kind] = now
        self.get_logger().warning(f"{text[:MAX_WARNING_CHARS]} (warnings of this kind are rate-limited "
                                  f"to one per {WARN_PERIOD:g} s; counts in the stats line)")

    def _over_cap(self, msg: Any) -> bool:
        """Skip (unanswered) a frame whose strings would be copied into outputs or logs."""
        s = self._settings
        n_frame, n_layout = len(msg.header.frame_id), len(msg.layout)
        if n_frame > s.max_frame_id_length:
            self._warn_skip("frame_id too long", f"frame skipped, unanswered: header.frame_id of {n_frame} "
                            f"characters, more than max_frame_id_length={s.max_frame_id_length}")
            return True
        if n_layout > s.max_layout_length:
            self._warn_skip("layout too long", f"frame skipped, unanswered: layout name of {n_layout} "
                            f"characters, more than max_layout_length={s.max_layout_length}")
            return True
        return False

    def _clip_confidence(self, confidence: NDArray[np.float64], track_id: int) -> NDArray[np.float64]:
        """Confidences outside [0, 1] are clipped into it, with a warning (they weigh the solve)."""
        outside = (confidence < 0.0) | (confidence > 1.0)
        if not np.any(outside):
            return confidence
        self._stats.clipped += 1
        worst = float(confidence[outside][np.argmax(np.abs(confidence[outside]))])
        self._warn_kind("confidence outside [0, 1]", f"track {track_id}: {int(outside.sum())} confidences "
                        f"outside [0, 1] (e.g. {worst:.3g}) clipped into it")
        return np.clip(confidence, 0.0, 1.0)

    def _check_unknown_parameters(self) -> None:
        """Report start-up parameters that are not the node's (a misspelt name is otherwise ignored)."""
        overrides = getattr(self, "_parameter_overrides", {})
        unknown = sorted(n for n in overrides if n not in _SPECS and n != "use_sim_time"
                         and not n.startswith("qos_overrides."))
        if not unknown:
            return
        hints = []
        for n in unknown:
            close = difflib.get_close_matches(n, list(_SPECS), n=1)
            hints.append(f"{n} (did you mean {close[0]}?)" if close else n)
        text = f"unknown parameter{'s' if len(unknown) > 1 else ''}: {', '.join(hints)}"
        if self._param("strict_parameters"):
            raise StartupError(f"{text} (strict_parameters is true)")
        self.get_logger().warning(f"{text}; ignored (strict_parameters:=true refuses them)")

    def _log_stats(self) -> None:
        s = self._stats
        elapsed = max(time.monotonic() - s.started, 1e-9)
        if s.frames == 0 and not s.skipped:
            self._stats = FrameStats()
            return
        lat = np.asarray(s.latencies) * 1e3
        solve = np.asarray(s.solve_times) * 1e3
        text = (f"{s.frames} frames ({s.frames / elapsed:.1f} Hz), {s.lifted} skeletons "
                f"({s.warm} warm)")
        if lat.size:  # per frame, callback in -> answer published
            text += (f", latency median {np.median(lat):.1f} ms p95 {np.percentile(lat, 95):.1f} ms "
                     f"max {lat.max():.1f} ms")
        if solve.size:  # per person-frame
            text += f", solve median {np.median(solve):.1f} ms p95 {np.percentile(solve, 95):.1f} ms"
        if s.clipped:
            text += f", confidences clipped in {s.clipped} skeletons"
        if s.skipped:
            text += ", skipped: " + ", ".join(f"{k} {n}" for k, n in sorted(s.skipped.items()))
        self.get_logger().info(text)
        self._stats = FrameStats()


def _one_line(err: BaseException) -> str:
    """An exception as one log line: its text (or type), whitespace collapsed, at most 1000 chars."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text[:1000]


class _Signals:
    """SIGINT / SIGTERM: during start-up (loading, the first kernel compile: ~25 s) they exit at
    once; while running they stop the spin loop after the current callback, so a frame in
    progress is finished and published (nothing is torn down under a running solve)."""

    def __init__(self) -> None:
        self.running = False
        self.stop = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.stop = True
        if not self.running:
            # Nothing runs yet, so nothing is lost: exit at once with code 0. (A KeyboardInterrupt
            # is not enough: numba's first compile runs ctypes callbacks that swallow it, or
            # leave llvmlite half torn down with tracebacks; numba writes cache files atomically.)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)


def _fatal(text: str) -> NoReturn:
    """One ``[FATAL]`` line, then exit code 1."""
    try:
        rclpy.logging.get_logger(NODE_NAME).fatal(text)
    except Exception:  # logging not initialised (rclpy.init itself failed)
        print(f"[FATAL] [{NODE_NAME}]: {text}", file=sys.stderr, flush=True)
    raise SystemExit(1)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run pose_lifter lifter``.

    Exit codes: 0 after SIGINT / SIGTERM (in any phase, within a frame's solve time), 1 when the
    node cannot start (bad parameter value or type, unknown parameter with strict_parameters,
    bad basis file, bad ROS arguments), with one ``[FATAL]`` line giving the reason.
    """
    if (sys.argv[1:] if args is None else args[1:]) == ["--params-yaml"]:
        print(params_yaml(), end="")
        return
    from .core._threads import one_blas_thread

    one_blas_thread()  # the solver's matrices are small: BLAS threads only contend
    if (sys.argv[1:] if args is None else args[1:]) == ["--warm-up"]:
        # compile the solver kernels into this install's cache (make ros runs it after the build)
        start = time.perf_counter()
        Lifter().warm_up()
        print(f"pose_lifter: solver kernels {'compiled' if HAVE_NUMBA else 'not compiled (no numba)'} "
              f"and cached in {time.perf_counter() - start:.1f} s")
        return
    signals = _Signals()
    node: LifterNode | None = None
    try:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            node = LifterNode()
        except (KeyboardInterrupt, ExternalShutdownException):
            return
        except Exception as err:  # bad start-up parameters or basis file: say why, exit 1
            _fatal(f"cannot start: {_one_line(err)}")
        signals.running = True
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not signals.stop and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
