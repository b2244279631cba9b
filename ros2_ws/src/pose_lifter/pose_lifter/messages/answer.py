"""A frame's answer, once: its outgoing messages from its lifted skeletons.

The node publishes what :func:`frame_answer` gives and the offline lift writes it
(:func:`pose_lifter.offline.lift.lift_bag`), so a lifted bag holds what the node published:

* ``skeletons_3d`` (``Skeleton3DArray``, :func:`~pose_lifter.messages.cdr.skeleton3d_array_cdr`),
* ``skeleton_markers`` (``MarkerArray``, :class:`~pose_lifter.messages.markers.MarkerBook`),
* the REP-155 bodies and their ``/tf`` (:class:`~pose_lifter.messages.hri.BodyBook`).

The books carry what is on screen and which bodies are alive from one frame to the next; the
caller owns them (one per output stream). All CDR bytes, no rclpy, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pose_lifter.messages.cdr import SkeletonFrame, skeleton3d_array_cdr
from pose_lifter.messages.hri import BodyBook, BodyFrame
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.messages.names import MARKER_ARRAY, SKELETON3D_ARRAY, TOPIC_MARKERS, TOPIC_SKELETONS

__all__ = ["FrameAnswer", "frame_answer"]


@dataclass(frozen=True)
class FrameAnswer:
    """The serialised answer of one frame.

    Attributes
    ----------
    skeletons : bytes
        ``Skeleton3DArray`` with the input's header.
    markers : bytes or None
        ``MarkerArray`` (None: no markers book).
    bodies : BodyFrame or None
        The REP-155 messages (None: no bodies book).
    """

    skeletons: bytes
    markers: bytes | None = None
    bodies: BodyFrame | None = None

    def messages(self) -> list[tuple[str, bytes, str]]:
        """Everything, in the node's publishing order, as (default topic, CDR, type)."""
        out = [(TOPIC_SKELETONS, self.skeletons, SKELETON3D_ARRAY)]
        if self.markers is not None:
            out.append((TOPIC_MARKERS, self.markers, MARKER_ARRAY))
        return out + (self.bodies.messages() if self.bodies is not None else [])


def frame_answer(header: Any, stamp_ns: int, lifted: SkeletonFrame, *, markers: MarkerBook | None = None,
                 marker_lifetime: float = 0.0, bodies: BodyBook | None = None,
                 image_size: tuple[float, float] | None = None) -> FrameAnswer:
    """The answer of one frame: its lifted skeletons (in message order) as ``Skeleton3DArray``,
    the markers that show them (``markers``' book updated) and their REP-155 bodies (``bodies``'
    book updated).

    Parameters
    ----------
    header : the answer's ``std_msgs/Header`` (``stamp.sec``, ``stamp.nanosec``, ``frame_id``)
    stamp_ns : int
        The frame's stamp (the bodies' clock: the header's, or the arrival time when it is 0).
    lifted : SkeletonFrame
    markers, bodies : the stream's books, or None (that output off)
    marker_lifetime : float
        Seconds (0: until replaced or deleted).
    image_size : (width, height) in pixels, or None (no REP-155 ``skeleton2d`` / ``roi``)
    """
    skeletons = skeleton3d_array_cdr(header, lifted)
    shown = (markers.update(header, lifted.track_ids.tolist(), lifted.joints_m, marker_lifetime)
             if markers is not None else None)
    people = bodies.frame(stamp_ns, str(header.frame_id), lifted, image_size) if bodies is not None else None
    return FrameAnswer(skeletons, shown, people)
