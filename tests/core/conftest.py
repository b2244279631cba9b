"""Fixtures shared by the core tests: real people from the committed bags' ground truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def real_frames() -> tuple[np.ndarray, np.ndarray]:
    """Real people (the committed bags' ground truth: CMU trials of the evaluation split, camera
    frame, metres), 4 frames of each of 3 bags, seen weak-perspective: (pixels (12, 12, 2),
    centred camera-frame truth (12, 12, 3))."""
    from pose_lifter.messages import convert as messages
    from pose_lifter.messages.names import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import read_messages

    truth = []
    for name in ("walk_clean", "punch_clean", "run_orbit"):
        msgs = [x.msg for x in read_messages(REPO / "bags" / f"{name}.mcap", [TOPIC_GROUND_TRUTH])]
        truth += [messages.skeleton3d_to_joints(m.skeletons[0]) for m in msgs[5:45:10]]
    cam = np.array(truth)
    cam -= cam.mean(axis=1, keepdims=True)
    return 160.0 * cam[..., :2] + 320.0, cam


@pytest.fixture(scope="module")
def walk_track() -> tuple[np.ndarray, np.ndarray]:
    """One real walker (bags/walk_clean.mcap's ground truth), 30 consecutive frames at 30 Hz,
    weak perspective: (pixels (30, 12, 2), centred camera-frame truth (30, 12, 3))."""
    from pose_lifter.messages import convert as messages
    from pose_lifter.messages.names import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import read_messages

    msgs = [x.msg for x in read_messages(REPO / "bags" / "walk_clean.mcap", [TOPIC_GROUND_TRUTH])]
    cam = np.array([messages.skeleton3d_to_joints(m.skeletons[0]) for m in msgs[5:35]])
    cam -= cam.mean(axis=1, keepdims=True)
    return 160.0 * cam[..., :2] + 320.0, cam
