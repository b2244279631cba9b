"""The live lifter: a ROS 2 node that lifts every 2D skeleton it receives to 3D.

One frame, from subscription to publication (:meth:`LifterNode.on_keypoints`):

1. ``keypoints_2d`` (``pose_lifter_msgs/Skeleton2DArray``, sensor-data QoS) arrives as its
   serialised bytes; before each lift every frame the subscription holds joins the waiting frames
   (:class:`~pose_lifter.ros.frame_queue.FrameQueue`), and the oldest left is lifted: when the
   input is faster than the lift, a newer frame drops the oldest waiting one whole (at most
   ``max_waiting_frames`` wait), counted in ``/diagnostics``, so the latency stays bounded. A
   frame dropped is never read.
2. The frame lifted is handed, as its bytes, to one call
   (:meth:`~pose_lifter.messages.answer.AnswerStream.answer`, no rclpy): it is read into arrays
   (:func:`~pose_lifter.messages.cdr.read_skeleton2d_array`, the offline lift's reader; rclpy
   deserialises what that reader refuses), checked and lifted by the frame pipeline
   (:class:`~pose_lifter.messages.frame.FramePipeline`, the offline lift's too: the caps, the
   layout mapped to the paper's 12 joints once, the core's per-track policy
   :class:`~pose_lifter.core.track.policy.TrackPolicy` over :class:`~pose_lifter.core.Lifter`,
   warm-started from the same track's previous solution when there is one, cold otherwise; placed
   in the camera optical frame in metres by
   :func:`~pose_lifter.core.track.placement.place_results`, depth from the weak-perspective scale
   and ``camera_info``'s focal length, or a parameter distance without ``camera_info``; checked
   finite once), with ``output_lag`` N held for the next N frames and each pose refined over them
   (:class:`~pose_lifter.messages.lagged.LaggedFrames`), and answered
   (:func:`~pose_lifter.messages.answer.frame_answer`, what the offline lift writes: one
   ``Skeleton3DArray``, its markers and its REP-155 bodies, CDR written from the lifted
   skeletons' arrays; rclpy reads them as the message built field by field,
   ``tests/ros/test_rclpy_bytes.py``).
3. What that call returns is data (:class:`~pose_lifter.messages.answer.FrameStep`): the node
   warns and counts the refusals and clipped confidences, then publishes each answer:
   ``skeletons_3d`` (``Skeleton3DArray``) with the input's header (stamp and frame), then
   ``skeleton_markers`` (``visualization_msgs/MarkerArray``,
   :class:`~pose_lifter.messages.markers.MarkerBook`, the offline lift's too: the same bytes).
4. With ``publish_hri`` (default), the tracked people as REP-155 bodies
   (:class:`~pose_lifter.ros.hri.HriOutputs`): ``/humans/bodies/tracked``, per body
   ``skeleton2d``, ``roi``, ``joint_states`` and the latched ``urdf``, and their frames on ``/tf``
   (``body_<id>`` under the input's frame).

Every input frame gets exactly one ``Skeleton3DArray`` answer with the same header. A skeleton
that cannot be lifted (bad input or a failed solve) is left out of it with one rate-limited
warning; the other skeletons of the frame are still published, and a frame with no liftable
skeleton is answered with an empty array. Nothing non-finite is ever published.

With ``depth_topic`` (a ``sensor_msgs/Image`` registered to the camera, e.g. RealSense's
aligned depth, or its ``/compressedDepth`` transport), each frame is paired with the depth image
of the nearest stamp within ``depth_tolerance`` (:class:`~pose_lifter.ros.depth_input.DepthInput`)
and its people are placed on it (:func:`~pose_lifter.messages.frame.place_lifted`); a frame
without one is lifted from the 2D alone, counted and warned by why.

Parameters (one table, :data:`pose_lifter.ros.params.PARAMS`, the solver options' ranges from the
core's option metadata; see ``config/lifter.yaml``) are validated on every live change by the
same :class:`~pose_lifter.core.LifterOptions` the core uses; a bad value is refused with the
core's reason. Input checks: :mod:`pose_lifter.messages.frame`; warnings:
:mod:`pose_lifter.ros.checks`; statistics:
:mod:`pose_lifter.ros.stats`.
"""

from __future__ import annotations

import copy
import gc
import os
import sys
import time
from pathlib import Path
from typing import Any, Final

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message

from pose_lifter.core import Lifter, LifterOptions, PoseBases, PoseLifterError
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.core.model.bases import default_bases_path
from pose_lifter.core.numeric.jit import HAVE_NUMBA
from pose_lifter.core.track.defaults import AHEAD_LAG
from pose_lifter.core.track.policy import compile_kernels
from pose_lifter.messages import convert as messages
from pose_lifter.messages import names
from pose_lifter.messages.answer import AnswerStream, FrameStep
from pose_lifter.messages.frame import FramePipeline
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.ros import diagnostics
from pose_lifter.ros.checks import WarningThrottle
from pose_lifter.ros.depth_input import DepthInput
from pose_lifter.ros.frame_queue import FrameQueue
from pose_lifter.ros.hri import HriOutputs, message_classes
from pose_lifter.ros.params import PARAMS, SPECS, NodeSettings, descriptor, params_yaml, unknown_parameters
from pose_lifter.ros.run import run_node
from pose_lifter.ros.stats import FrameCounter

__all__ = ["NODE_NAME", "LifterNode", "StartupError", "freeze_long_lived", "main"]

NODE_NAME: Final[str] = names.LIFTER_NODE
MARKER_NS: Final[str] = "pose_lifter"
STATS_LINE: Final[str] = "stats line"  # the statistics line's window in the node's counter
#: A frame's receive stamp older than this (s) is taken as another clock's: its latency counts from
#: its callback instead.
MAX_RECEIVE_AGE_S: Final[float] = 10.0
#: The depth subscription's QoS: reliable, keep the last 2 (RealSense and image_transport publish
#: depth reliably; over best effort most 0.6 MB images lose a fragment and never arrive).
DEPTH_QOS: Final[QoSProfile] = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
#: With ``output_lag``, the frames held for it are published when no frame has come for this long
#: (s): the input stopped or paused. Checked every LAG_CHECK_S.
LAG_IDLE_S: Final[float] = 0.5
LAG_CHECK_S: Final[float] = 0.1


class StartupError(Exception):
    """The node cannot start (bad parameter, basis file): one [FATAL] line and exit code 1."""


_DEFAULT_OPTIONS: Final[LifterOptions] = LifterOptions()


def _own(profile: QoSProfile) -> QoSProfile:
    """A copy of ``profile`` for one topic: rclpy writes a topic's ``qos_overrides`` into the
    profile it is given, so a profile shared by two topics would carry one's override to the other
    (camera_info made reliable made the keypoints reliable)."""
    return copy.copy(profile)


def freeze_long_lived() -> None:
    """Move what the node now holds for as long as it runs (rclpy, numba and its kernels, the
    bases, the prior, the lifter) out of the garbage collector's generations, so that a full
    collection walks only what the frames make (~0.5 ms instead of up to ~58 ms with 30 people,
    longer than a frame's period at 30 Hz). Called once a lifter is built: what an earlier call
    froze is first returned to the collector and collected, so the reference cycles of a
    replaced lifter are freed rather than kept frozen."""
    gc.unfreeze()
    gc.collect()
    gc.freeze()


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
            self.declare_parameter(spec.name, spec.default, descriptor(spec))
        self._throttle = WarningThrottle(self.get_logger().warning)
        self._check_unknown_parameters()
        self._callbacks_added = False
        # frames taken from the subscription, waiting to be lifted (the oldest dropped first)
        self._waiting: FrameQueue[tuple[float, Any]] = FrameQueue(int(self._param("max_waiting_frames")))
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
        lag = int(self._param("output_lag"))
        # from AHEAD_LAG on the lift reads its tracks' next frames (the offline prior) as it waits
        self._lifter = Lifter(self._bases, options, reads_ahead=lag >= AHEAD_LAG)
        self._lifter.threads = self._solver_threads()
        # compile (first start after an install: ~25 s) or load the solver kernels before the
        # topics exist, so the first frame is not the one that pays for it
        kernels = "numba-compiled" if HAVE_NUMBA else "plain Python (pip install numba: ~3x faster)"
        self.get_logger().info(f"solver ready in {self._lifter.warm_up():.1f} s, {kernels} kernels, "
                               f"{self._lifter.threads} solver threads")
        self._pending: tuple[PoseBases, Lifter] | None = None
        self._settings = self._read_settings()
        self._depth: DepthInput | None = None
        if self._settings.frame.depth_topic:  # compile or load the depth kernel before the first frame
            from pose_lifter.messages import depth

            depth.warm_up()
        freeze_long_lived()

        self._pipeline = FramePipeline(self._lifter, self._settings.frame)
        # a frame's way from its bytes to its answer (rclpy reads what the array reader refuses)
        skeletons_2d = self._types.Skeleton2DArray
        self._stream = AnswerStream(self._pipeline, lag, lambda data: deserialize_message(data, skeletons_2d))
        self._last_frame = time.perf_counter()
        self._markers = MarkerBook(MARKER_NS)
        self._counts = FrameCounter()  # one counter, a window per report (stats line, /diagnostics)

        qos_override = QoSOverridingOptions.with_default_policies()
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._pub_skeletons = self.create_publisher(
            self._types.Skeleton3DArray, "skeletons_3d", _own(reliable), qos_overriding_options=qos_override)
        self._pub_markers = self.create_publisher(
            self._types.MarkerArray, "skeleton_markers", _own(reliable), qos_overriding_options=qos_override)
        self._diagnostics = diagnostics.LifterDiagnostics(self, float(self._param("diagnostics_period")),
                                                         self._counts)
        self._hri = self._hri_outputs()
        self._configure_answers()
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
            self._types.CameraInfo, "camera_info", self.on_camera_info, _own(qos_profile_sensor_data),
            qos_overriding_options=qos_override)
        # the depth images before the keypoints (the frame's image is then held when it is lifted);
        # reliable, as cameras publish them: best effort loses most 0.6 MB images in fragments
        frame = self._settings.frame
        if frame.depth_topic:
            self._depth = DepthInput(self, frame.depth_topic, frame.depth_tolerance, self._counts.depth,
                                     self._throttle.warn, self._camera, _own(DEPTH_QOS), qos_override)
            self._stream.depth_of = self._depth.depth_of
            self._diagnostics.depth_warning = self._depth.silence
        # a callback of (message, MessageInfo), which rclpy takes (its stubs know one argument only);
        # raw: the serialised frame, read into arrays when it is lifted (AnswerStream.answer)
        self._sub_keypoints = self.create_subscription(
            self._types.Skeleton2DArray, "keypoints_2d", self.on_keypoints,  # type: ignore[arg-type]
            _own(qos_profile_sensor_data), qos_overriding_options=qos_override, raw=True)
        # triggered while frames wait after a lift: the executor comes back for the next one
        # between its other callbacks (camera_info, timers, parameter services)
        self._more = self.create_guard_condition(self._lift_next)
        lagged = self._stream.lagged
        self._lag_timer = self.create_timer(LAG_CHECK_S, self._publish_idle) if lagged is not None else None
        period = float(self._param("stats_period"))
        self._stats_timer = None
        if period > 0:
            self._counts.open(STATS_LINE)
            self._stats_timer = self.create_timer(period, self._log_stats)
        self.get_logger().info(
            f"lifting {self._sub_keypoints.topic_name} -> {self._pub_skeletons.topic_name}: "
            f"{self._bases.method} bases (k={self._bases.n_bases}), variant {options.variant}, "
            f"{options.n_starts} cold starts, warm start {'on' if self._param('warm_start') else 'off'}, "
            f"mode {options.mode}, weak perspective until camera_info arrives"
            + (f", answers {lagged.lag} frames late (output_lag)" if lagged is not None else "")
            + (f", depth from {self._depth.topic} (within {frame.depth_tolerance:g} s)"
               if self._depth is not None else "")
        )
        if self._depth is not None and self._stream.intrinsics is None:
            self.get_logger().info("depth_topic is set: its images are used once camera_info has come "
                                   "(the lift is from the 2D alone until then)")

    def _camera(self) -> tuple[Any, Any]:
        """The camera's intrinsics and (width, height) from camera_info (None: not yet)."""
        return self._stream.intrinsics, self._stream.image_size

    def _hri_outputs(self) -> HriOutputs | None:
        """The REP-155 publishers, or None (``publish_hri`` false, or a message package missing:
        one warning, the other outputs go on)."""
        if not self._param("publish_hri"):
            return None
        try:
            types = message_classes()
        except ImportError as err:
            self.get_logger().warning(f"REP-155 bodies and /tf not published: {err} (publish_hri:=false "
                                      "silences this)")
            return None
        return HriOutputs(self, types, self._settings.frame.track_timeout)

    def deactivate_lifter(self) -> None:
        """Unsubscribe (the solver and the publishers stay: activating again is immediate); the
        frames still waiting are dropped, the answers held for ``output_lag`` published."""
        self._waiting.clear()
        if self._lag_timer is not None:
            self.destroy_timer(self._lag_timer)
            self._lag_timer = None
        self._publish_idle(force=True)
        self.destroy_guard_condition(self._more)
        for entity in (self._sub_keypoints, self._sub_camera_info):
            self.destroy_subscription(entity)
        if self._depth is not None:
            self._depth.close()
            self._depth = None
            self._stream.depth_of = None
            self._diagnostics.depth_warning = None
        if self._stats_timer is not None:
            self.destroy_timer(self._stats_timer)
            self._stats_timer = None
            self._counts.close(STATS_LINE)
        self._pipeline.clear()
        if self._hri is not None:
            self._hri.clear()

    def cleanup_lifter(self) -> None:
        """Destroy the publishers and the diagnostics (back to the state after the constructor)."""
        self._stream.clear()
        self._diagnostics.close()
        for pub in (self._pub_skeletons, self._pub_markers):
            self.destroy_publisher(pub)
        if self._hri is not None:
            self._hri.close()

    # ------------------------------------------------------------------ parameters

    def _configure_answers(self) -> None:
        """The answers' outputs and defaults, from the settings."""
        stream = self._stream
        stream.markers = self._markers if self._settings.publish_markers else None
        stream.bodies = self._hri.book if self._hri is not None else None
        stream.frame_id = self._settings.frame_id  # RViz cannot place an empty frame
        stream.marker_lifetime = self._settings.marker_lifetime

    def _param(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _solver_threads(self) -> int:
        """``solver_threads``, 0 resolved to the CPU cores this process may run on."""
        threads = int(self._param("solver_threads"))
        return threads if threads > 0 else len(os.sched_getaffinity(0))

    def _read_settings(self) -> NodeSettings:
        return NodeSettings.read(self._param)

    @staticmethod
    def _load_bases(path: str, mode: str) -> PoseBases:
        """``bases_file``, or the packaged bases of ``mode`` when it is empty."""
        return PoseBases.load(Path(path).expanduser() if path else default_bases_path(mode))

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: build the new options (and bases) or refuse with the reason."""
        ours = [p for p in params if p.name in SPECS]
        if not ours:
            return SetParametersResult(successful=True)
        try:
            bases = self._bases
            changes = {p.name: p.value for p in ours if SPECS[p.name].option}
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
            lifter = (Lifter(bases, options, reads_ahead=self._lifter.reads_ahead)
                      if bases is not self._lifter.bases or options != self._lifter.options else self._lifter)
            lifter.threads = self._lifter.threads
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
        self._configure_answers()
        if self._hri is not None:  # bodies leave as tracks are forgotten
            self._hri.book.timeout_ns = round(self._settings.frame.track_timeout * 1e9)
        if self._depth is not None:
            self._depth.set_tolerance(self._settings.frame.depth_tolerance)
        if self._pending is None:
            return
        bases, lifter = self._pending
        self._pending = None
        if bases is not self._bases:
            self._bases = bases
            self._pipeline.clear()  # coefficients of other bases are meaningless
        replaced = lifter is not self._lifter
        self._lifter = lifter
        self._pipeline.configure(self._lifter, self._settings.frame)
        if replaced:
            freeze_long_lived()
        names = ", ".join(f"{p.name}={p.value!r}" for p in params if p.name in SPECS)
        if names:
            self.get_logger().info(f"parameters changed: {names}")

    # ------------------------------------------------------------------ callbacks

    def on_camera_info(self, msg: Any) -> None:
        """Keep the latest intrinsics (a bad CameraInfo is ignored with a warning); the first ones
        switch the lift from weak perspective to the 2D corrected for perspective (said once)."""
        try:
            intrinsics = messages.intrinsics_from_camera_info(msg)
        except (InvalidInputError, ValueError, TypeError) as err:
            self._warn_skip("camera_info", str(err))
            return
        if int(msg.width) > 0 and int(msg.height) > 0:  # the REP-155 2D outputs are normalised by it
            self._stream.image_size = (float(msg.width), float(msg.height))
        if self._stream.intrinsics is None:
            (fx, fy), (cx, cy) = intrinsics
            self.get_logger().info(
                f"camera_info received (fx {fx:.1f}, fy {fy:.1f}, cx {cx:.1f}, cy {cy:.1f} px): tracked "
                "people are lifted from their 2D corrected for perspective and placed at metric depth")
        self._stream.intrinsics = intrinsics

    def on_keypoints(self, msg: Any, info: Any) -> None:
        """A frame arrived: it waits with the others (:class:`~pose_lifter.ros.frame_queue.FrameQueue`),
        then the oldest waiting frame is lifted."""
        self._wait(msg, info)
        self._lift_next()

    def _wait(self, msg: Any, info: Any) -> None:
        """``msg`` joins the waiting frames; the oldest is dropped (and counted) beyond
        ``max_waiting_frames``. Its latency counts from when the middleware received it
        (``info["received_timestamp"]``, system clock): it may have waited in the subscription's
        queue while the previous frame was lifted."""
        received = time.perf_counter()
        stamp = info.get("received_timestamp") if isinstance(info, dict) else None
        if stamp:
            waited = (time.time_ns() - int(stamp)) / 1e9
            if 0.0 < waited < MAX_RECEIVE_AGE_S:  # else another clock: counted from now
                received -= waited
        if self._waiting.put((received, msg)) is not None:
            self._counts.drop()

    def _lift_next(self) -> None:
        """Take every frame the subscription holds into the waiting frames, then lift the oldest
        one left; while frames still wait, the guard condition brings the executor back."""
        sub = self._sub_keypoints
        # what the executor itself calls to take a message (rclpy has no public take)
        with sub.handle:
            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                self._wait(*taken)
        item = self._waiting.pop()
        if item is None:
            return
        self.lift_frame(item[1], item[0])
        if len(self._waiting):
            self._more.trigger()

    def lift_frame(self, data: Any, received: float) -> None:
        """Lift one frame (its serialised bytes, or a message object) and publish its answer
        (always, even when every skeleton is skipped; with ``output_lag``, those it releases);
        ``received``: when it arrived (:func:`time.perf_counter`), for its latency."""
        self._last_frame = time.perf_counter()
        self._publish(self._stream.answer(data, received, self.get_clock().now().nanoseconds))

    def _publish_idle(self, force: bool = False) -> None:
        """Publish the answers held for ``output_lag`` when no frame has come for LAG_IDLE_S (or
        ``force``): the input stopped, and nothing later will refine them."""
        if not len(self._stream):
            return
        if force or time.perf_counter() - self._last_frame > LAG_IDLE_S:
            self._publish(self._stream.flush())

    def _publish(self, step: FrameStep) -> None:
        """What a frame gave, on every output: each answer's ``skeletons_3d``, markers and REP-155
        bodies, in order; the refusals and clipped confidences counted and warned; each answer's
        latency counted from when its input arrived."""
        for text in step.clipped:  # they weigh the solve: clipped into [0, 1], with a warning
            self._counts.clip()
            self._throttle.warn("confidence outside [0, 1]", text)
        for kind, text in step.skipped:
            self._warn_skip(kind, text)
        for out in step.answers:
            self._pub_skeletons.publish(out.answer.skeletons)
            if out.answer.markers is not None:
                self._pub_markers.publish(out.answer.markers)
            if self._hri is not None and out.answer.bodies is not None:  # REP-155 bodies and /tf
                self._hri.publish(out.answer.bodies)
            self._counts.frame(out.lifted, time.perf_counter() - out.received)

    # ------------------------------------------------------------------ diagnostics

    def _warn_skip(self, kind: str, text: str) -> None:
        """Count a skipped input and warn, rate-limited per kind (each kind at least once a period)."""
        self._counts.skip(kind)
        self._throttle.warn(kind, text)

    def _check_unknown_parameters(self) -> None:
        """Report start-up parameters that are not the node's (a misspelt name is otherwise ignored)."""
        text = unknown_parameters(getattr(self, "_parameter_overrides", {}))
        if not text:
            return
        if self._param("strict_parameters"):
            raise StartupError(f"{text} (strict_parameters is true)")
        self.get_logger().warning(f"{text}; ignored (strict_parameters:=true refuses them)")

    def _log_stats(self) -> None:
        text = self._counts.take(STATS_LINE).line()
        if text:
            self.get_logger().info(text)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run pose_lifter lifter`` (``--params-yaml``: print config/lifter.yaml;
    ``--warm-up``: compile the solver kernels into the cache).

    Exit codes (:func:`pose_lifter.ros.run.run_node`): 0 after SIGINT / SIGTERM (in any phase,
    within a frame's solve time), 1 when the node cannot start (bad parameter value or type,
    unknown parameter with strict_parameters, bad basis file, bad ROS arguments), with one
    ``[FATAL]`` line giving the reason.
    """
    if (sys.argv[1:] if args is None else args[1:]) == ["--params-yaml"]:  # config/lifter.yaml
        print(params_yaml(), end="")
        return
    from pose_lifter.core.numeric.threads import one_blas_thread

    one_blas_thread()  # the solver's matrices are small: BLAS threads only contend
    if (sys.argv[1:] if args is None else args[1:]) == ["--warm-up"]:
        # compile the solver kernels into this install's cache (make ros runs it after the build)
        seconds = compile_kernels()
        print(f"pose_lifter: solver kernels {'compiled' if HAVE_NUMBA else 'not compiled (no numba)'} "
              f"and cached in {seconds:.1f} s")
        return
    run_node(lambda signals: LifterNode(), NODE_NAME, args)

if __name__ == "__main__":
    main()
