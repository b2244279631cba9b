"""``pose-lifter play BAG``: publish a bag's topics into the live ROS graph at the bag's rate.

What ``ros2 bag play`` does for the node, without ros2cli or rosbag2: each message is published
as the serialised bytes stored in the bag (rclpy publishes raw CDR), on a reliable publisher,
paced by the bag's log times divided by ``rate``. Needs a sourced workspace (the message
packages of the topics played, e.g. ``pose_lifter_msgs``)::

    source ros2_ws/install/setup.bash
    ros2 run pose_lifter lifter &
    pose-lifter play bags/walk_clean.mcap

A message published before discovery has matched a subscriber is lost, so the first message
waits (up to ``wait`` seconds, :data:`DEFAULT_WAIT_S` by default) for a subscriber on each played
topic a lifter reads (:func:`lifter_topics`: the keypoints and ``camera_info``, known by their
types), not on those no node may read (the ground truth); when it gives up it says so on stderr
and plays anyway.
"""

from __future__ import annotations

import importlib
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from pose_lifter.messages.names import CAMERA_INFO, SKELETON2D_ARRAY, YOLO_DETECTION_ARRAY
from pose_lifter.offline.bags import BagError, bag_topics, read_raw

__all__ = ["DEFAULT_WAIT_S", "lifter_topics", "message_class", "play_bag"]

#: Seconds ``play`` waits by default for a subscriber on the topics a lifter reads.
DEFAULT_WAIT_S: Final[float] = 5.0
#: The message types a lifter (or its adapter) subscribes to.
_LIFTER_READS: Final[frozenset[str]] = frozenset((SKELETON2D_ARRAY, YOLO_DETECTION_ARRAY, CAMERA_INFO))


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)


def lifter_topics(types: Mapping[str, str]) -> list[str]:
    """The topics of ``types`` (topic -> message type) a lifter reads: keypoints (the types
    ``pose-lifter lift`` lifts, :data:`pose_lifter.offline.lift.LIFTABLE_TYPES`) and
    ``sensor_msgs/msg/CameraInfo``; sorted."""
    return sorted(t for t, kind in types.items() if kind in _LIFTER_READS)


def message_class(msgtype: str) -> Any:
    """The rclpy class of ``pkg/msg/Name`` (BagError when its package is not importable)."""
    pkg, kind, name = msgtype.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError):
        raise BagError(f"cannot play {msgtype}: the {pkg} Python package is not importable "
                       f"(source the workspace that has it, or leave its topic out with --topics)") from None


def play_bag(
    bag: str | Path,
    topics: Sequence[str] | None = None,
    rate: float = 1.0,
    wait: float = DEFAULT_WAIT_S,
    log: Callable[[str], None] = print,
    warn: Callable[[str], None] = _stderr,
) -> int:
    """Publish the messages of ``topics`` (all when None) of ``bag``; returns how many.

    Parameters
    ----------
    bag : path
    topics : sequence of str, optional
    rate : float
        Speed factor (2 = twice as fast); > 0.
    wait : float
        Seconds to wait, before the first message, for a subscriber on each played topic a
        lifter reads (:func:`lifter_topics`; every played topic when none is one of those);
        0: do not wait. After the match, 0.5 s more for the readers' side of discovery.
    log : callable
        Progress lines.
    warn : callable
        The line said when the wait gives up (default: to stderr).
    """
    if not rate > 0:
        raise BagError(f"rate must be > 0, got {rate}")
    available = bag_topics(bag)
    chosen = sorted(available) if topics is None else list(topics)
    missing = sorted(set(chosen) - set(available))
    if missing:
        raise BagError(f"{bag} has no topic(s) {missing}; its topics: {sorted(available)}")
    classes = {t: message_class(available[t]) for t in chosen}

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node("pose_lifter_play")
    try:
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        pubs = {t: node.create_publisher(classes[t], t, qos) for t in chosen}
        waited = {t: pubs[t] for t in lifter_topics({t: available[t] for t in chosen}) or chosen}
        if wait > 0:
            deadline = time.monotonic() + wait
            while any(p.get_subscription_count() == 0 for p in waited.values()):
                if time.monotonic() > deadline:
                    lonely = sorted(t for t, p in waited.items() if p.get_subscription_count() == 0)
                    warn(f"play: no subscriber after {wait:g} s on {lonely}; playing anyway "
                         "(their first messages may be lost)")
                    break
                time.sleep(0.05)
            else:
                time.sleep(0.5)
        n = 0
        start_wall = time.monotonic()
        start_bag: int | None = None
        for raw in read_raw(bag, chosen):
            if start_bag is None:
                start_bag = raw.stamp_ns
            due = start_wall + (raw.stamp_ns - start_bag) / 1e9 / rate
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            pubs[raw.topic].publish(raw.data)
            n += 1
        for p in pubs.values():
            p.wait_for_all_acked(rclpy.duration.Duration(seconds=5.0))
        log(f"play: {n} messages on {len(chosen)} topics in {time.monotonic() - start_wall:.1f} s")
        return n
    finally:
        node.destroy_node()
        rclpy.utilities.try_shutdown()
