"""Downstream example: an action-recognition node behind the lifter.

    ros2 run pose_lifter lifter &
    ros2 run pose_lifter action_recognition        # subscribes to skeletons_3d

For every tracked person in ``skeletons_3d`` (``pose_lifter_msgs/Skeleton3DArray``) the node
keeps the last second of 3D poses, assembles a window of ``W`` poses ``step_s`` apart (the
model's settings) and classifies it with a nearest-neighbour vote over view-normalised CMU
training windows (:class:`~pose_lifter.actions.ActionClassifier`). It publishes
``actions`` (``std_msgs/String``, ``"<track_id> <label>"`` per track and frame) and logs when a
track's action changes. Untracked skeletons (id -1) have no history and are not classified.

The lifter is what makes this work from any viewpoint: the 3D poses are normalised to the
body frame, so one training set serves every camera (see tools/action_recognition_eval.py
for 3D-vs-2D accuracy on unseen trials).
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from pose_lifter.actions import ActionClassifier, PoseHistory
from pose_lifter.core.errors import PoseLifterError
from pose_lifter.messages import convert as messages
from pose_lifter.ros.run import run_node

__all__ = ["ActionRecognitionNode", "main"]


class ActionRecognitionNode(Node):
    """Classifies each track's recent 3D poses (see the module doc)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("action_recognition", **kwargs)
        self.declare_parameter("model_file", "", ParameterDescriptor(
            description="Action model (.npz from tools/action_recognition_eval.py); empty = packaged",
            read_only=True))
        path = str(self.get_parameter("model_file").value)
        self._model = ActionClassifier.load(path or None)
        if self._model.kind != "3d":
            raise PoseLifterError(f"{path}: a 3D model is needed, got kind {self._model.kind!r}")
        self._histories: dict[int, PoseHistory] = {}
        self._labels: dict[int, str] = {}
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._pub = self.create_publisher(String, "actions", reliable)
        self._sub = self.create_subscription(
            messages.rclpy_types().Skeleton3DArray, "skeletons_3d", self.on_skeletons, reliable)
        self.get_logger().info(
            f"classifying {self._sub.topic_name} into {self._model.classes_} "
            f"(windows of {self._model.window} poses {self._model.step_s} s apart)")

    def on_skeletons(self, msg: Any) -> None:
        stamp = messages.stamp_to_ns(msg.header.stamp)
        present = set()
        for skel in msg.skeletons:
            track = int(skel.track_id)
            if track < 0:
                continue
            present.add(track)
            try:
                joints = messages.skeleton3d_to_joints(skel)
            except PoseLifterError:
                continue
            history = self._histories.setdefault(track, PoseHistory(self._model.window, self._model.step_s))
            history.add(stamp, joints)
            window = history.window_at(stamp)
            if window is None:
                continue
            label = str(self._model.predict(window[None])[0])
            self._pub.publish(String(data=f"{track} {label}"))
            if self._labels.get(track) != label:
                self.get_logger().info(f"track {track}: {label}")
                self._labels[track] = label
        horizon = int(2 * self._model.window * self._model.step_s * 1e9)
        for track in [t for t, h in self._histories.items()
                      if t not in present and (h.last_stamp_ns or 0) < stamp - horizon]:
            del self._histories[track]
            self._labels.pop(track, None)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run pose_lifter action_recognition``."""
    run_node(lambda signals: ActionRecognitionNode(), "action_recognition", args)


if __name__ == "__main__":
    main()
