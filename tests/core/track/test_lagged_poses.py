"""The refiner (core.track.later.Refiner): with a horizon (the node's ``output_lag``), without an
update, the centred window over the frames kept (checked against the offline lift's smoothing and
the weights written out); the window of frames kept, a clock that jumps back, forgetting idle
tracks. Over the whole track, with the update: the two passes of the offline update written out;
a horizon that reaches every frame of a short track gives the whole track's poses; each pose placed
as its frame (as place_results places it), then windowed in metres."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core.track.later import (
    WINDOW,
    LaterFrame,
    Placement,
    Refiner,
    RunArrays,
    placements,
    update_later,
)
from pose_lifter.core.track.measurement import MeasurementUpdate
from pose_lifter.core.track.placement import place_results
from pose_lifter.core.track.smoothing import centred_smoothing

STEP = 33_333_333


def _poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = np.cumsum(rng.normal(scale=0.01, size=(n, 12, 3)), axis=0) + rng.normal(size=(1, 12, 3))
    return p - p.mean(axis=1, keepdims=True)


def test_without_an_update_the_lagged_pose_is_the_offline_window_over_the_frames_kept() -> None:
    poses = _poses(12)
    stamps = np.arange(12, dtype=np.int64) * STEP
    stamps[9:] += 2 * 10**9  # a gap over the timeout: frames 9-11 are another segment
    kept = Refiner(3, 0.04, 1.0, 0.5, 0.3)
    for s, p in zip(stamps, poses, strict=True):
        kept.add(3, int(s), p, None)
    # the independent reference: the Gaussian weights written out for frame 5 (+-3 frames at 0.04 s)
    w = np.exp(-0.5 * ((np.arange(2, 9) - 5) * STEP * 1e-9 / 0.04) ** 2)
    expect = np.einsum("k,kjc->jc", w, poses[2:9]) / w.sum()
    np.testing.assert_allclose(kept.pose(3, int(stamps[5])), expect, rtol=0, atol=tol.ROUND_OFF)
    offline = centred_smoothing(poses, stamps, np.ones(12, dtype=bool), 0.04, 1.0)
    for k in (0, 7, 8, 9, 11):  # truncated at the ends and at the gap, as pose-lifter lift truncates
        np.testing.assert_allclose(kept.pose(3, int(stamps[k])), offline[k], rtol=0, atol=tol.ROUND_OFF)


def test_a_track_keeps_its_newest_window_forgets_when_idle_and_restarts_when_the_clock_jumps_back() -> None:
    kept = Refiner(3, 0.04, 1.0, 0.5, 0.3)
    poses = _poses(WINDOW + 5)
    for i, p in enumerate(poses):
        kept.add(7, i * STEP, p, None)
    assert kept.pose(7, 4 * STEP) is None  # left the window
    assert kept.pose(7, 5 * STEP) is not None and kept.pose(8, 5 * STEP) is None
    # the clock jumps back (a looped recording): the track starts again from that frame
    kept.add(7, 2 * STEP, poses[0], None)
    np.testing.assert_array_equal(kept.pose(7, 2 * STEP), poses[0])
    assert kept.pose(7, 10 * STEP) is None
    kept.add(9, 100 * STEP, poses[1], None)
    kept.forget(50 * STEP)
    assert len(kept) == 1 and kept.pose(9, 100 * STEP) is not None


def _later_frames(n: int, seed: int = 1) -> list[LaterFrame]:
    """A track's frames with an update: noisy 2D of a moving pose, the noise known from frame 2 on,
    a new run (a frame that does not follow) at frame 14."""
    rng = np.random.default_rng(seed)
    poses = _poses(n, seed)
    used = np.ones(12, dtype=bool)
    points = 100.0 * poses[:, :, :2] + 320.0 + rng.normal(scale=3.0, size=(n, 12, 2))
    return [LaterFrame(i * STEP, poses[i], points[i], used, None if i < 2 else 0.05, i not in (0, 14))
            for i in range(n)]


def test_over_the_whole_track_each_run_is_the_mean_of_a_forward_and_a_backward_pass() -> None:
    frames = _later_frames(24)
    out = update_later(frames, 0.5, 0.3)
    for a, b in ((0, 14), (14, 24)):  # the runs, written out: the 2D smoothed over each, two passes
        arrays = RunArrays.of(frames[a:b])
        noise = arrays.backward_noise()
        assert noise is not None
        order = np.arange(b - a)
        fwd, fdone = MeasurementUpdate().run(*arrays, order, 0.5, 0.3)
        bwd, bdone = MeasurementUpdate().run(arrays.poses, arrays.points, arrays.used, noise, order[::-1],
                                             0.5, 0.3)
        for i in order:
            p = out[a + i]
            assert bdone[i] and p is not None
            expect = 0.5 * (fwd[i] + bwd[i]) if fdone[i] else bwd[i]
            np.testing.assert_allclose(p, expect, rtol=0, atol=tol.ROUND_OFF)
    assert not np.allclose(out[5], frames[5].pose, atol=1e-3)  # the update moved it


def test_a_horizon_that_reaches_every_frame_gives_the_whole_tracks_refinement() -> None:
    frames = _later_frames(WINDOW - 2)
    lagged, whole = Refiner(3, 0.04, 1.0, 0.5, 0.3), Refiner(None, 0.04, 1.0, 0.5, 0.3)
    for f in frames:
        lagged.add(4, f.stamp_ns, f.pose, f)
        whole.add(4, f.stamp_ns, f.pose, f)
    for f in frames:  # asked in time order once every frame has come (the node's flush)
        a, b = lagged.pose(4, f.stamp_ns), whole.pose(4, f.stamp_ns)
        assert a is not None and b is not None
        np.testing.assert_allclose(a, b, rtol=0, atol=tol.ROUND_OFF)
    with np.testing.assert_raises(ValueError):
        lagged.measured(4)
    # over the whole track the window is the offline lift's centred smoothing of the updated poses
    measured = whole.measured(4)
    updated = np.array([f.pose if p is None else p for f, p in zip(frames, measured, strict=True)])
    stamps = np.array([f.stamp_ns for f in frames], dtype=np.int64)
    offline = centred_smoothing(updated, stamps, np.ones(len(frames), dtype=bool), 0.04, 1.0)
    for k, f in enumerate(frames):
        np.testing.assert_allclose(whole.pose(4, f.stamp_ns), offline[k], rtol=0, atol=tol.ROUND_OFF)


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_each_pose_is_placed_as_its_frame_then_windowed_in_metres() -> None:
    """Frames placed at different centroids and rays: the window averages the placed joints (the
    person's depth smoothed too), a horizon's row as the whole track's, as centred_smoothing of
    the placed poses."""
    rng = np.random.default_rng(5)
    frames = _later_frames(16)
    placed = [Placement(_rotation(rng), np.array([0.1, -0.2, 5.0]) + rng.normal(scale=0.05, size=3), 0.45)
              for _ in frames]
    lagged, whole = Refiner(3, 0.04, 1.0, 0.5, 0.3), Refiner(None, 0.04, 1.0, 0.5, 0.3)
    for f, p in zip(frames, placed, strict=True):
        lagged.add(2, f.stamp_ns, f.pose, f, p)
        whole.add(2, f.stamp_ns, f.pose, f, p)
    measured = whole.measured(2)
    metres = np.array([p.rotation @ (0.45 * (f.pose if m is None else m)).T for f, p, m in
                       zip(frames, placed, measured, strict=True)]).transpose(0, 2, 1)
    metres += np.array([p.centroid for p in placed])[:, None, :]
    stamps = np.array([f.stamp_ns for f in frames], dtype=np.int64)
    expect = centred_smoothing(metres, stamps, np.ones(len(frames), dtype=bool), 0.04, 1.0)
    np.testing.assert_allclose(whole.poses(2), expect, rtol=0, atol=tol.ROUND_OFF)
    for k, f in enumerate(frames):
        np.testing.assert_allclose(lagged.pose(2, f.stamp_ns), expect[k], rtol=0, atol=tol.ROUND_OFF)
    # the centroid is the window over the frames' centroids
    w = np.exp(-0.5 * ((np.arange(2, 9) - 5) * STEP * 1e-9 / 0.04) ** 2)
    centroids = np.array([p.centroid for p in placed[2:9]])
    np.testing.assert_allclose(expect[5].mean(axis=0), w @ centroids / w.sum(), rtol=0, atol=tol.ROUND_OFF)


@pytest.mark.parametrize("intrinsics", [None, ((800.0, 790.0), (320.0, 240.0))])
def test_a_placement_places_any_pose_as_the_lift_was_placed(intrinsics: Any) -> None:
    """placements() of lifts (their camera's scale and translation): a refined pose placed by it is
    where place_results puts that pose with those lifts' cameras."""
    rng = np.random.default_rng(7)
    results: Any = [SimpleNamespace(camera=SimpleNamespace(scale=s, translation=t))
                    for s, t in zip([60.0, 95.0, 140.0], rng.uniform(50, 600, size=(3, 2)), strict=True)]
    poses = _poses(3, 4)
    expect = place_results(poses, results, 0.43, intrinsics, 5.0)
    for p, placement, e in zip(poses, placements(results, 0.43, intrinsics, 5.0), expect, strict=True):
        np.testing.assert_allclose(placement.place(p), e, rtol=0, atol=tol.ROUND_OFF)
