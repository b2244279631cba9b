"""2D keypoint layouts of common detectors, mapped onto the paper's 12 joints, and a frame's
``Skeleton2D`` messages read through them (:func:`frame_joints`).

A detector's keypoint order is a property of its messages: the core reads the 12 joints only.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.errors import InvalidInputError, UnknownLayoutError
from pose_lifter.core.model.skeleton import JOINT_NAMES, N_JOINTS

__all__ = ["ALIASES", "LAYOUTS", "Layout", "frame_joints", "get_layout", "to_model_joints"]


@dataclass(frozen=True)
class Layout:
    """A detector's keypoint layout.

    Attributes
    ----------
    name : str
    n_keypoints : int
        Keypoints per skeleton in this layout.
    model_indices : tuple of int, length 12
        ``model_indices[j]`` is the layout index of the paper's joint ``j``
        (order of :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`).
    """

    name: str
    n_keypoints: int
    model_indices: tuple[int, ...]

    @functools.cached_property
    def index_array(self) -> NDArray[np.intp]:
        """``model_indices`` as an index array (12,)."""
        return np.asarray(self.model_indices, dtype=np.intp)


LAYOUTS: Final[dict[str, Layout]] = {
    # COCO-17: 5 l_sho, 6 r_sho, 7 l_elb, 8 r_elb, 9 l_wri, 10 r_wri, 11 l_hip, 12 r_hip,
    # 13 l_knee, 14 r_knee, 15 l_ank, 16 r_ank.
    "coco17": Layout("coco17", 17, (5, 7, 9, 6, 8, 10, 11, 13, 15, 12, 14, 16)),
    # Human3.6M 17: 1 r_hip, 2 r_knee, 3 r_ank, 4 l_hip, 5 l_knee, 6 l_ank, 11 l_sho,
    # 12 l_elb, 13 l_wri, 14 r_sho, 15 r_elb, 16 r_wri.
    "h36m17": Layout("h36m17", 17, (11, 12, 13, 14, 15, 16, 4, 5, 6, 1, 2, 3)),
    # OpenPose BODY_25: 2 r_sho, 3 r_elb, 4 r_wri, 5 l_sho, 6 l_elb, 7 l_wri, 9 r_hip,
    # 10 r_knee, 11 r_ank, 12 l_hip, 13 l_knee, 14 l_ank.
    "body25": Layout("body25", 25, (5, 6, 7, 2, 3, 4, 12, 13, 14, 9, 10, 11)),
    # OpenPose COCO-18, also ROS4HRI / REP-155 ``hri_msgs/Skeleton2D``: 0 nose, 1 neck, 2 r_sho,
    # 3 r_elb, 4 r_wri, 5 l_sho, 6 l_elb, 7 l_wri, 8 r_hip, 9 r_knee, 10 r_ank, 11 l_hip,
    # 12 l_knee, 13 l_ank, 14-17 eyes and ears.
    "coco18": Layout("coco18", 18, (5, 6, 7, 2, 3, 4, 11, 12, 13, 8, 9, 10)),
    # Halpe-26 (AlphaPose, RTMPose body7/halpe): COCO-17 first, then 17 head, 18 neck, 19 hip,
    # 20-25 feet.
    "halpe26": Layout("halpe26", 26, (5, 7, 9, 6, 8, 10, 11, 13, 15, 12, 14, 16)),
    # MediaPipe BlazePose 33: 11 l_sho, 12 r_sho, 13 l_elb, 14 r_elb, 15 l_wri, 16 r_wri,
    # 23 l_hip, 24 r_hip, 25 l_knee, 26 r_knee, 27 l_ank, 28 r_ank.
    "mediapipe33": Layout("mediapipe33", 33, (11, 13, 15, 12, 14, 16, 23, 25, 27, 24, 26, 28)),
    # COCO-WholeBody 133 (RTMPose / MMPose wholebody): its body part is COCO-17 (0-16), then
    # 6 feet, 68 face and 42 hand keypoints.
    "coco_wholebody133": Layout("coco_wholebody133", 133, (5, 7, 9, 6, 8, 10, 11, 13, 15, 12, 14, 16)),
    # The paper's own 12 joints.
    "wang12": Layout("wang12", 12, tuple(range(N_JOINTS))),
}

#: Other names people use for the layouts above.
ALIASES: Final[dict[str, str]] = {
    "coco": "coco17",
    "openpose18": "coco18",
    "rep155": "coco18",
    "hri": "coco18",
    "openpose25": "body25",
    "halpe": "halpe26",
    "blazepose": "mediapipe33",
    "mediapipe": "mediapipe33",
    "wholebody": "coco_wholebody133",
    "coco_wholebody": "coco_wholebody133",
}


def get_layout(name: str) -> Layout:
    """Look up a layout by name or alias (``coco17``, ``coco18``, ``halpe26``, ``mediapipe33``, ...)."""
    try:
        key = name.strip().lower()
        return LAYOUTS[ALIASES.get(key, key)]
    except (KeyError, AttributeError):
        raise UnknownLayoutError(
            f"unknown keypoint layout {name!r}; expected one of {sorted(LAYOUTS)}"
        ) from None


def to_model_joints(
    keypoints: NDArray[np.float64], confidence: NDArray[np.float64] | None, layout: str | Layout
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Select the paper's 12 joints from a detector skeleton.

    Parameters
    ----------
    keypoints : ndarray, shape (K, 2)
        Pixels, in the layout's order.
    confidence : ndarray, shape (K,), or None
        Per-keypoint confidence in [0, 1]; None means all 1.
    layout : str or Layout

    Returns
    -------
    points : ndarray, shape (12, 2)
    confidence : ndarray, shape (12,)
    """
    lay = layout if isinstance(layout, Layout) else get_layout(layout)
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.shape != (lay.n_keypoints, 2):
        raise InvalidInputError(
            f"layout {lay.name!r} needs keypoints of shape ({lay.n_keypoints}, 2), got {kp.shape}"
        )
    if confidence is None:
        conf = np.ones(lay.n_keypoints)
    else:
        conf = np.asarray(confidence, dtype=np.float64)
        if conf.shape != (lay.n_keypoints,):
            raise InvalidInputError(
                f"layout {lay.name!r} needs {lay.n_keypoints} confidences, got shape {conf.shape}"
            )
    idx = lay.index_array
    return kp[idx], conf[idx]  # integer indexing: copies


def frame_joints(skeletons: Sequence[Any], layout: str | Layout
                 ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]] | Exception]:
    """The paper's 12 joints of each ``Skeleton2D`` of one frame, the frame's ``layout`` (a name
    or a :class:`Layout`) looked up once: per skeleton, in order,
    ``(points (12, 2) pixels, confidence (12,))``, or the error that refused it (a malformed
    skeleton costs only itself: :class:`~pose_lifter.core.errors.InvalidInputError` for a wrong
    keypoint count or non-finite values). Joints whose confidence is 0 (missing) may carry
    non-finite coordinates; they are returned as 0.

    Raises
    ------
    UnknownLayoutError
        Unknown layout name (the whole frame is unusable).
    """
    read: list[tuple[NDArray[np.float64], NDArray[np.float64]] | Exception] = []
    for skel in skeletons:
        try:
            read.append(_keypoints(skel))
        except Exception as err:
            read.append(err)
    lay = layout if isinstance(layout, Layout) else get_layout(layout)
    out: list[tuple[NDArray[np.float64], NDArray[np.float64]] | Exception] = []
    for r in read:
        if isinstance(r, Exception):
            out.append(r)
            continue
        try:
            points, confidence = to_model_joints(*r, lay)
        except Exception as err:
            out.append(err)
            continue
        if not np.isfinite(confidence).all():
            out.append(InvalidInputError("keypoint confidences must be finite"))
            continue
        bad = ~np.isfinite(points).all(axis=1)
        if bad.any():
            if (bad & (confidence > 0)).any():
                names = [JOINT_NAMES[j] for j in np.flatnonzero(bad & (confidence > 0))]
                out.append(InvalidInputError(f"non-finite keypoint coordinates for visible joints {names}"))
                continue
            points[bad] = 0.0  # missing joints (confidence 0) may carry any coordinates
        out.append((points, confidence))
    return out


def _keypoints(skel: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A ``Skeleton2D``'s keypoints as given: pixels (K, 2) and confidences (K,)."""
    xyc = getattr(skel, "xyc", None)  # pose_lifter.messages.cdr.DecodedSkeleton2D: the keypoints as one array
    if xyc is not None:
        return xyc[:, :2], xyc[:, 2]
    kps = list(skel.keypoints)
    xy = np.array([[float(k.x), float(k.y)] for k in kps], dtype=np.float64).reshape(len(kps), 2)
    return xy, np.array([float(k.confidence) for k in kps], dtype=np.float64)
