"""From what 2D pose detectors output to the paper's 12 joints (pixels + confidence).

Every converter returns :class:`Person2D` objects: the model joints in the order of
:data:`pose_lifter.core.model.skeleton.JOINT_NAMES`, in image pixels, with a confidence per joint
(0 = missing) and a track id (-1 = untracked). They are what :meth:`pose_lifter.core.Lifter.lift`
takes, and what the ROS adapter (:mod:`pose_lifter.messages.adapters`) publishes as a ``wang12``
``Skeleton2DArray``.

Three shapes cover the detectors people run:

- dense arrays, one row per keypoint in a known layout (:func:`dense_to_model`,
  :func:`batch_to_model`): RTMPose / rtmlib, MMPose, ultralytics YOLO-pose, OpenPose JSON;
- sparse keypoint lists with ids (:func:`sparse_to_model`): ``yolo_msgs/KeyPoint2DArray``
  (1-based ids, only keypoints above the detector's threshold);
- normalised coordinates in [0, 1] (``image_size=(width, height)``): MediaPipe,
  ``hri_msgs/Skeleton2D`` (REP-155).

The library result objects are read by attribute (duck typing); this module imports none of
the detector libraries, and accepts torch tensors wherever arrays are expected (``.cpu()``,
``.numpy()``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InvalidInputError
from ..core.model.skeleton import JOINT_NAMES
from .layouts import Layout, get_layout, to_model_joints

__all__ = [
    "LAYOUT_FOR_COUNT",
    "Person2D",
    "as_array",
    "batch_to_model",
    "dense_to_model",
    "from_mediapipe",
    "from_mmpose",
    "from_openpose_json",
    "from_ultralytics",
    "guess_layout",
    "sparse_to_model",
]

#: The layout assumed for a number of keypoints per person when none is given.
LAYOUT_FOR_COUNT: Final[dict[int, str]] = {
    12: "wang12", 17: "coco17", 18: "coco18", 25: "body25", 26: "halpe26", 33: "mediapipe33",
    133: "coco_wholebody133",
}


@dataclass(frozen=True)
class Person2D:
    """One detected person, in the paper's 12 joints.

    Attributes
    ----------
    points : ndarray, shape (12, 2)
        Pixels (x right, y down, origin top-left). 0 where a joint is missing.
    confidence : ndarray, shape (12,)
        In [0, 1]; 0 = missing.
    track_id : int
        The detector's tracking id, -1 when untracked.
    """

    points: NDArray[np.float64]
    confidence: NDArray[np.float64]
    track_id: int = -1


def as_array(value: Any, dtype: type = np.float64) -> NDArray[Any]:
    """A numpy array from an array, a list or a torch tensor (moved to the CPU first)."""
    if hasattr(value, "detach"):
        value = value.detach()
    if hasattr(value, "cpu"):
        value = value.cpu()
    if hasattr(value, "numpy") and not isinstance(value, np.ndarray):
        value = value.numpy()
    return np.asarray(value, dtype=dtype)


def guess_layout(n_keypoints: int) -> Layout:
    """The layout of a detector that gives ``n_keypoints`` keypoints per person.

    17 is taken as COCO-17 (the output of every COCO-trained detector); pass ``h36m17``
    explicitly for Human3.6M-ordered keypoints.
    """
    try:
        return get_layout(LAYOUT_FOR_COUNT[int(n_keypoints)])
    except KeyError:
        raise InvalidInputError(
            f"no known layout has {n_keypoints} keypoints per person "
            f"(known counts: {sorted(LAYOUT_FOR_COUNT)}); pass the layout explicitly") from None


def _layout(layout: str | Layout | None, n_keypoints: int) -> Layout:
    if layout is None:
        return guess_layout(n_keypoints)
    return layout if isinstance(layout, Layout) else get_layout(layout)


def _scale(image_size: tuple[float, float] | None) -> NDArray[np.float64]:
    if image_size is None:
        return np.ones(2)
    size = np.asarray(image_size, dtype=np.float64)
    if size.shape != (2,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
        raise InvalidInputError(f"image_size must be (width, height) > 0, got {image_size!r}")
    return size


def _clean(points: NDArray[np.float64], confidence: NDArray[np.float64]
           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Check finiteness: missing joints (confidence 0) may be NaN and become 0."""
    if not np.all(np.isfinite(confidence)):
        raise InvalidInputError("keypoint confidences must be finite")
    conf = np.clip(confidence, 0.0, 1.0)
    bad = ~np.all(np.isfinite(points), axis=1)
    if np.any(bad & (conf > 0)):
        names = [JOINT_NAMES[j] for j in np.flatnonzero(bad & (conf > 0))]
        raise InvalidInputError(f"non-finite keypoint coordinates for visible joints {names}")
    pts = points.copy()
    pts[bad] = 0.0
    return pts, conf


def dense_to_model(
    keypoints: Any,
    confidence: Any | None = None,
    layout: str | Layout | None = None,
    image_size: tuple[float, float] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One person's keypoints in a layout's order -> the model joints.

    Parameters
    ----------
    keypoints : array-like, shape (K, 2) or (K, 3)
        x, y (and the confidence as a third column when ``confidence`` is None).
    confidence : array-like, shape (K,), optional
        None and two columns: all 1.
    layout : str or Layout, optional
        Default: from K (:func:`guess_layout`).
    image_size : (width, height), optional
        Given: the coordinates are normalised to [0, 1] and are multiplied by it.

    Returns
    -------
    points : ndarray, shape (12, 2)
        Pixels.
    confidence : ndarray, shape (12,)
    """
    kp = as_array(keypoints)
    if kp.ndim != 2 or kp.shape[1] not in (2, 3):
        raise InvalidInputError(f"keypoints of shape (K, 2) or (K, 3) expected, got {kp.shape}")
    if confidence is None:
        conf = kp[:, 2] if kp.shape[1] == 3 else np.ones(kp.shape[0])
    else:
        conf = as_array(confidence).reshape(-1)
    lay = _layout(layout, kp.shape[0])
    points, conf12 = to_model_joints(kp[:, :2] * _scale(image_size), conf, lay)
    return _clean(points, conf12)


def sparse_to_model(
    ids: Sequence[int] | NDArray[np.int64],
    keypoints: Any,
    confidence: Any,
    layout: str | Layout,
    id_base: int = 0,
    image_size: tuple[float, float] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A sparse keypoint list (only the detected keypoints, each with its layout id) -> model joints.

    Keypoints not in the list are missing (confidence 0).

    Parameters
    ----------
    ids : sequence of int
        Layout index of each keypoint plus ``id_base`` (yolo_ros numbers keypoints from 1).
    keypoints : array-like, shape (n, 2)
    confidence : array-like, shape (n,)
    layout : str or Layout
    id_base : int
        The id of the layout's first keypoint.
    image_size : (width, height), optional
        Normalised coordinates (see :func:`dense_to_model`).

    Raises
    ------
    InvalidInputError
        An id outside the layout, a repeated id, or lengths that do not match.
    """
    lay = layout if isinstance(layout, Layout) else get_layout(layout)
    idx = np.asarray(ids, dtype=np.int64).reshape(-1) - int(id_base)
    xy = as_array(keypoints).reshape(-1, 2) if len(idx) else np.zeros((0, 2))
    conf = as_array(confidence).reshape(-1)
    if xy.shape[0] != idx.shape[0] or conf.shape[0] != idx.shape[0]:
        raise InvalidInputError(
            f"{idx.shape[0]} ids, {xy.shape[0]} points and {conf.shape[0]} confidences: lengths differ")
    if np.any((idx < 0) | (idx >= lay.n_keypoints)):
        bad = sorted({int(i) + id_base for i in idx[(idx < 0) | (idx >= lay.n_keypoints)]})
        raise InvalidInputError(f"keypoint ids {bad} are outside layout {lay.name!r} "
                                f"(ids {id_base}..{id_base + lay.n_keypoints - 1})")
    if len(np.unique(idx)) != len(idx):
        raise InvalidInputError("a keypoint id appears twice in one skeleton")
    dense = np.zeros((lay.n_keypoints, 2))
    dense_conf = np.zeros(lay.n_keypoints)
    dense[idx] = xy * _scale(image_size)
    dense_conf[idx] = conf
    points, conf12 = to_model_joints(dense, dense_conf, lay)
    return _clean(points, conf12)


def batch_to_model(
    keypoints: Any,
    confidence: Any | None = None,
    layout: str | Layout | None = None,
    track_ids: Iterable[int] | Any | None = None,
    image_size: tuple[float, float] | None = None,
) -> list[Person2D]:
    """Several people at once: arrays of shape (N, K, 2|3) (and (N, K) confidences).

    This is the output of rtmlib (``keypoints, scores = model(image)``), of MMPose's
    ``pred_instances`` and of ultralytics' ``result.keypoints.data``.

    Parameters
    ----------
    keypoints : array-like, shape (N, K, 2) or (N, K, 3)
    confidence : array-like, shape (N, K), optional
    layout : str or Layout, optional
        Default: from K.
    track_ids : N ints, optional
        Default: all untracked (-1).
    image_size : (width, height), optional
        Normalised coordinates.
    """
    kp = as_array(keypoints)
    if kp.size == 0:
        return []
    if kp.ndim == 2:  # one person
        kp = kp[None]
    if kp.ndim != 3 or kp.shape[2] not in (2, 3):
        raise InvalidInputError(f"keypoints of shape (N, K, 2) or (N, K, 3) expected, got {kp.shape}")
    n, k = kp.shape[:2]
    conf = None if confidence is None else as_array(confidence).reshape(n, k)
    ids = [-1] * n if track_ids is None else [int(t) for t in as_array(track_ids, np.float64).reshape(-1)]
    if len(ids) != n:
        raise InvalidInputError(f"{len(ids)} track ids for {n} people")
    lay = _layout(layout, k)
    out = []
    for i in range(n):
        points, c = dense_to_model(kp[i], None if conf is None else conf[i], lay, image_size)
        out.append(Person2D(points, c, ids[i]))
    return out


def from_ultralytics(result: Any, layout: str | Layout = "coco17") -> list[Person2D]:
    """People of an ultralytics YOLO-pose ``Results`` (one image).

    Reads ``result.keypoints.xy`` (N, 17, 2 pixels), ``result.keypoints.conf`` (N, 17; None for
    models without keypoint confidences) and ``result.boxes.id`` (tracker ids after
    ``model.track(...)``, else None).
    """
    kps = getattr(result, "keypoints", None)
    if kps is None:
        return []
    xy = as_array(kps.xy)
    conf = None if getattr(kps, "conf", None) is None else as_array(kps.conf)
    boxes = getattr(result, "boxes", None)
    ids = None if boxes is None or getattr(boxes, "id", None) is None else as_array(boxes.id)
    return batch_to_model(xy, conf, layout, ids, None)


def _landmark_lists(result: Any) -> list[Sequence[Any]]:
    """The landmark lists of a MediaPipe result (Tasks API or legacy solutions API)."""
    if hasattr(result, "pose_landmarks"):  # PoseLandmarkerResult or legacy solution output
        lms = result.pose_landmarks
        if lms is None:
            return []
        if hasattr(lms, "landmark"):  # legacy: one NormalizedLandmarkList
            return [list(lms.landmark)]
        return [list(p) for p in lms]  # Tasks: one list of NormalizedLandmark per person
    if hasattr(result, "landmark"):
        return [list(result.landmark)]
    seq = list(result)
    if seq and hasattr(seq[0], "x"):
        return [seq]
    return [list(p) for p in seq]


def from_mediapipe(result: Any, image_size: tuple[float, float]) -> list[Person2D]:
    """People of a MediaPipe pose result (33 BlazePose landmarks, normalised to the image).

    Accepts a Tasks ``PoseLandmarkerResult`` (``.pose_landmarks``: a list of 33-landmark lists),
    a legacy ``mp.solutions.pose`` result (``.pose_landmarks.landmark``), or landmark lists.
    The confidence is each landmark's ``visibility`` (1 when absent).

    Parameters
    ----------
    result : MediaPipe result
    image_size : (width, height)
        Pixels of the image the landmarks were found in.
    """
    out = []
    for landmarks in _landmark_lists(result):
        xy = np.array([[float(lm.x), float(lm.y)] for lm in landmarks]).reshape(-1, 2)
        vis = np.array([1.0 if getattr(lm, "visibility", None) is None else float(lm.visibility)
                        for lm in landmarks])
        points, conf = dense_to_model(xy, vis, "mediapipe33", image_size)
        out.append(Person2D(points, conf, -1))
    return out


def from_mmpose(result: Any, layout: str | Layout | None = None) -> list[Person2D]:
    """People of an MMPose result.

    Accepts a ``PoseDataSample`` (``.pred_instances.keypoints`` (N, K, 2) and
    ``.keypoint_scores`` (N, K)), one item of ``MMPoseInferencer`` output (a dict with
    ``"predictions"``: a list, per image, of instance dicts with ``"keypoints"`` and
    ``"keypoint_scores"``), or a list of such instance dicts. The layout follows from K when not
    given (17 COCO, 26 Halpe, 133 COCO-WholeBody).
    """
    pred = getattr(result, "pred_instances", None)
    if pred is not None:
        return batch_to_model(pred.keypoints, getattr(pred, "keypoint_scores", None), layout)
    instances: Any = result
    if isinstance(result, dict):
        instances = result.get("predictions", [result])
        if instances and isinstance(instances[0], list | tuple):  # per image: take the first
            instances = instances[0]
    out = []
    for inst in instances:
        points, conf = dense_to_model(inst["keypoints"], inst.get("keypoint_scores"), layout)
        tid = inst.get("track_id", -1)
        out.append(Person2D(points, conf, -1 if tid is None else int(tid)))
    return out


def from_openpose_json(frame: dict[str, Any], layout: str | Layout | None = None) -> list[Person2D]:
    """People of one OpenPose ``--write_json`` frame (``people[i]["pose_keypoints_2d"]``: x, y, c
    flattened; BODY_25 or COCO-18 by length)."""
    out = []
    for person in frame.get("people", []):
        flat = as_array(person["pose_keypoints_2d"])
        if flat.size % 3:
            raise InvalidInputError(f"pose_keypoints_2d has {flat.size} values, not a multiple of 3")
        points, conf = dense_to_model(flat.reshape(-1, 3), None, layout)
        tid = person.get("person_id", -1)
        tid = tid[0] if isinstance(tid, list) and tid else tid
        out.append(Person2D(points, conf, int(tid) if isinstance(tid, int | float) else -1))
    return out
