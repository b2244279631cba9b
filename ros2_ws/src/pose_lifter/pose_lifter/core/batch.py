"""Solves that hand their runs to one compiled pass: several people of a frame, and several
starts of one person, in :func:`pose_lifter.core.run_kernel.run_calls`.

A solve is written as a generator (:data:`Steps`): where it needs runs of alternations it
``yield``\\ s their operands (a list of :class:`~pose_lifter.core.run_kernel.RunCall`) and is sent
back their results (a list of :class:`~pose_lifter.core.run_kernel.RunOut`, in the same order),
then goes on; its ``return`` value is the solve's result. The Python around the runs (the
checks, the prior, the starts, the choice of the best run, the track) stays with the person it
belongs to; the runs of everybody who is waiting go through the kernel together.

* :func:`gather` runs several solves in step as one solve: each round it yields the runs every
  unfinished solve asked for, concatenated, and hands each its own results back. A person's
  starts (the screened multi-start, the outlier pass's two runs) are gathered so, and so are
  the people of a frame.
* :func:`solve` drives one solve to its end, each round's runs in one
  :func:`~pose_lifter.core.run_kernel.run_calls` (a solve of one person is a batch like any other).

A run's result does not depend on what else is in its batch (the kernel solves each run on its
own operands), so a person lifted with others gets what they get alone, bit for bit
(``tests/core/test_batch.py``).
"""

from __future__ import annotations

from collections.abc import Generator, Sequence
from typing import Any, TypeVar

from ._records import ModelArrays, StepSettings
from .run_kernel import RunCall, RunOut, run_calls

__all__ = ["Failed", "Steps", "gather", "solve"]

T = TypeVar("T")

#: A solve: yields the runs it needs, is sent their results (a run whose kernel raised: the
#: exception, which the solve raises), returns its result.
Steps = Generator[list[RunCall], list[RunOut | Exception], T]


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
    pending: dict[int, list[RunCall]] = {}

    def advance(i: int, sent: list[RunOut | Exception] | None) -> None:
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
    :func:`~pose_lifter.core.run_kernel.run_calls` of the model ``km`` and settings ``st`` (over
    ``threads`` threads)."""
    try:
        calls = next(steps)
        while True:
            calls = steps.send(run_calls(calls, km, st, threads))
    except StopIteration as done:
        result: T = done.value
        return result
