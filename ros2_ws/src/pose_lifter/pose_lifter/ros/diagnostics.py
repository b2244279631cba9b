"""``/diagnostics`` of the lifter node (``diagnostic_msgs/DiagnosticArray``, the ROS convention
that ``rqt_robot_monitor``, ``diagnostic_aggregator`` and Foxglove read).

Once per ``diagnostics_period`` the node publishes one ``DiagnosticStatus`` named
``"<node name>: lifter"`` (hardware id ``pose_lifter``) about the window since the last one:

========================  ===============================================================
key                       value
========================  ===============================================================
``input rate (Hz)``       keypoint frames received per second (answered or dropped)
``frames``                keypoint frames answered
``frames dropped``        frames dropped unanswered while the node was busy (the oldest first)
``skeletons lifted``      skeletons published
``warm share``            fraction of them warm-started from their track's previous frame
``cold share``            fraction solved cold (multi-start)
``latency median (ms)``   per frame, received -> answer published (also ``p95``)
``solve median (ms)``     per skeleton (also ``p95``)
``labels swapped back``   skeletons whose track swapped back their detector's left/right labels
``skipped total``         skeletons or frames left out, and ``skipped: <kind>`` per kind
``frames with depth``     with ``depth_topic``: frames lifted with their depth image, and
                          ``frames without depth: <why>`` per reason (no partner within
                          ``depth_tolerance``, no camera_info, an image refused by kind)
========================  ===============================================================

The counts come from the node's one counter (:class:`pose_lifter.ros.stats.FrameCounter`), in a
window of their own. Levels: ``ERROR`` when skeletons came in but none could be lifted; ``WARN``
when no input came in the window, frames were dropped (the input is faster than the lift: fewer
people, ``max_skeletons``, or a lower rate), some inputs were skipped, or with ``depth_topic`` no
depth image came for a second (:data:`pose_lifter.ros.depth_input.SILENT_S`: the frames are lifted
from the 2D alone); ``OK`` otherwise. The message says which.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

import numpy as np

from pose_lifter.ros.stats import FrameCounter, FrameStats

__all__ = ["HARDWARE_ID", "LifterDiagnostics", "status_level", "values"]

HARDWARE_ID: Final[str] = "pose_lifter"
OK: Final[int] = 0
WARN: Final[int] = 1
ERROR: Final[int] = 2


def status_level(frames: int, lifted: int, skipped: int, dropped: int = 0, depth_warning: str = ""
                 ) -> tuple[int, str]:
    """(level, message) of a window with these counts (see the module doc); ``depth_warning``:
    the depth input's (``""``: none)."""
    if frames == 0 and dropped == 0:
        level, message = WARN, "no input on keypoints_2d"
    elif lifted == 0 and skipped > 0:
        return ERROR, f"no skeleton could be lifted ({skipped} skipped)"
    elif dropped > 0:
        level, message = WARN, (f"{dropped} of {frames + dropped} frames dropped: the input is faster than "
                                "the lift")
    elif skipped > 0:
        level, message = WARN, f"{skipped} inputs skipped"
    else:
        level, message = OK, "lifting"
    if depth_warning:
        return WARN, depth_warning if level == OK else f"{message}; {depth_warning}"
    return level, message


def values(window: FrameStats) -> list[tuple[str, str]]:
    """The key/value pairs of a window (see the module doc)."""
    lat = np.asarray(window.latencies) * 1e3
    solve = np.asarray(window.solve_times) * 1e3
    n = max(window.lifted, 1)

    def ms(a: Any, q: float) -> str:
        return f"{np.percentile(a, q):.2f}" if a.size else "nan"

    out = [
        ("input rate (Hz)", f"{(window.frames + window.dropped) / window.elapsed():.2f}"),
        ("frames", str(window.frames)),
        ("frames dropped", str(window.dropped)),
        ("skeletons lifted", str(window.lifted)),
        ("warm share", f"{window.warm / n:.3f}" if window.lifted else "nan"),
        ("cold share", f"{(window.lifted - window.warm) / n:.3f}" if window.lifted else "nan"),
        ("latency median (ms)", ms(lat, 50)), ("latency p95 (ms)", ms(lat, 95)),
        ("solve median (ms)", ms(solve, 50)), ("solve p95 (ms)", ms(solve, 95)),
        ("labels swapped back", str(window.relabelled)),
        ("skipped total", str(sum(window.skipped.values()))),
    ]
    out += [(f"skipped: {k}", str(v)) for k, v in sorted(window.skipped.items())]
    if window.with_depth or window.without_depth:
        out.append(("frames with depth", str(window.with_depth)))
        out += [(f"frames without depth: {k}", str(v)) for k, v in sorted(window.without_depth.items())]
    return out


class LifterDiagnostics:
    """Publishes ``/diagnostics`` on a timer, from its own window of the node's counter.

    Parameters
    ----------
    node : rclpy.node.Node
    period : float
        Seconds between updates; 0 = no publisher, no timer, no window.
    counter : FrameCounter
        The node's counter (this report opens its window ``"diagnostics"`` in it).

    Attributes
    ----------
    depth_warning : callable or None
        The depth input's warning now (:meth:`pose_lifter.ros.depth_input.DepthInput.silence`;
        None: no depth topic).
    """

    REPORT: Final[str] = "diagnostics"

    def __init__(self, node: Any, period: float, counter: FrameCounter) -> None:
        self._node = node
        self._counter = counter
        self._pub = None
        self.depth_warning: Callable[[], str] | None = None
        if period > 0:
            from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

            self._types = (DiagnosticArray, DiagnosticStatus, KeyValue)
            counter.open(self.REPORT)
            self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
            self._timer = node.create_timer(period, self.publish)

    def close(self) -> None:
        """Destroy the timer and the publisher (a lifecycle node's cleanup)."""
        if self._pub is not None:
            self._node.destroy_timer(self._timer)
            self._node.destroy_publisher(self._pub)
            self._counter.close(self.REPORT)
            self._pub = None

    def publish(self) -> None:
        """Publish the status of the window since the last update; a new window starts."""
        if self._pub is None:
            return
        array_t, status_t, kv_t = self._types
        window = self._counter.take(self.REPORT)
        level, message = status_level(window.frames, window.lifted, sum(window.skipped.values()),
                                      window.dropped, self.depth_warning() if self.depth_warning else "")
        status = status_t(level=bytes([level]), name=f"{self._node.get_name()}: lifter", message=message,
                          hardware_id=HARDWARE_ID, values=[kv_t(key=k, value=v) for k, v in values(window)])
        msg = array_t(status=[status])
        msg.header.stamp = self._node.get_clock().now().to_msg()
        self._pub.publish(msg)
