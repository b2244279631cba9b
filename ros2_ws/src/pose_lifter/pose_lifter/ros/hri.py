"""The node's REP-155 (ros4hri) outputs: ``/humans/bodies/...`` topics and ``/tf``.

The messages are :mod:`pose_lifter.messages.hri`'s (serialised, published as they are); this
module owns the publishers: the shared ones (``/humans/bodies/tracked``, ``/tf``) and, per body,
``skeleton2d``, ``roi``, ``joint_states`` and the latched ``urdf``, created when the body appears
and destroyed when it leaves (its track is forgotten), so that its topics disappear from the
graph with it.
"""

from __future__ import annotations

import importlib
from types import SimpleNamespace
from typing import Any, Final

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from pose_lifter.messages import hri

__all__ = ["HriOutputs", "message_classes"]

#: /tf as tf2's TransformBroadcaster publishes it (reliable, volatile, 100 deep).
TF_QOS: Final[QoSProfile] = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: The URDF, latched: a subscriber that joins later still gets it.
LATCHED_QOS: Final[QoSProfile] = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
_QOS: Final[QoSProfile] = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def message_classes() -> SimpleNamespace:
    """The rclpy classes of the REP-155 outputs, by message name (``IdsList``, ``TFMessage``...).

    Raises
    ------
    ImportError
        A message package is not installed, or its messages' fields are not the ones the
        outputs are written for (:func:`hri.layout_mismatches`).
    """
    classes: dict[str, Any] = {}
    for name in hri.LAYOUTS:
        pkg, _, cls = name.split("/")
        try:
            classes[cls] = getattr(importlib.import_module(f"{pkg}.msg"), cls)
        except ImportError as err:
            raise ImportError(f"{pkg} is not installed ({err})") from err
    wrong = hri.layout_mismatches(list(classes.values()))
    if wrong:
        raise ImportError(f"the installed {', '.join(wrong)} differ from the layout the node writes")
    return SimpleNamespace(**classes)


class HriOutputs:
    """Publishes one frame's :class:`~pose_lifter.messages.hri.BodyFrame`.

    Parameters
    ----------
    node : rclpy Node
    types : namespace of the REP-155 message classes (:func:`message_classes`)
    timeout_s : float
        Seconds (input stamps) after which a body not lifted leaves (the node's ``track_timeout``).
    """

    def __init__(self, node: Node, types: Any, timeout_s: float) -> None:
        self._node = node
        self.book = hri.BodyBook(timeout_s)
        self._class = {name: getattr(types, name.rsplit("/", 1)[1]) for name in hri.LAYOUTS}
        self._shared = {f"{hri.BODIES_NS}/tracked": node.create_publisher(types.IdsList,
                                                                         f"{hri.BODIES_NS}/tracked", _QOS),
                        hri.TF_TOPIC: node.create_publisher(types.TFMessage, hri.TF_TOPIC, TF_QOS)}
        self._pubs: dict[str, Any] = dict(self._shared)  # topic -> its publisher
        self._bodies: dict[str, list[str]] = {}  # body id -> its topics

    def publish(self, out: hri.BodyFrame) -> None:
        """Publish a frame's bodies (built by :attr:`book`: :meth:`hri.BodyFrame.messages`, new
        bodies' publishers created first); the publishers of bodies that left are destroyed."""
        for bid in out.gone:
            self._drop(bid)
        for bid in out.new:
            self._bodies[bid] = []
            for kind, msgtype in hri.PER_BODY.items():
                topic = f"{hri.BODIES_NS}/{bid}/{kind}"
                self._pubs[topic] = self._node.create_publisher(
                    self._class[msgtype], topic, LATCHED_QOS if kind == "urdf" else _QOS)
                self._bodies[bid].append(topic)
        for topic, data, _ in out.messages():
            self._pubs[topic].publish(data)

    def clear(self) -> None:
        """Every body leaves (the node deactivates or its tracks are cleared)."""
        for bid in self.book.clear():
            self._drop(bid)

    def close(self) -> None:
        """Destroy every publisher."""
        self.clear()
        for pub in self._shared.values():
            self._node.destroy_publisher(pub)

    def _drop(self, bid: str) -> None:
        for topic in self._bodies.pop(bid, []):
            self._node.destroy_publisher(self._pubs.pop(topic))
