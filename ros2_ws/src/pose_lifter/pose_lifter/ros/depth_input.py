"""The lifter node's depth input: the ``depth_topic`` subscription, its images held in a small
buffer, and each keypoints frame's depth image (or why it has none).

The images arrive as their serialised bytes (sensor-data QoS, like the keypoints) and are read
only as far as their header (:func:`~pose_lifter.messages.depth.decode_image_cdr`, a view of the
bytes, or :func:`~pose_lifter.messages.depth.decode_compressed_image_cdr` on a topic ending in
``/compressedDepth``: image_transport's compressedDepth transport) into a
:class:`~pose_lifter.messages.depth.DepthBuffer` of :data:`DEPTH_CAPACITY` images. When a frame
is lifted (:attr:`pose_lifter.messages.answer.AnswerStream.depth_of` is :meth:`DepthInput.depth_of`)
the images the subscription still holds are taken first, the frame's partner (the nearest header
stamp within ``depth_tolerance``) is decoded into metres and checked against ``camera_info``
(:func:`~pose_lifter.messages.depth.read_depth`, :func:`~pose_lifter.messages.depth.check_depth_size`).
A frame without a partner, or whose partner is refused, is lifted from the 2D alone: counted in
``/diagnostics`` by why, and each kind warned once per period. No depth image for more than
:data:`SILENT_S` is a ``WARN`` of ``/diagnostics``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Final

from pose_lifter.messages.convert import stamp_to_ns
from pose_lifter.messages.depth import (
    DepthBuffer,
    DepthError,
    camera_info_missing,
    check_depth_size,
    check_held,
    decode_compressed_image_cdr,
    decode_image_cdr,
    is_compressed_topic,
    read_depth,
)
from pose_lifter.messages.frame import DepthImage

__all__ = ["DEPTH_CAPACITY", "NO_PARTNER", "SILENT_S", "DepthInput"]

#: Depth images held (the newest stamps): 0.33 s at 30 Hz, more than a detector's latency, so the
#: image of a frame is still held when the frame's keypoints come; 12 MB of 640x480 16UC1.
DEPTH_CAPACITY: Final[int] = 10
#: Seconds without a depth image after which ``/diagnostics`` warns.
SILENT_S: Final[float] = 1.0
#: The warning kind of a frame without a depth partner.
NO_PARTNER: Final[str] = "depth: no partner"


class DepthInput:
    """The depth subscription of a node and the pairing of its frames (see the module doc).

    Parameters
    ----------
    node : rclpy.node.Node
    topic : str
        ``depth_topic``.
    tolerance_s : float
        ``depth_tolerance``.
    count : callable
        ``count(kind)``: one frame lifted with depth (``kind`` None) or without (the reason's kind).
    warn : callable
        ``warn(kind, text)``: a warning, rate-limited per kind by the caller.
    camera : callable
        ``camera()``: (the intrinsics or None, (width, height) of the camera_info or None).
    qos : rclpy QoS profile
    qos_overriding_options : rclpy QoSOverridingOptions or None
    """

    def __init__(self, node: Any, topic: str, tolerance_s: float, count: Callable[[str | None], None],
                 warn: Callable[[str, str], None], camera: Callable[[], tuple[Any, Any]], qos: Any,
                 qos_overriding_options: Any = None) -> None:
        from sensor_msgs.msg import CompressedImage, Image

        self._node, self._count, self._warn, self._camera = node, count, warn, camera
        compressed = is_compressed_topic(topic)
        self._decode = decode_compressed_image_cdr if compressed else decode_image_cdr
        self.buffer: DepthBuffer[Any] = DepthBuffer(DEPTH_CAPACITY, round(tolerance_s * 1e9))
        self.started = time.monotonic()
        self.last_image: float | None = None  # monotonic time of the last image received
        self.subscription = node.create_subscription(
            CompressedImage if compressed else Image, topic, self.on_image, qos,
            qos_overriding_options=qos_overriding_options, raw=True)

    @property
    def topic(self) -> str:
        return str(self.subscription.topic_name)

    def set_tolerance(self, tolerance_s: float) -> None:
        """A new ``depth_tolerance`` (s), from the next frame on."""
        self.buffer.tolerance_ns = round(tolerance_s * 1e9)

    def close(self) -> None:
        """Destroy the subscription and forget the images."""
        self._node.destroy_subscription(self.subscription)
        self.buffer.clear()

    def on_image(self, data: bytes) -> None:
        """A serialised depth image: held by its header stamp (a message that does not even hold
        its fields, or of more than MAX_DEPTH_PIXELS pixels, is refused and warned)."""
        self.last_image = time.monotonic()
        try:
            image = check_held(self._decode(data))  # a huge image is not held
        except DepthError as err:
            self._warn(str(err.fault), f"depth image refused: {err}")
            return
        self.buffer.push(stamp_to_ns(image.header.stamp), image)

    def _take_waiting(self) -> None:
        """Take the images the subscription holds (as the executor would, before the frame)."""
        sub = self.subscription
        with sub.handle:
            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                self.on_image(taken[0])

    def depth_of(self, stamp_ns: int) -> DepthImage:
        """The depth image (float32 (H, W) metres, NaN = none; a 16-bit one as uint16 millimetres,
        0 = none: :func:`~pose_lifter.messages.depth.read_depth`) of the frame of ``stamp_ns``, or
        None (counted and warned: no partner within the tolerance, no camera_info, an image
        refused)."""
        self._take_waiting()
        pairing = self.buffer.pair(stamp_ns)
        if pairing.image is None:
            self._count(NO_PARTNER)
            self._warn(NO_PARTNER, f"frame lifted from the 2D alone: {pairing.reason()} on {self.topic} "
                       f"(depth_tolerance {self.buffer.tolerance_ns / 1e9:g} s)")
            return None
        intrinsics, size = self._camera()
        try:
            if intrinsics is None:
                raise camera_info_missing()
            depth = read_depth(pairing.image, millimetres=True)
            if size is not None:
                check_depth_size(depth, size)
        except DepthError as err:
            self._count(str(err.fault))
            self._warn(str(err.fault), f"frame lifted from the 2D alone: {err}")
            return None
        self._count(None)
        return depth

    def silence(self) -> str:
        """A warning when no depth image came for more than :data:`SILENT_S` (``""``: they come)."""
        now = time.monotonic()
        if self.last_image is None:
            waited = now - self.started
            return (f"no depth image on {self.topic} yet ({waited:.0f} s): lifting from the 2D alone"
                    if waited > SILENT_S else "")
        if now - self.last_image > SILENT_S:
            return (f"no depth image on {self.topic} for {now - self.last_image:.1f} s: lifting from "
                    "the 2D alone")
        return ""

