"""Test poses in the layouts detectors publish (shared by tests/messages/test_adapters.py and the graph
tests): one standing person, imaged, and laid out as each layout's own definition says."""

from __future__ import annotations

import numpy as np
from pose_lifter.messages.layouts import get_layout

# A standing person (metres, y up) in the model's joint order.
STANDING = np.array([
    [0.19, 1.42, 0.0], [0.24, 1.13, 0.05], [0.26, 0.88, 0.12],
    [-0.19, 1.42, 0.0], [-0.24, 1.13, 0.05], [-0.26, 0.88, 0.12],
    [0.10, 0.92, 0.0], [0.11, 0.50, 0.03], [0.11, 0.08, 0.0],
    [-0.10, 0.92, 0.0], [-0.11, 0.50, 0.03], [-0.11, 0.08, 0.0],
])


def model_xy(yaw_deg: float = 30.0) -> np.ndarray:
    """Pixels (640x480 image) of STANDING seen from a yaw angle, model joint order."""
    a = np.deg2rad(yaw_deg)
    x = STANDING[:, 0] * np.cos(a) + STANDING[:, 2] * np.sin(a)
    return np.column_stack([320.0 - 150.0 * x, 400.0 - 150.0 * STANDING[:, 1]])


def coco17(xy12: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A COCO-17 detection: body joints at the COCO indices, face keypoints elsewhere."""
    kp = np.full((17, 2), 300.0)
    kp[:5] = [[320, 170], [315, 165], [325, 165], [310, 170], [330, 170]]  # nose, eyes, ears
    order = [("l_sho", 5, 0), ("l_elb", 7, 1), ("l_wri", 9, 2), ("r_sho", 6, 3), ("r_elb", 8, 4),
             ("r_wri", 10, 5), ("l_hip", 11, 6), ("l_knee", 13, 7), ("l_ank", 15, 8),
             ("r_hip", 12, 9), ("r_knee", 14, 10), ("r_ank", 16, 11)]
    for _, coco, model in order:
        kp[coco] = xy12[model]
    conf = np.linspace(0.5, 0.95, 17)
    return kp, conf


def coco17_to(name: str, kp: np.ndarray, conf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same detection in another published layout (the layouts' own definitions)."""
    rng = np.random.default_rng(1)
    if name in ("halpe26", "coco_wholebody133"):  # COCO-17 first, extras after
        n = get_layout(name).n_keypoints
        out = np.vstack([kp, rng.uniform(0, 640, (n - 17, 2))])
        return out, np.concatenate([conf, rng.uniform(0, 1, n - 17)])
    if name == "coco18":  # OpenPose order: nose, neck, r arm, l arm, r leg, l leg, eyes, ears
        coco_of = [0, -1, 6, 8, 10, 5, 7, 9, 12, 14, 16, 11, 13, 15, 2, 1, 4, 3]
        out = np.array([(kp[5] + kp[6]) / 2 if i < 0 else kp[i] for i in coco_of])
        return out, np.array([0.9 if i < 0 else conf[i] for i in coco_of])
    if name == "mediapipe33":  # BlazePose: 11-16 arms (l, r alternating), 23-28 legs, as COCO 5-16
        out = rng.uniform(0, 640, (33, 2))
        c = rng.uniform(0, 1, 33)
        out[11:17], c[11:17] = kp[5:11], conf[5:11]
        out[23:29], c[23:29] = kp[11:17], conf[11:17]
        return out, c
    if name == "body25":  # BODY_25 = COCO-18 with mid-hip at 8 and feet at 19-24
        kp18, c18 = coco17_to("coco18", kp, conf)
        out = np.vstack([kp18[:8], (kp18[8] + kp18[11]) / 2, kp18[8:], rng.uniform(0, 640, (6, 2))])
        return out, np.concatenate([c18[:8], [0.9], c18[8:], np.ones(6)])
    raise AssertionError(name)
