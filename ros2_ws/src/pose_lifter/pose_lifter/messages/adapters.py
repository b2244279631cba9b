"""Detector messages -> ``pose_lifter_msgs/Skeleton2DArray`` (duck-typed, no rclpy import).

Two ROS detector ecosystems publish 2D skeletons in their own messages:

- yolo_ros (``yolo_msgs/DetectionArray``): one ``Detection`` per object, ``keypoints.data`` a
  *sparse* list of ``KeyPoint2D`` (``id`` 1-based in the COCO-17 order, ``point`` in pixels,
  ``score``), the tracker id a *string* ``id`` (empty when not tracked);
- ROS4HRI / REP-155 (``hri_msgs/Skeleton2D`` on ``/humans/bodies/<body_id>/skeleton2d``): 18
  OpenPose-COCO points *normalised* to [0, 1] (``x``, ``y``, ``c``), the person in the topic name.

The functions here read those fields by name, so they serve rclpy messages (the ``adapter``
node, :mod:`pose_lifter.ros.adapter_node`) and rosbags messages (bags, tests) alike, and give a
``wang12`` ``Skeleton2DArray`` (the paper's 12 joints, pixels) that the lifter takes as it is.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from typing import Any, Final

import numpy as np

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.messages.detectors import Person2D, sparse_to_model
from pose_lifter.messages.layouts import get_layout
from pose_lifter.messages.names import YOLO_DETECTION_ARRAY

__all__ = [
    "HRI_SKELETON_TOPIC",
    "INPUT_TYPES",
    "TrackIds",
    "hri_body_id",
    "hri_skeleton_to_person",
    "people_to_skeleton2d_array",
    "yolo_detections_to_people",
]

#: ``input_type`` -> full ROS message type of the adapter's input.
INPUT_TYPES: Final[dict[str, str]] = {
    "yolo": YOLO_DETECTION_ARRAY,
    "hri": "hri_msgs/msg/Skeleton2D",
}
#: REP-155 topic of one body's 2D skeleton; group 1 is the body id.
HRI_SKELETON_TOPIC: Final[re.Pattern[str]] = re.compile(r"^/humans/bodies/([^/]+)/skeleton2d$")


class TrackIds:
    """Stable integer track ids for the string ids detectors use.

    A string that is a non-negative decimal integer (yolo_ros' tracker: ``"3"``) keeps its
    number; any other non-empty string (REP-155 body ids such as ``"b4f2a"``) gets the next id
    from ``2**40`` on, the same one every time it comes back. Empty -> -1 (untracked).
    """

    FIRST_NAMED: Final[int] = 1 << 40

    def __init__(self, max_named: int = 100_000) -> None:
        self._named: dict[str, int] = {}
        self._max_named = max_named

    def __call__(self, value: str) -> int:
        text = str(value).strip()
        if not text:
            return -1
        if text.isdecimal() and int(text) < self.FIRST_NAMED:
            return int(text)
        tid = self._named.get(text)
        if tid is None:
            if len(self._named) >= self._max_named:  # a peer inventing ids forever: start over
                self._named.clear()
            tid = self.FIRST_NAMED + len(self._named)
            self._named[text] = tid
        return tid


def yolo_detections_to_people(
    msg: Any,
    track_ids: TrackIds,
    layout: str = "coco17",
    class_names: Sequence[str] = ("person",),
    id_base: int = 1,
) -> tuple[list[Person2D], list[str]]:
    """The people of a ``yolo_msgs/DetectionArray``.

    Parameters
    ----------
    msg : DetectionArray-like
    track_ids : TrackIds
        Maps ``Detection.id`` to integers (kept across messages).
    layout : str
        Keypoint layout of the pose model (yolo pose models: COCO-17).
    class_names : sequence of str
        Detections of other classes are ignored; empty = every class with keypoints.
    id_base : int
        Id of the first keypoint (yolo_ros: 1).

    Returns
    -------
    people : list of Person2D
    problems : list of str
        One line per detection that was left out (bad keypoint ids, non-finite values).
    """
    lay = get_layout(layout)
    people: list[Person2D] = []
    problems: list[str] = []
    for det in msg.detections:
        if class_names and str(det.class_name) not in class_names:
            continue
        kps = list(det.keypoints.data)
        if not kps:
            continue
        tid = track_ids(det.id)
        try:
            points, conf = sparse_to_model(
                [int(k.id) for k in kps], [[float(k.point.x), float(k.point.y)] for k in kps],
                [float(k.score) for k in kps], lay, id_base=id_base)
        except InvalidInputError as err:
            problems.append(f"detection {str(det.id)!r}: {err}")
            continue
        people.append(Person2D(points, conf, tid))
    return people, problems


def hri_skeleton_to_person(msg: Any, image_size: tuple[float, float], track_id: int) -> Person2D:
    """One ``hri_msgs/Skeleton2D`` (18 normalised OpenPose-COCO points) as a person in pixels.

    Raises
    ------
    InvalidInputError
        Not 18 points, non-finite values, or a bad image size.
    """
    from pose_lifter.messages.detectors import dense_to_model

    pts = list(msg.skeleton)
    xy = np.array([[float(p.x), float(p.y)] for p in pts], dtype=np.float64).reshape(len(pts), 2)
    conf = np.array([float(p.c) for p in pts], dtype=np.float64)
    points, c = dense_to_model(xy, conf, "coco18", image_size)
    return Person2D(points, c, int(track_id))


def hri_body_id(topic: str) -> str | None:
    """The body id of a REP-155 ``/humans/bodies/<id>/skeleton2d`` topic (None for other topics)."""
    match = HRI_SKELETON_TOPIC.match(topic)
    return match.group(1) if match else None


def people_to_skeleton2d_array(header: Any, people: Iterable[Person2D], types: Any) -> Any:
    """A ``wang12`` ``Skeleton2DArray`` (the model joints, pixels) with ``header``."""
    skeletons = [
        types.Skeleton2D(track_id=int(p.track_id), keypoints=[
            types.Keypoint2D(x=float(x), y=float(y), confidence=float(c))
            for (x, y), c in zip(p.points, p.confidence, strict=True)])
        for p in people
    ]
    return types.Skeleton2DArray(header=header, layout="wang12", skeletons=skeletons)
