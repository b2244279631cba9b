"""``ros2 run pose_lifter adapter``: a detector's own messages in, ``keypoints_2d`` out.

``input_type:=yolo`` subscribes to ``yolo_msgs/DetectionArray`` (yolo_ros, topic
``yolo/detections``; remap it), ``input_type:=hri`` to every REP-155 body skeleton
``/humans/bodies/<id>/skeleton2d`` (``hri_msgs/Skeleton2D``, found by scanning the graph once a
second). Each input message becomes one ``pose_lifter_msgs/Skeleton2DArray`` in the ``wang12``
layout (the paper's 12 joints, pixels) on ``keypoints_2d``, with the input's header (an empty
``frame_id`` replaced by the ``frame_id`` parameter), so ``lifter`` takes it unchanged:

    ros2 run pose_lifter adapter --ros-args -p input_type:=yolo -r yolo/detections:=/yolo/detections
    ros2 run pose_lifter lifter

REP-155 coordinates are normalised: the image size comes from the ``image_width`` /
``image_height`` parameters or, when they are 0, from ``camera_info``. The message packages
(``yolo_msgs``, ``hri_msgs``) are needed only for the input type used; a missing one is one
``[FATAL]`` line and exit code 1.
"""

from __future__ import annotations

import importlib
from typing import Any, Final

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from pose_lifter.core.errors import InvalidInputError, PoseLifterError
from pose_lifter.messages import adapters, names
from pose_lifter.messages import convert as messages
from pose_lifter.messages.layouts import get_layout
from pose_lifter.ros.run import run_node

__all__ = ["AdapterNode", "main"]

NODE_NAME: Final[str] = "pose_lifter_adapter"


class AdapterError(PoseLifterError):
    """The adapter cannot start (unknown input type, message package not installed)."""


def _message_class(full_name: str) -> Any:
    pkg, _, cls = full_name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), cls)
    except (ImportError, AttributeError):
        raise AdapterError(
            f"{full_name} is not available: install the {pkg} package (e.g. apt install "
            f"ros-jazzy-{pkg.replace('_', '-')}) or build it in your workspace, then source it") from None


class AdapterNode(Node):
    """Converts detector messages to ``keypoints_2d``, see the module doc."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        ro = ParameterDescriptor(read_only=True)
        self.declare_parameter("input_type", "yolo", ParameterDescriptor(
            read_only=True, description=f"Input messages: one of {sorted(adapters.INPUT_TYPES)}."))
        self.declare_parameter("layout", "coco17", ParameterDescriptor(
            read_only=True, description="yolo: keypoint layout of the pose model."))
        self.declare_parameter("class_names", ["person"], ParameterDescriptor(
            read_only=True, description="yolo: classes whose keypoints are people (empty = all)."))
        self.declare_parameter("image_width", 0, ro)
        self.declare_parameter("image_height", 0, ro)
        self.declare_parameter("frame_id", "camera", ParameterDescriptor(
            description="frame_id of outputs whose input header has an empty one."))
        self._types = messages.rclpy_types()
        self._ids = adapters.TrackIds()
        self._input_type = str(self.get_parameter("input_type").value)
        if self._input_type not in adapters.INPUT_TYPES:
            raise AdapterError(f"input_type must be one of {sorted(adapters.INPUT_TYPES)}, "
                               f"got {self._input_type!r}")
        self._layout = get_layout(str(self.get_parameter("layout").value)).name  # unknown: refused
        self._classes = tuple(str(c) for c in self.get_parameter("class_names").value if str(c))
        width = int(self.get_parameter("image_width").value)
        height = int(self.get_parameter("image_height").value)
        self._image_size: tuple[float, float] | None = (width, height) if width > 0 and height > 0 else None
        self._msg_class = _message_class(adapters.INPUT_TYPES[self._input_type])
        self._pub = self.create_publisher(self._types.Skeleton2DArray, "keypoints_2d",
                                          QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self._subs: dict[str, Any] = {}
        if self._input_type == "yolo":
            self._subs["yolo/detections"] = self.create_subscription(
                self._msg_class, "yolo/detections", self.on_yolo, 10)
        else:
            self._camera_info = self.create_subscription(
                self._types.CameraInfo, "camera_info", self.on_camera_info, qos_profile_sensor_data)
            self._scan_timer = self.create_timer(1.0, self._scan_hri_topics)
            self._scan_hri_topics()
        self.get_logger().info(
            f"adapting {self._input_type} ({adapters.INPUT_TYPES[self._input_type]}) -> "
            f"{self._pub.topic_name} (wang12)")

    # ------------------------------------------------------------------ inputs

    def _header(self, header: Any) -> Any:
        if not str(header.frame_id):
            header.frame_id = str(self.get_parameter("frame_id").value)
        return header

    def _warn(self, text: str) -> None:
        self.get_logger().warning(text, throttle_duration_sec=5.0)

    def on_yolo(self, msg: Any) -> None:
        """One DetectionArray -> one Skeleton2DArray (people with keypoints only)."""
        people, problems = adapters.yolo_detections_to_people(msg, self._ids, self._layout, self._classes)
        for p in problems:
            self._warn(f"detection skipped: {p}")
        self._pub.publish(adapters.people_to_skeleton2d_array(self._header(msg.header), people, self._types))

    def on_camera_info(self, msg: Any) -> None:
        """Image size for the normalised REP-155 coordinates (when not set by parameters)."""
        fixed = self.get_parameter("image_width").value > 0 and self.get_parameter("image_height").value > 0
        if int(msg.width) > 0 and int(msg.height) > 0 and not fixed:
            self._image_size = (int(msg.width), int(msg.height))

    def _scan_hri_topics(self) -> None:
        for topic, kinds in self.get_topic_names_and_types():
            body = adapters.hri_body_id(topic)
            if body is None or topic in self._subs or adapters.INPUT_TYPES["hri"] not in kinds:
                continue
            publishers = {info.node_name for info in self.get_publishers_info_by_topic(topic)}
            if not publishers or publishers <= {names.LIFTER_NODE}:
                continue  # the lifter's own REP-155 output (or not matched yet): never lifted again
            track_id = self._ids(body)

            def callback(msg: Any, track_id: int = track_id, body: str = body) -> None:
                self.on_hri(msg, track_id, body)

            self._subs[topic] = self.create_subscription(self._msg_class, topic, callback, 10)
            self.get_logger().info(f"body {body!r} (track {track_id}): subscribed to {topic}")

    def on_hri(self, msg: Any, track_id: int, body: str) -> None:
        """One body's Skeleton2D -> a Skeleton2DArray with that one person."""
        if self._image_size is None:
            self._warn("hri skeleton skipped: image size unknown (set image_width/image_height "
                       "or publish camera_info)")
            return
        try:
            person = adapters.hri_skeleton_to_person(msg, self._image_size, track_id)
        except InvalidInputError as err:
            self._warn(f"body {body!r} skipped: {err}")
            return
        out = adapters.people_to_skeleton2d_array(self._header(msg.header), [person], self._types)
        self._pub.publish(out)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run pose_lifter adapter``."""
    run_node(lambda signals: AdapterNode(), NODE_NAME, args)


if __name__ == "__main__":
    main()
