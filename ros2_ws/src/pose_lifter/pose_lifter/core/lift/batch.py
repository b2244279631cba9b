"""Solves that hand their runs and their prior's poses to one compiled pass each: several
people of a frame, and several starts of one person, in
:func:`pose_lifter.core.solve.run_kernel.run_calls` and :func:`prior_calls`.

A solve is written as a generator (:data:`Steps`): where it needs runs of alternations or the
learned prior's poses it ``yield``\\ s their operands (a list of
:class:`~pose_lifter.core.solve.run_kernel.RunCall` and :class:`PriorCall`) and
is sent back their results (a :class:`~pose_lifter.core.solve.run_kernel.RunOut` per run, a pose (12, 3)
per prior call, in the same order), then goes on; its ``return`` value is the solve's result.
The Python around them (the checks, the starts, the choice of the best run, the track) stays
with the person it belongs to; the runs and the prior's poses of everybody who is waiting go
through the kernel and the network together.

* :func:`gather` runs several solves in step as one solve: each round it yields the calls every
  unfinished solve asked for, concatenated, and hands each its own outcomes back. A person's
  starts (the screened multi-start, the outlier pass's two runs) are gathered so, and so are
  the people of a frame.
* :func:`solve` drives one solve to its end, each round's runs in one
  :func:`~pose_lifter.core.solve.run_kernel.run_calls` and its prior calls in one
  :func:`prior_calls` (a solve of one person is a batch like any other).

A run's or a pose's result does not depend on what else is in its batch (the kernel solves each
run on its own operands, the network's rows do not mix), so a person lifted with others gets
what they get alone, bit for bit (``tests/core/lift/test_batch.py``).
"""

from __future__ import annotations

from collections.abc import Generator, Sequence
from dataclasses import dataclass
from typing import Any, Final, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError
from ..model.prior import PosePrior, flip_rows
from ..model.skeleton import N_JOINTS
from ..numeric.jit import HAVE_NUMBA
from ..numeric.records import ModelArrays, StepSettings
from ..results import LiftResult, TrackContext, WarmStart
from ..solve.run_kernel import RunCall, RunOut, run_calls

__all__ = ["Call", "Failed", "LiftCall", "Outcome", "PeopleLifter", "PriorCall", "Steps", "gather",
           "outcomes", "prior_calls", "solve"]


@dataclass(frozen=True, eq=False)
class PriorCall:
    """One pose a solve asks of a learned prior: ``prior.predict(points, visible, flip)``,
    computed with the other poses of its round (:func:`prior_calls`).

    Attributes
    ----------
    prior : PosePrior
    points : ndarray, shape (12, 2) or (W, 12, 2)
        A frame, or a window of frames for a prior with ``window`` W.
    visible : ndarray of bool, shape (12,) or (W, 12)
    flip : bool
        Test-time flip averaging (``LifterOptions.prior_flip``).
    """

    prior: PosePrior
    points: NDArray[np.float64]
    visible: NDArray[np.bool_]
    flip: bool


class PeopleLifter(Protocol):
    """What lifts the people of a round's :class:`LiftCall` s together
    (:meth:`pose_lifter.core.lift.lifter.Lifter.lift_people`)."""

    def lift_people(self, calls: Sequence[LiftCall]) -> list[LiftResult | Exception]: ...


@dataclass(frozen=True, eq=False)
class LiftCall:
    """One person's lift a solve asks of a lifter (``lifter.lift(points, confidence, warm,
    track)``), lifted with the other people of its round who ask the same lifter
    (:meth:`PeopleLifter.lift_people`): the tracks of a frame, or offline the chains of a step,
    go through the lifter's checks, prior, starts and runs as one batch."""

    lifter: PeopleLifter
    points: NDArray[np.float64]  #: (12, 2)
    confidence: NDArray[np.float64] | None  #: (12,)
    warm: WarmStart | None
    track: TrackContext | None


T = TypeVar("T")

#: What a solve asks for: a run of alternations, a pose of the learned prior, or a person's lift.
Call = RunCall | PriorCall | LiftCall
#: What it is sent back for it: the run's result, the prior's pose (12, 3), the lift's result, or
#: the exception the kernel, the prior or the lift raised, which the solve raises.
Outcome = RunOut | NDArray[np.float64] | LiftResult | Exception
#: A solve: yields the calls it needs, is sent their outcomes in order, returns its result.
Steps = Generator[list[Call], list[Outcome], T]


class Failed:
    """What :func:`gather` with ``capture=True`` returns for a solve that raised: the error."""

    __slots__ = ("error",)

    def __init__(self, error: Exception) -> None:
        self.error = error


def gather(solves: Sequence[Steps[Any]], capture: bool = False) -> Steps[list[Any]]:
    """Several solves in step, as one solve returning their results in order.

    Each round yields the runs every unfinished solve asked for (concatenated, solve by solve)
    and sends each solve its own results. A solve that raises: with ``capture`` its result is a
    :class:`Failed` holding the error and the others go on; without, the error propagates (the
    other solves are closed).
    """
    n = len(solves)
    results: list[Any] = [None] * n
    pending: dict[int, list[Call]] = {}

    def advance(i: int, sent: list[Outcome] | None) -> None:
        try:
            calls = next(solves[i]) if sent is None else solves[i].send(sent)
        except StopIteration as done:
            results[i] = done.value
            return
        except Exception as err:
            if not capture:
                for j in pending:
                    solves[j].close()
                raise
            results[i] = Failed(err)
            return
        pending[i] = calls

    for i in range(n):
        advance(i, None)
    while pending:
        order = sorted(pending)
        calls = [c for i in order for c in pending[i]]
        outs = yield calls
        start = 0
        for i in order:
            size = len(pending.pop(i))
            advance(i, outs[start:start + size])
            start += size
    return results


def solve(steps: Steps[T], km: ModelArrays, st: StepSettings, threads: int = 1) -> T:
    """Drive ``steps`` to its result: each round's runs in one
    :func:`~pose_lifter.core.solve.run_kernel.run_calls` of the model ``km`` and settings ``st``, its
    prior calls in one :func:`prior_calls` (each over ``threads`` threads)."""
    try:
        calls = next(steps)
        while True:
            calls = steps.send(outcomes(calls, km, st, threads))
    except StopIteration as done:
        result: T = done.value
        return result


def outcomes(calls: list[Call], km: ModelArrays, st: StepSettings, threads: int = 1) -> list[Outcome]:
    """The outcomes of a round's ``calls``, in order: the runs through one
    :func:`~pose_lifter.core.solve.run_kernel.run_calls`, the prior calls through one
    :func:`prior_calls` (each over ``threads`` threads), the lifts of each lifter through one
    :meth:`PeopleLifter.lift_people`."""
    runs = [c for c in calls if isinstance(c, RunCall)]
    if len(runs) == len(calls):
        return list(run_calls(runs, km, st, threads))
    out: list[Outcome] = []
    done_runs = iter(run_calls(runs, km, st, threads))
    done_priors = iter(prior_calls([c for c in calls if isinstance(c, PriorCall)], threads))
    lifts: dict[int, list[LiftCall]] = {}
    for c in calls:
        if isinstance(c, LiftCall):
            lifts.setdefault(id(c.lifter), []).append(c)
    lifted: dict[int, LiftResult | Exception] = {}
    for group in lifts.values():
        lifted.update(zip(map(id, group), group[0].lifter.lift_people(group), strict=True))
    for c in calls:
        if isinstance(c, RunCall):
            out.append(next(done_runs))
        elif isinstance(c, PriorCall):
            out.append(next(done_priors))
        else:
            out.append(lifted[id(c)])
    return out


def prior_calls(calls: list[PriorCall], threads: int = 1) -> list[NDArray[np.float64] | Exception]:
    """The poses (12, 3) of ``calls``, in order, each prior's network in one pass over its
    weights for all of its calls (its rows split over ``threads`` threads,
    :meth:`PosePrior.forward_rows`).

    A prior's weights (4 MB) are no longer in the cache when the next person needs them, so one
    pose alone costs the reading of the weights from memory; the poses of a frame's people read
    them once. The rows go through the compiled layer pass (:meth:`PosePrior._forward_small`),
    whose rows do not mix: each pose is the one :meth:`PosePrior.predict` gives alone, bit for
    bit. Without numba each pose is computed alone (numpy's matrix product of many rows rounds
    otherwise than of two). An input the prior refuses gets its :class:`InvalidInputError` in
    its place.
    """
    out: list[NDArray[np.float64] | Exception] = [_NO_POSE] * len(calls)
    if not HAVE_NUMBA:
        for i, c in enumerate(calls):
            try:
                out[i] = c.prior.predict(c.points, c.visible, c.flip)
            except InvalidInputError as err:
                out[i] = err
        return out
    groups: dict[tuple[int, bool], list[tuple[int, NDArray[np.float64], NDArray[np.float64],
                                              NDArray[np.float64]]]] = {}
    for i, c in enumerate(calls):
        try:
            feats, centre, radius = c.prior.features(c.points, c.visible)
        except InvalidInputError as err:
            out[i] = err
            continue
        groups.setdefault((id(c.prior), c.flip), []).append((i, feats, centre, radius))
    for (_, flip), members in groups.items():
        prior = calls[members[0][0]].prior
        # stacked: the rows and the poses formed once for all of them (element-wise: what
        # PosePrior.input_rows and .poses give each alone)
        rows = flip_rows(np.stack([f for _, f, _, _ in members]), flip)  # (n, [2,] d)
        h = np.ascontiguousarray(rows.reshape(-1, rows.shape[-1]), dtype=np.float32)
        y = prior.forward_rows(h, threads).reshape(*rows.shape[:-1], N_JOINTS, 3)
        poses = prior.poses(y, np.stack([c for _, _, c, _ in members]),
                            np.stack([r for _, _, _, r in members]), flip)  # (n, 12, 3)
        for (i, _, _, _), pose in zip(members, poses, strict=True):
            out[i] = pose
    return out


_NO_POSE: Final[NDArray[np.float64]] = np.empty((0, 3))
