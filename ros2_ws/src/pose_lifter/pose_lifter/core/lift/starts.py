"""The starts of a solve: the runs of alternations a mode tried, and the paper's choice of them.

A mode's solve (paper: :func:`paper_starts`; hybrid:
:meth:`pose_lifter.core.lift.hybrid.PriorFit.starts_people`, for a batch of people) returns
:class:`Starts` per person: its runs, each tagged with where it began (:class:`StartRun`), and
what the lift reports of the solve's work; the lifter keeps the run of the lowest objective.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.bases import PoseBases
from ..options import LifterOptions
from ..results import Camera, StartKind, WarmStart
from .batch import Steps, gather
from .runs import Run, Runs

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


def paper_starts(runs: Runs, bases: PoseBases, options: LifterOptions, xn: NDArray[np.float64],
                 w: NDArray[np.float64], warm: WarmStart | None, cam0: Camera | None) -> Steps[Starts]:
    """The paper's starts on the normalised 2D ``xn`` (12, 2) with weights ``w`` (12,): the warm
    start (camera ``cam0``, normalised) and its depth-mirrored copy (``warm_flip``), or the
    screened multi-start: every start pose one alternation (a short first pose step when it
    screens; the starts' runs in one round), the ``n_refine`` best continued (in one round). A
    solve (:mod:`pose_lifter.core.lift.batch`)."""
    if warm is not None:
        first = yield from runs.run_steps(xn, w, warm.alpha, cam0)
        tried = [StartRun(StartKind.WARM, -1, first)]
        if options.warm_flip:
            flip = yield from runs.mirrored_run_steps(xn, w, first, None)
            tried.append(StartRun(StartKind.MIRRORED, -1, flip))
        return Starts(tried, sum(r.run.n_iter for r in tried), len(tried), w)
    alphas = bases.with_starts(options.n_starts)
    # a short first pose step only when it screens (some starts are then dropped)
    screen = options.screen_pose_max_iter if len(alphas) > options.n_refine else None
    first_runs = yield from gather([runs.run_steps(xn, w, a, None, max_alternations=1, pose_max_iter=screen)
                                    for a in alphas])
    screened = list(enumerate(first_runs))
    n_screened = len(screened)
    if len(screened) > 1:  # screen: continue only the most promising starts
        screened.sort(key=lambda r: r[1].objective)
        screened = screened[: options.n_refine]
    continued = yield from gather([runs.run_steps(xn, w, r.pose.alpha, None, start=r) for _, r in screened])
    tried = [StartRun(StartKind.COLD, i, run) for (i, _), run in zip(screened, continued, strict=True)]
    # a continued run's n_iter counts its screening alternation too
    return Starts(tried, n_screened - len(tried) + sum(r.run.n_iter for r in tried), len(alphas), w)
