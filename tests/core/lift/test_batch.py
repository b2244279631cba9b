"""A lift is a batch: stages over all its rows (``core/lift``), each one call of the compiled kernels
(``run_kernel.run_calls``) or of the prior's network (``batch.prior_calls``); a person lifted with
others gets, bit for bit, what they get lifted alone, whatever the batch and the thread count; each
row ends with its status and reason; a failing run or row costs only its own person."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from pose_lifter.core import InvalidInputError, Lifter, LifterOptions, LiftStatus, TooFewJointsError
from pose_lifter.core.errors import OutOfOrderFrameError, SolverError
from pose_lifter.core.lift import batch
from pose_lifter.core.lift import runs as runs_module
from pose_lifter.core.lift.batch import LiftRow
from pose_lifter.core.results import Failure, LiftOutcome, TrackContext
from pose_lifter.core.solve.run_kernel import RunCall, RunStatus, _run_kernel, run_calls
from pose_lifter.core.track.policy import TrackFrame, TrackOutcome, TrackPolicy, lift_tracks
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


def _same(a: TrackOutcome, b: TrackOutcome) -> bool:
    if a.result is None or b.result is None:
        return (a.status, a.reason, a.result) == (b.status, b.reason, b.result)
    ra, rb = a.result.result, b.result.result
    return (np.array_equal(ra.pose, rb.pose) and np.array_equal(ra.alpha, rb.alpha)
            and np.array_equal(ra.camera.rotation, rb.camera.rotation) and ra.camera.scale == rb.camera.scale
            and np.array_equal(ra.camera.translation, rb.camera.translation) and ra.objective == rb.objective
            and ra.total_alternations == rb.total_alternations
            and np.array_equal(ra.pose_camera, rb.pose_camera)
            and a.result.warm_started == b.result.warm_started)


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
        got = lift_tracks([TrackFrame(crowd, p, stamp, points[f, p], conf[f, p]) for p in range(N_PEOPLE)])
        for p in range(N_PEOPLE):
            want = lift_tracks([TrackFrame(alone[p], p, stamp, points[f, p], conf[f, p])])[0]
            assert _same(got[p], want), (f, p)
    assert sum(1 for r in got if r.status == LiftStatus.SOLVED) >= N_PEOPLE - 2  # the frame was lifted


def _recorded_calls(monkeypatch: pytest.MonkeyPatch) -> tuple[list[list[RunCall]], list[int]]:
    """Every ``run_calls`` of the lifts' stages (their runs) and the size of every ``prior_calls``
    (their prior's poses), recorded from here on."""
    runs: list[list[RunCall]] = []
    priors: list[int] = []
    run_all, prior_all = runs_module.run_calls, batch.prior_calls

    def runs_spy(calls: list[RunCall], *args: Any) -> Any:
        runs.append(list(calls))
        return run_all(calls, *args)

    def priors_spy(calls: list[batch.PriorCall], threads: int = 1) -> Any:
        priors.append(len(calls))
        return prior_all(calls, threads)

    monkeypatch.setattr(runs_module, "run_calls", runs_spy)
    monkeypatch.setattr(batch, "prior_calls", priors_spy)
    return runs, priors


def _calls(lifter: Lifter, n: int, monkeypatch: pytest.MonkeyPatch) -> list[RunCall]:
    """The run operands of ``n`` cold hybrid lifts (recorded from real solves: their first stage of
    runs, after the prior stage)."""
    points, conf = _crowd(3)
    with monkeypatch.context() as mp:
        runs, _ = _recorded_calls(mp)
        lifter.lift_people([LiftRow(points[0, p], conf[0, p]) for p in range(n)])
    assert len(runs[0]) == n
    return runs[0]


def test_run_calls_are_each_runs_kernel_alone_at_any_thread_count(monkeypatch: pytest.MonkeyPatch) -> None:
    lifter = Lifter()
    calls = _calls(lifter, 9, monkeypatch)
    km, st = lifter.model.kernel_arrays, lifter.runs.settings
    alone = [_run_kernel(c, km, st) for c in calls]
    for threads in (1, 2, 4, 20):
        for got, want in zip(run_calls(calls, km, st, threads), alone, strict=True):
            assert not isinstance(got, Exception)
            for a, b in zip(got, want, strict=True):
                assert np.array_equal(a, b)
    assert run_calls([], km, st) == []


@pytest.mark.parametrize("mode", ["hybrid", "paper"])
def test_each_stage_is_one_call_over_the_whole_batch(mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The stages' calls do not grow with the batch: the prior stage is one pass of the network
    over every row (and one per outlier pass), each stage's runs one kernel call over every row."""
    options = LifterOptions(mode=mode, n_starts=6 if mode == "paper" else 30)  # type: ignore[arg-type]
    lifter = Lifter(None, options)
    points, conf = _crowd(5)
    counts = {}
    for n in (1, 12):
        with monkeypatch.context() as mp:
            runs, priors = _recorded_calls(mp)
            out = lifter.lift_people([LiftRow(points[0, p], conf[0, p]) for p in range(n)])
        assert all(o.status == LiftStatus.SOLVED for o in out)
        counts[n] = (len(runs), len(priors))
        if mode == "hybrid":  # the prior, the runs, the mirrored screens (and continued runs), the passes
            assert priors[0] == n and len(priors) <= 1 + options.outlier_passes
            assert len(runs[0]) == n and 2 <= len(runs) <= 3 + options.outlier_passes
        else:  # every start's screening run, then the n_refine best continued
            assert priors == [] and [len(r) for r in runs] == [6 * n, options.n_refine * n]
    assert counts[12][0] <= counts[1][0] + options.outlier_passes  # a pass may flag no one alone


def test_a_run_that_raises_costs_only_its_own_person(monkeypatch: pytest.MonkeyPatch) -> None:
    lifter = Lifter()
    calls = _calls(lifter, 3, monkeypatch)
    km, st = lifter.model.kernel_arrays, lifter.runs.settings
    bad = calls[1]._replace(xn=np.full_like(calls[1].xn, np.nan), w=np.ones_like(calls[1].w))
    out = run_calls([calls[0], bad, calls[2]], km, st, threads=2)
    good = run_calls([calls[0], calls[2]], km, st)
    assert not isinstance(out[0], Exception) and not isinstance(out[2], Exception)
    assert not isinstance(good[0], Exception) and not isinstance(good[1], Exception)
    assert np.array_equal(out[0].pose, good[0].pose) and np.array_equal(out[2].pose, good[1].pose)
    # the bad run: an error in its place, or a result its solve refuses (a diverged status)
    assert isinstance(out[1], Exception) or out[1].status != RunStatus.OK


def test_a_lift_alone_is_a_batch_of_one() -> None:
    lifter = Lifter()
    points, conf = _crowd(5)
    direct = lifter.lift(points[0, 0], conf[0, 0])
    lifter.threads = 3
    batched = lifter.lift_people([LiftRow(points[0, p], conf[0, p]) for p in range(3)])
    first = batched[0].unwrap()
    assert np.array_equal(direct.pose, first.pose) and direct.objective == first.objective
    assert batched[0] == LiftOutcome(LiftStatus.SOLVED, "", first)


def test_each_row_ends_with_its_status_and_reason() -> None:
    """Refused rows get their status and reason (osqp's ``info.status``) and cost the others
    nothing; :meth:`Lifter.lift` raises the status's error."""
    lifter = Lifter()
    points, conf = _crowd(5)
    x, c = points[0, 0], conf[0, 0]
    few = np.zeros(12)
    few[:3] = 1.0
    rows = [LiftRow(x, c), LiftRow(x[:11], c[:11]), LiftRow(x, few), LiftRow(np.full((12, 2), 5.0), c),
            LiftRow(x, c, track=TrackContext(temporal_weight=-1.0)), LiftRow(points[0, 1], conf[0, 1])]
    out = lifter.lift_people(rows)
    assert [o.status for o in out] == [LiftStatus.SOLVED, LiftStatus.INVALID_INPUT, LiftStatus.TOO_FEW_JOINTS,
                                       LiftStatus.INVALID_INPUT, LiftStatus.INVALID_INPUT, LiftStatus.SOLVED]
    assert "shape" in out[1].reason and "3 joints visible" in out[2].reason
    assert "one point" in out[3].reason and "temporal_weight" in out[4].reason
    assert all(o.result is None for o in out[1:5]) and out[0].reason == out[5].reason == ""
    for o, r in ((out[0], rows[0]), (out[5], rows[5])):
        alone = lifter.lift(r.points, r.confidence)
        assert o.result is not None and np.array_equal(o.result.pose, alone.pose)
    with pytest.raises(TooFewJointsError, match="3 joints visible"):
        lifter.lift(x, few)
    with pytest.raises(InvalidInputError, match="one point"):
        lifter.lift(np.full((12, 2), 5.0), c)


def test_a_failure_stands_for_its_error_and_back() -> None:
    for err, status in ((TooFewJointsError("few"), LiftStatus.TOO_FEW_JOINTS),
                        (InvalidInputError("bad"), LiftStatus.INVALID_INPUT),
                        (SolverError("diverged"), LiftStatus.DIVERGED),
                        (OutOfOrderFrameError("late"), LiftStatus.OUT_OF_ORDER)):
        f = Failure.of(err)
        assert f == Failure(status, str(err))
        again = f.error()
        assert type(again) is type(err) and str(again) == str(err)
    bug = Failure.of(KeyError("k"))
    assert bug.status == LiftStatus.FAILED and bug.reason == "KeyError: 'k'"
    assert type(bug.error()) is RuntimeError


def test_a_batch_that_fails_is_lifted_person_by_person(monkeypatch: pytest.MonkeyPatch) -> None:
    """A failure of the batch itself (not a person's refusal) costs only the people it belongs
    to: each is lifted again alone and gets what they get alone."""
    lifter = Lifter()
    points, conf = _crowd(5)
    rows = [LiftRow(points[0, p], conf[0, p]) for p in range(3)]
    alone = [lifter.lift(points[0, p], conf[0, p]) for p in range(3)]
    original = Lifter._results

    def only_alone(self: Lifter, won: Any) -> Any:
        if len(won) > 1 or won[0][0].x[0, 0] == points[0, 1, 0, 0]:
            raise RuntimeError("a bug of the batch")
        return original(self, won)

    monkeypatch.setattr(Lifter, "_results", only_alone)
    got = lifter.lift_people(rows)
    assert got[1] == LiftOutcome(LiftStatus.FAILED, "RuntimeError: a bug of the batch")
    for p in (0, 2):
        r = got[p].unwrap()
        assert np.array_equal(r.pose, alone[p].pose) and r.objective == alone[p].objective
    with pytest.raises(RuntimeError, match="a bug of the batch"):
        lifter.lift(points[0, 1], conf[0, 1])


def test_the_policy_hands_the_lifter_its_rows_once_and_the_reinitialised_again(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame of several tracks: one batch of every row, and one of the rows the policy
    re-initialises (cold); an out-of-order frame is refused with its status, the others lifted."""
    points, conf = _crowd(9)
    lifter = Lifter()
    policy = TrackPolicy(lifter, reinit_ratio=1e-9)  # every warm frame with 3 objectives re-initialised
    sizes: list[list[tuple[int, bool]]] = []
    lift_people = Lifter.lift_people

    def spy(self: Lifter, rows: Sequence[LiftRow]) -> list[LiftOutcome]:
        sizes[-1].append((len(rows), all(r.warm is None for r in rows)))
        return lift_people(self, rows)

    monkeypatch.setattr(Lifter, "lift_people", spy)
    for f in range(N_FRAMES):
        sizes.append([])
        stamp = 10**9 + f * 33_333_333
        out = lift_tracks([TrackFrame(policy, p, stamp, points[f, p], conf[0, p]) for p in range(4)])
        assert [o.status for o in out] == [LiftStatus.SOLVED] * 4
    assert sizes == [[(4, True)], [(4, False)], [(4, False)], [(4, False), (4, True)]]
    late = TrackFrame(policy, 0, stamp - 10_000_000, points[0, 0], conf[0, 0])
    (refused,) = lift_tracks([late])
    assert refused.status == LiftStatus.OUT_OF_ORDER and "older than its last frame" in refused.reason
    with pytest.raises(OutOfOrderFrameError, match="older than its last frame"):
        policy.lift(0, late.stamp_ns, late.points, late.confidence)
