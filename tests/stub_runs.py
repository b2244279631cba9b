"""For the stand-in lifters of the pipeline tests: the ``runs`` whose ``solve`` drives a solve
(:mod:`pose_lifter.core.lift.batch`) that asks for lifts of a stand-in lifter (its
``lift_people``) and for no runs of the compiled kernel."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pose_lifter.core.lift.batch import LiftCall, outcomes


class NoRuns:
    """``Runs.solve`` for solves whose rounds ask only for lifts (:class:`LiftCall`), answered by
    :func:`~pose_lifter.core.lift.batch.outcomes` (each lifter's calls in one ``lift_people``)."""

    def solve(self, steps: Any) -> Any:
        try:
            calls = next(steps)
            while True:
                if not all(isinstance(c, LiftCall) for c in calls):
                    raise AssertionError("a stand-in lifter's solve asked for runs or prior poses")
                calls = steps.send(outcomes(calls, None, None))  # type: ignore[arg-type]
        except StopIteration as done:
            return done.value


RUNS_NEEDED_NONE = NoRuns()


def lift_each(lifter: Any, calls: Sequence[LiftCall]) -> list[Any]:
    """A stand-in lifter's ``lift_people``: its ``lift`` of each call, or the error it raised."""
    out: list[Any] = []
    for c in calls:
        try:
            out.append(lifter.lift(c.points, c.confidence, c.warm))
        except Exception as err:
            out.append(err)
    return out
