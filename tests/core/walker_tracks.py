"""A committed bag's person tracked by the hybrid lifter, for the tests of a track's published
pose (the output smoothing and the measurement update): the person's 2D and truth, the track's
lifts, and the check that an output-only option leaves the fits alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import tolerances as tol
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.core.track.policy import TrackedLift, TrackPolicy

REPO = Path(__file__).resolve().parents[2]


def person(bag: str, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The ground truth of a committed bag's person, ``frames`` frames at 30 Hz, weak
    perspective: (pixels (frames, 12, 2), centred camera-frame truth in metres (frames, 12, 3))."""
    from pose_lifter.messages import convert as messages
    from pose_lifter.messages.names import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import read_messages

    msgs = [x.msg for x in read_messages(REPO / "bags" / f"{bag}.mcap", [TOPIC_GROUND_TRUTH])]
    cam = np.array([messages.skeleton3d_to_joints(m.skeletons[0]) for m in msgs[:frames]])
    cam -= cam.mean(axis=1, keepdims=True)
    return 160.0 * cam[..., :2] + 320.0, cam


def track(options: LifterOptions, x: np.ndarray, conf: np.ndarray | None = None) -> list[TrackedLift]:
    """One track's lifts of the 2D ``x`` (T, 12, 2; confidences ``conf`` (T, 12) or all 1), a frame
    every 1/30 s."""
    policy = TrackPolicy(Lifter(options=options))
    return [policy.lift(0, i * 33_333_333, x[i], None if conf is None else conf[i]) for i in range(len(x))]


def assert_only_the_output_differs(on: list[TrackedLift], off: list[TrackedLift]) -> None:
    """The lifts of one track with an output-only option on and off: the fits (coefficients,
    cameras, objectives) are the same, the published body-frame and camera-frame poses of ``on``
    stay one pose under the fit's camera, and the published poses differ."""
    for a, b in zip(on, off, strict=True):
        np.testing.assert_array_equal(a.result.alpha, b.result.alpha)
        np.testing.assert_array_equal(a.result.camera.rotation, b.result.camera.rotation)
        assert a.result.objective == b.result.objective
        c = a.result.pose - a.result.pose.mean(axis=0)
        np.testing.assert_allclose(c @ a.result.camera.rotation.T, a.result.pose_camera,
                                   atol=tol.ROUND_OFF_ACCUMULATED)
    assert not np.allclose(on[10].result.pose_camera, off[10].result.pose_camera)
