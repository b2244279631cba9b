"""Solves in step (``core/lift/batch.py``) and runs in one compiled pass (``run_kernel.run_calls``):
a person lifted with others gets, bit for bit, what they get lifted alone, whatever the batch
and the thread count; a failing run or solve costs only its own person."""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.core.errors import SolverError
from pose_lifter.core.lift.batch import Failed, LiftCall, PriorCall, gather, outcomes, solve
from pose_lifter.core.solve.run_kernel import RunCall, RunOut, RunStatus, _run_kernel, run_calls
from pose_lifter.core.track.policy import TrackedLift, TrackFrame, TrackPolicy, lift_tracks_steps
from synthetic_poses import synthetic_poses

#: People of the crowd frame, frames of their tracks.
N_PEOPLE, N_FRAMES = 30, 4


def _crowd(seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """(N_FRAMES, N_PEOPLE, 12, 2) pixels of 30 people moving slightly, seen from random azimuths,
    with 2D noise and a few missing joints; and their confidences (N_FRAMES, N_PEOPLE, 12)."""
    rng = np.random.default_rng(seed)
    poses, _ = synthetic_poses(N_PEOPLE, seed=seed)
    points = np.zeros((N_FRAMES, N_PEOPLE, 12, 2))
    conf = np.ones((N_FRAMES, N_PEOPLE, 12))
    for p in range(N_PEOPLE):
        yaw = rng.uniform(0, 2 * np.pi)
        rot = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, -1, 0]])  # image y down
        drift = rng.normal(scale=0.05, size=(12, 3))
        for f in range(N_FRAMES):
            pose = poses[p] + f * drift
            noise = rng.normal(scale=1.0, size=(12, 2))
            points[f, p] = 40.0 * pose @ rot.T + [60.0 + 20.0 * p, 240.0] + noise
    conf[rng.uniform(size=conf.shape) < 0.05] = 0.0
    return points, conf


def _same(a: TrackedLift | Exception, b: TrackedLift | Exception) -> bool:
    if isinstance(a, Exception) or isinstance(b, Exception):
        return type(a) is type(b) and str(a) == str(b)
    ra, rb = a.result, b.result
    return (np.array_equal(ra.pose, rb.pose) and np.array_equal(ra.alpha, rb.alpha)
            and np.array_equal(ra.camera.rotation, rb.camera.rotation) and ra.camera.scale == rb.camera.scale
            and np.array_equal(ra.camera.translation, rb.camera.translation) and ra.objective == rb.objective
            and ra.total_alternations == rb.total_alternations
            and np.array_equal(ra.pose_camera, rb.pose_camera) and a.warm_started == b.warm_started)


@pytest.mark.parametrize("mode", ["hybrid", "paper"])
def test_a_30_person_frame_gives_each_person_what_they_get_alone(mode: str) -> None:
    options = LifterOptions(mode=mode, n_starts=6 if mode == "paper" else 30)  # type: ignore[arg-type]
    points, conf = _crowd()
    together = Lifter(None, options)
    together.threads = 2
    crowd = TrackPolicy(together)
    alone_lifter = Lifter(None, options)
    alone = [TrackPolicy(alone_lifter) for _ in range(N_PEOPLE)]  # one policy per track: nothing shared
    for f in range(N_FRAMES):
        stamp = 10**9 + f * 33_333_333
        got = together.runs.solve(lift_tracks_steps([TrackFrame(crowd, p, stamp, points[f, p], conf[f, p])
                                                     for p in range(N_PEOPLE)]))
        for p in range(N_PEOPLE):
            try:
                want: TrackedLift | Exception = alone[p].lift(p, stamp, points[f, p], conf[f, p])
            except Exception as err:
                want = err
            assert _same(got[p], want), (f, p)
    assert sum(1 for r in got if not isinstance(r, Exception)) >= N_PEOPLE - 2  # the frame was lifted


def _calls(lifter: Lifter, n: int) -> list[RunCall]:
    """The run operands of ``n`` cold hybrid lifts (recorded from real solves: their first round
    of runs, after the round of their prior's pose)."""
    points, conf = _crowd(3)
    km, st = lifter.model.kernel_arrays, lifter.runs.settings
    calls: list[RunCall] = []
    for p in range(n):
        steps = lifter.people_steps([LiftCall(lifter, points[0, p], conf[0, p], None, None)])
        first = next(steps)
        assert [type(c) for c in first] == [PriorCall]
        batch = steps.send(outcomes(first, km, st))
        assert all(isinstance(c, RunCall) for c in batch)
        calls += [c for c in batch if isinstance(c, RunCall)]
        steps.close()
    return calls


def test_run_calls_are_each_runs_kernel_alone_at_any_thread_count() -> None:
    lifter = Lifter()
    calls = _calls(lifter, 9)
    km, st = lifter.model.kernel_arrays, lifter.runs.settings
    alone = [_run_kernel(c, km, st) for c in calls]
    for threads in (1, 2, 4, 20):
        for got, want in zip(run_calls(calls, km, st, threads), alone, strict=True):
            assert not isinstance(got, Exception)
            for a, b in zip(got, want, strict=True):
                assert np.array_equal(a, b)
    assert run_calls([], km, st) == []


def test_a_round_of_runs_and_prior_calls_gets_each_its_own_outcome_in_order() -> None:
    """A round may mix runs and prior calls (one person's outlier pass asks for its prior while
    another's runs wait): each call gets what it gets in a round of its own kind, in its place."""
    lifter = Lifter()
    runs = _calls(lifter, 2)
    km, st = lifter.model.kernel_arrays, lifter.runs.settings
    points, conf = _crowd(3)
    prior = lifter.prior
    asks = [PriorCall(prior, points[0, p], conf[0, p] > 0, True) for p in range(3)]
    mixed = [asks[0], runs[0], asks[1], asks[2], runs[1]]
    got = outcomes(mixed, km, st)
    want_runs = run_calls(runs, km, st)
    for g, w in zip([got[1], got[4]], want_runs, strict=True):
        assert isinstance(g, RunOut) and isinstance(w, RunOut)
        assert all(np.array_equal(a, b) for a, b in zip(g, w, strict=True))
    for g, c in zip([got[0], got[2], got[3]], asks, strict=True):
        assert isinstance(g, np.ndarray)
        np.testing.assert_array_equal(g, prior.predict(c.points, c.visible, True))
    assert not np.array_equal(got[0], got[2])


def test_a_run_that_raises_costs_only_its_own_person() -> None:
    lifter = Lifter()
    calls = _calls(lifter, 3)
    km, st = lifter.model.kernel_arrays, lifter.runs.settings
    bad = calls[1]._replace(xn=np.full_like(calls[1].xn, np.nan), w=np.ones_like(calls[1].w))
    out = run_calls([calls[0], bad, calls[2]], km, st, threads=2)
    good = run_calls([calls[0], calls[2]], km, st)
    assert not isinstance(out[0], Exception) and not isinstance(out[2], Exception)
    assert np.array_equal(out[0].pose, good[0].pose) and np.array_equal(out[2].pose, good[1].pose)
    # the bad run: an error in its place, or a result its solve refuses (a diverged status)
    assert isinstance(out[1], Exception) or out[1].status != RunStatus.OK


def _solve_of(values: list[int], fail_at: int | None = None) -> Generator[list[Any], list[Any], list[Any]]:
    """A fake solve: each round asks for len(values) 'runs' (here: plain numbers) and returns what
    it was sent, raising at round ``fail_at``."""
    got: list[Any] = []
    for r in range(2):
        if r == fail_at:
            raise SolverError("diverged")
        got += (yield list(values))
    return got


def test_gather_hands_each_solve_its_own_results_and_captures_failures() -> None:
    steps = gather([_solve_of([1, 2]), _solve_of([3]), _solve_of([4, 5, 6], fail_at=1)], capture=True)
    rounds = []
    try:
        calls = next(steps)
        while True:
            rounds.append(list(calls))
            calls = steps.send([10 * c for c in calls])
    except StopIteration as done:
        a, b, c = done.value
    assert rounds == [[1, 2, 3, 4, 5, 6], [1, 2, 3]]  # the failed solve leaves the second round
    assert a == [10, 20, 10, 20] and b == [30, 30]
    assert isinstance(c, Failed) and isinstance(c.error, SolverError)
    with pytest.raises(SolverError):  # without capture the error propagates
        steps = gather([_solve_of([1]), _solve_of([2], fail_at=0)])
        next(steps)


def test_a_lift_driven_alone_is_a_batch_of_one() -> None:
    lifter = Lifter()
    points, conf = _crowd(5)
    direct = lifter.lift(points[0, 0], conf[0, 0])
    driven = solve(lifter.lift_steps(points[0, 0], conf[0, 0]), lifter.model.kernel_arrays,
                   lifter.runs.settings, threads=3)
    assert np.array_equal(direct.pose, driven.pose) and direct.objective == driven.objective


def test_a_batch_that_fails_is_lifted_person_by_person(monkeypatch: pytest.MonkeyPatch) -> None:
    """A failure of the batch itself (not a person's refusal) costs only the people it belongs
    to: each is lifted again alone and gets what they get alone."""
    lifter = Lifter()
    points, conf = _crowd(5)
    calls = [LiftCall(lifter, points[0, p], conf[0, p], None, None) for p in range(3)]
    alone = [lifter.lift(points[0, p], conf[0, p]) for p in range(3)]
    original = Lifter._results

    def only_alone(self: Lifter, won: Any, scaled: bool) -> Any:
        if len(won) > 1 or won[0][0].x[0, 0] == points[0, 1, 0, 0]:
            raise RuntimeError("a bug of the batch")
        return original(self, won, scaled)

    monkeypatch.setattr(Lifter, "_results", only_alone)
    got = lifter.lift_people(calls)
    assert isinstance(got[1], RuntimeError)  # the person whose lift fails alone too
    for p in (0, 2):
        r = got[p]
        assert not isinstance(r, Exception)
        assert np.array_equal(r.pose, alone[p].pose) and r.objective == alone[p].objective
