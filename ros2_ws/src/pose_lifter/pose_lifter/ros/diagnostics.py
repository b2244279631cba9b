"""``/diagnostics`` of the lifter node (``diagnostic_msgs/DiagnosticArray``, the ROS convention
that ``rqt_robot_monitor``, ``diagnostic_aggregator`` and Foxglove read).

Once per ``diagnostics_period`` the node publishes one ``DiagnosticStatus`` named
``"<node name>: lifter"`` (hardware id ``pose_lifter``) about the window since the last one:

========================  ===============================================================
key                       value
========================  ===============================================================
``input rate (Hz)``       keypoint frames received per second
``frames``                keypoint frames answered
``skeletons lifted``      skeletons published
``warm share``            fraction of them warm-started from their track's previous frame
``cold share``            fraction solved cold (multi-start)
``latency median (ms)``   per frame, callback in -> answer published (also ``p95``)
``solve median (ms)``     per skeleton (also ``p95``)
``skipped total``         skeletons or frames left out, and ``skipped: <kind>`` per kind
========================  ===============================================================

Levels: ``ERROR`` when skeletons came in but none could be lifted; ``WARN`` when no input came
in the window, or some inputs were skipped; ``OK`` otherwise. The message says which.
"""

from __future__ import annotations

import time
from collections import Counter
from typing import Any, Final

import numpy as np

__all__ = ["HARDWARE_ID", "LifterDiagnostics", "status_level"]

HARDWARE_ID: Final[str] = "pose_lifter"
OK: Final[int] = 0
WARN: Final[int] = 1
ERROR: Final[int] = 2


def status_level(frames: int, lifted: int, skipped: int) -> tuple[int, str]:
    """(level, message) of a window with these counts (see the module doc)."""
    if frames == 0:
        return WARN, "no input on keypoints_2d"
    if lifted == 0 and skipped > 0:
        return ERROR, f"no skeleton could be lifted ({skipped} skipped)"
    if skipped > 0:
        return WARN, f"{skipped} inputs skipped"
    return OK, "lifting"


class LifterDiagnostics:
    """Counts a node's frames and publishes ``/diagnostics`` on a timer.

    Parameters
    ----------
    node : rclpy.node.Node
    period : float
        Seconds between updates; 0 = no publisher, no timer (the counters still work).
    """

    def __init__(self, node: Any, period: float) -> None:
        self._node = node
        self._started = time.monotonic()
        self._reset()
        self._pub = None
        if period > 0:
            from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

            self._types = (DiagnosticArray, DiagnosticStatus, KeyValue)
            self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
            self._timer = node.create_timer(period, self.publish)

    def close(self) -> None:
        """Destroy the timer and the publisher (a lifecycle node's cleanup)."""
        if self._pub is not None:
            self._node.destroy_timer(self._timer)
            self._node.destroy_publisher(self._pub)
            self._pub = None

    def _reset(self) -> None:
        self._window_start = time.monotonic()
        self._frames = 0
        self._lifted = 0
        self._warm = 0
        self._latencies: list[float] = []
        self._solve: list[float] = []
        self._skipped: Counter[str] = Counter()

    def frame(self, lifted: list[Any], latency: float) -> None:
        """One answered frame: its published ``Skeleton3D`` messages and its latency (s)."""
        self._frames += 1
        self._lifted += len(lifted)
        self._warm += sum(1 for s in lifted if s.warm_started)
        self._solve.extend(float(s.solve_time) for s in lifted)
        self._latencies.append(latency)

    def skipped(self, kind: str) -> None:
        """One skipped input of a kind (as counted in the statistics line)."""
        self._skipped[kind] += 1

    def values(self) -> list[tuple[str, str]]:
        """The window's key/value pairs."""
        elapsed = max(time.monotonic() - self._window_start, 1e-9)
        lat = np.asarray(self._latencies) * 1e3
        solve = np.asarray(self._solve) * 1e3
        n = max(self._lifted, 1)

        def ms(a: Any, q: float) -> str:
            return f"{np.percentile(a, q):.2f}" if a.size else "nan"

        out = [
            ("input rate (Hz)", f"{self._frames / elapsed:.2f}"),
            ("frames", str(self._frames)),
            ("skeletons lifted", str(self._lifted)),
            ("warm share", f"{self._warm / n:.3f}" if self._lifted else "nan"),
            ("cold share", f"{(self._lifted - self._warm) / n:.3f}" if self._lifted else "nan"),
            ("latency median (ms)", ms(lat, 50)), ("latency p95 (ms)", ms(lat, 95)),
            ("solve median (ms)", ms(solve, 50)), ("solve p95 (ms)", ms(solve, 95)),
            ("skipped total", str(sum(self._skipped.values()))),
        ]
        out += [(f"skipped: {k}", str(v)) for k, v in sorted(self._skipped.items())]
        return out

    def publish(self) -> None:
        """Publish the window's status and start a new window."""
        if self._pub is None:
            return
        array_t, status_t, kv_t = self._types
        level, message = status_level(self._frames, self._lifted, sum(self._skipped.values()))
        status = status_t(level=bytes([level]), name=f"{self._node.get_name()}: lifter", message=message,
                          hardware_id=HARDWARE_ID,
                          values=[kv_t(key=k, value=v) for k, v in self.values()])
        msg = array_t(status=[status])
        msg.header.stamp = self._node.get_clock().now().to_msg()
        self._pub.publish(msg)
        self._reset()
