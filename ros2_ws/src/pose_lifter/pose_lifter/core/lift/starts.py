"""The starts of a solve: the runs of alternations a mode tried, and the paper's choice of them.

A mode's stages over a batch of people (paper: :func:`paper_starts`; hybrid:
:meth:`pose_lifter.core.lift.hybrid.PriorFit.starts_people`) return :class:`Starts` per person:
its runs, each tagged with where it began (:class:`StartRun`), and what the lift reports of the
solve's work; the lifter keeps the run of the lowest objective.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.bases import PoseBases
from ..options import LifterOptions
from ..results import Failure, StartKind
from .batch import Person
from .runs import Run, Runs, RunSpec

__all__ = ["StartRun", "Starts", "paper_starts"]


@dataclass(frozen=True)
class StartRun:
    """A run of alternations and where it began.

    Attributes
    ----------
    kind : StartKind
    index : int
        With ``kind`` COLD the index of its multi-start pose (``PoseBases.with_starts``), else -1.
    run : Run
    """

    kind: StartKind
    index: int
    run: Run


@dataclass(frozen=True)
class Starts:
    """What a mode's solve tried.

    Attributes
    ----------
    runs : list of StartRun
        The candidate runs (the lift keeps the one of the lowest objective).
    total_alternations : int
        Alternations over every run tried (see ``LiftResult.total_alternations``).
    n_starts : int
        Starts tried.
    weights : ndarray, shape (12,)
        The 2D term's weights after the solve (the hybrid outlier pass sets some to 0).
    prior_pose : ndarray, shape (12, 3), optional
        The learned prior's pose in input units (hybrid mode), else None.
    """

    runs: list[StartRun]
    total_alternations: int
    n_starts: int
    weights: NDArray[np.float64]
    prior_pose: NDArray[np.float64] | None = None

    def best(self) -> StartRun:
        """The run of the lowest objective (the first of equal ones)."""
        return min(self.runs, key=lambda r: r.run.objective)


def paper_starts(runs: Runs, bases: PoseBases, options: LifterOptions, people: Sequence[Person]
                 ) -> list[Starts | Failure]:
    """The paper's stages over a batch of people (their normalised 2D ``xn`` (12, 2), weights ``w``
    (12,)), in order:

    1. the first runs, in one call: a warm person's run from the warm start (camera ``cam0``,
       normalised), and a cold person's screened multi-start, every start pose one alternation (a
       short first pose step when it screens);
    2. the cold people's ``n_refine`` best screened runs continued, in one call;
    3. the warm people's depth-mirrored hypotheses (``warm_flip``; :meth:`Runs.mirrored_runs`).

    Returns each person's :class:`Starts`, or the failure of the first of their runs that failed."""
    alphas = bases.with_starts(options.n_starts)
    # a short first pose step only when it screens (some starts are then dropped)
    screen = options.screen_pose_max_iter if len(alphas) > options.n_refine else None
    specs: list[RunSpec] = []
    for p in people:
        if p.warm is not None:
            specs.append(RunSpec(p.xn, p.w, p.warm.alpha, p.cam0))
        else:
            specs += [RunSpec(p.xn, p.w, a, None, 1, pose_max_iter=screen) for a in alphas]
    firsts = iter(runs.run_all(specs))
    out: dict[int, Starts | Failure] = {}
    warm: list[tuple[int, Run]] = []
    screened: dict[int, list[tuple[int, Run]]] = {}
    for i, p in enumerate(people):
        mine = [next(firsts)] if p.warm is not None else [next(firsts) for _ in alphas]
        ok = [r for r in mine if isinstance(r, Run)]
        if len(ok) < len(mine):
            out[i] = _first_failure(mine)
        elif p.warm is not None:
            warm.append((i, ok[0]))
        else:
            ranked = list(enumerate(ok))
            if len(ranked) > 1:  # screen: continue only the most promising starts
                ranked.sort(key=lambda kr: kr[1].objective)
                ranked = ranked[: options.n_refine]
            screened[i] = ranked
    cold = list(screened.items())
    done = iter(runs.run_all([RunSpec(people[i].xn, people[i].w, r.pose.alpha, None, start=r)
                              for i, ranked in cold for _, r in ranked]))
    for i, ranked in cold:
        continued = [next(done) for _ in ranked]
        ok = [r for r in continued if isinstance(r, Run)]
        if len(ok) < len(continued):
            out[i] = _first_failure(continued)
            continue
        tried = [StartRun(StartKind.COLD, k, r) for (k, _), r in zip(ranked, ok, strict=True)]
        # a continued run's n_iter counts its screening alternation too
        out[i] = Starts(tried, len(alphas) - len(tried) + sum(r.run.n_iter for r in tried), len(alphas),
                        people[i].w)
    flips = (runs.mirrored_runs([(people[i].xn, people[i].w, first, None) for i, first in warm])
             if options.warm_flip else [])
    for k, (i, first) in enumerate(warm):
        tried = [StartRun(StartKind.WARM, -1, first)]
        if options.warm_flip:
            flip = flips[k]
            if isinstance(flip, Failure):
                out[i] = flip
                continue
            tried.append(StartRun(StartKind.MIRRORED, -1, flip))
        out[i] = Starts(tried, sum(r.run.n_iter for r in tried), len(tried), people[i].w)
    return [out[i] for i in range(len(people))]


def _first_failure(runs: Sequence[Run | Failure]) -> Failure:
    """The first failure among a person's runs."""
    return next(r for r in runs if isinstance(r, Failure))
