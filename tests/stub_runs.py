"""For the stand-in lifters of the pipeline tests: their ``lift_people`` (each row's ``lift``,
with its status) and their ``runs``, which nothing may read (the track policy hands a lifter its
rows through ``lift_people`` alone)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NoReturn

from pose_lifter.core.lift.batch import LiftRow
from pose_lifter.core.results import Failure, LiftOutcome


class NoRuns:
    """A stand-in lifter's ``runs``: reading any of it fails the test."""

    def __getattr__(self, name: str) -> NoReturn:
        raise AssertionError(f"a stand-in lifter's runs were read ({name})")


RUNS_NEEDED_NONE = NoRuns()


def lift_each(lifter: Any, rows: Sequence[LiftRow]) -> list[LiftOutcome]:
    """A stand-in lifter's ``lift_people``: its ``lift`` of each row, or the failure it raised."""
    out: list[LiftOutcome] = []
    for r in rows:
        try:
            out.append(LiftOutcome.solved(lifter.lift(r.points, r.confidence, r.warm)))
        except Exception as err:
            out.append(LiftOutcome.failed(Failure.of(err)))
    return out
