"""For the stand-in lifters of the pipeline tests: the ``runs`` whose ``solve`` drives a solve
(:mod:`pose_lifter.core.lift.batch`) that asks for no runs of the compiled kernel."""

from __future__ import annotations

from typing import Any


class NoRuns:
    """``Runs.solve`` for solves that yield nothing (a stand-in lifter's ``lift_steps``)."""

    def solve(self, steps: Any) -> Any:
        try:
            next(steps)
        except StopIteration as done:
            return done.value
        raise AssertionError("a stand-in lifter's solve asked for runs of the compiled kernel")


RUNS_NEEDED_NONE = NoRuns()
