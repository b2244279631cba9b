"""The track filter of the fused joints answered at once (pose_lifter.core.depth.track_filter)
against a textbook Kalman filter, and when it starts again."""

from __future__ import annotations

import numpy as np
from pose_lifter.core.depth.track_filter import ACCEL_PSD, INITIAL_SPEED_STD, TrackFilter, filter_track
from tolerances import ROUND_OFF_LONG

FRAME_NS = 33_333_333


def _reference(z: np.ndarray, r: np.ndarray, dt: np.ndarray, q: float) -> np.ndarray:
    """One coordinate's constant-velocity Kalman filter written with matrices: state (position,
    velocity), F = [[1, dt], [0, 1]], Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]], H = [1, 0]."""
    x = np.array([z[0], 0.0])
    p = np.diag([r[0], INITIAL_SPEED_STD**2])
    out = [z[0]]
    for k in range(1, len(z)):
        f = np.array([[1.0, dt[k]], [0.0, 1.0]])
        qm = q * np.array([[dt[k] ** 3 / 3, dt[k] ** 2 / 2], [dt[k] ** 2 / 2, dt[k]]])
        x = f @ x
        p = f @ p @ f.T + qm
        h = np.array([1.0, 0.0])
        gain = p @ h / (h @ p @ h + r[k])
        x = x + gain * (z[k] - h @ x)
        p = (np.eye(2) - np.outer(gain, h)) @ p
        out.append(x[0])
    return np.array(out)


def test_the_filter_is_a_constant_velocity_kalman_filter_per_coordinate() -> None:
    rng = np.random.default_rng(3)
    n = 40
    steps = rng.integers(1, 4, size=n) * FRAME_NS  # frames dropped now and then: uneven dt
    stamps = np.cumsum(steps)
    truth = np.cumsum(rng.normal(0.0, 0.01, size=(n, 12, 3)), axis=0) + np.array([0.0, 0.0, 3.0])
    std = rng.uniform(0.01, 0.08, size=(n, 12, 3))
    z = truth + std * rng.standard_normal((n, 12, 3))
    f = TrackFilter(gap_s=1.0)
    got = np.array([f.update(7, int(s), z[k], std[k]) for k, s in enumerate(stamps)])
    dt = np.diff(stamps, prepend=stamps[0]) * 1e-9
    for j in range(12):
        for a in range(3):
            want = _reference(z[:, j, a], std[:, j, a] ** 2, dt, ACCEL_PSD)
            np.testing.assert_allclose(got[:, j, a], want, rtol=ROUND_OFF_LONG)  # the same filter, reordered
    # it follows the truth better than the frames do, and the whole-track helper is the same filter
    assert np.abs(got - truth)[10:].mean() < 0.8 * np.abs(z - truth)[10:].mean()
    np.testing.assert_array_equal(filter_track(stamps, z, std, np.ones(n, dtype=bool), 1.0), got)


def test_a_track_starts_again_after_a_gap_or_a_step_back_and_tracks_are_apart() -> None:
    rng = np.random.default_rng(4)
    z = rng.normal(0.0, 1.0, size=(6, 12, 3))
    std = np.full((12, 3), 0.05)
    f = TrackFilter(gap_s=0.5)
    np.testing.assert_array_equal(f.update(1, 0, z[0], std), z[0])  # a track's first frame: itself
    assert not np.array_equal(f.update(1, FRAME_NS, z[1], std), z[1])  # then filtered
    np.testing.assert_array_equal(f.update(2, FRAME_NS, z[2], std), z[2])  # another track: its own
    np.testing.assert_array_equal(f.update(1, FRAME_NS + 600_000_000, z[3], std), z[3])  # a gap
    np.testing.assert_array_equal(f.update(1, FRAME_NS, z[4], std), z[4])  # the clock stepped back
    f.forget(2 * FRAME_NS)  # both tracks' last frames are older: gone
    np.testing.assert_array_equal(f.update(1, 2 * FRAME_NS, z[5], std), z[5])
    # frames not fused are left as they are and do not move the filter
    joints = np.stack([z[0], z[1], z[2]])
    fused = np.array([True, False, True])
    out = filter_track([0, FRAME_NS, 2 * FRAME_NS], joints, np.stack([std] * 3), fused, 1.0)
    np.testing.assert_array_equal(out[1], z[1])
    g = TrackFilter(1.0)
    g.update(0, 0, z[0], std)
    np.testing.assert_array_equal(out[2], g.update(0, 2 * FRAME_NS, z[2], std))
