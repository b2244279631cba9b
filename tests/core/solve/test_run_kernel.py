"""The compiled run (core/solve/run_kernel.py) against the Python alternation loop of ``Runs.run`` (the
other solvers' path, and the kernel's reference): every run of tracked lifts (new, warm,
continued, screening and mirrored runs, with and without the prior's rows) replayed both ways;
and the objective's terms, which both paths call, against their formulas written with numpy.

The two paths call the same compiled steps and the same compiled objective terms, so they perform
the same floating-point operations on any CPU and BLAS: what the replay checks is the kernel's
control flow (which alternation is kept, when a run stops, how a continued run resumes), which a
changed sign, bound or index breaks by far more than FUSED_RUN_REL."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core.lift.lifter import Lifter
from pose_lifter.core.lift.runs import Run, Runs, RunSpec
from pose_lifter.core.model.pose_model import PoseModel
from pose_lifter.core.options import VARIANTS, LifterOptions
from pose_lifter.core.results import Failure
from pose_lifter.core.solve.pose_kernel import _depth_row, _depth_term, _sum_abs
from pose_lifter.core.solve.pose_step import PriorRows
from pose_lifter.core.solve.run_kernel import _run_objective
from pose_lifter.offline.lift import lift_messages
from pose_lifter.offline.settings import LiftSettings
from synthetic_poses import small_pca_bases

REPO = Path(__file__).resolve().parents[3]
Call = tuple[tuple[Any, ...], dict[str, Any]]


def _recorded_runs(mode: str, bag: str, n_messages: int, variant: str = "full") -> tuple[Lifter, list[Call]]:
    """The runs (``Runs.run_all``'s specs, as ``Runs.run`` arguments) of a tracked lift of a
    bag's first messages (through the loop)."""
    from pose_lifter.offline.bags import read_messages

    kps, infos = [], []
    for x in read_messages(REPO / "bags" / bag, None):
        if x.topic.endswith("keypoints_2d"):
            kps.append((x.stamp_ns, x.msg))
        elif x.topic.endswith("camera_info"):
            infos.append((x.stamp_ns, x.msg))
    lifter = Lifter(None, LifterOptions(mode=mode, n_starts=4, variant=variant) if mode == "paper"
                    else LifterOptions())
    lifter.runs.compiled = False
    calls: list[Call] = []
    original = lifter.runs.run_all

    def recorded(specs: Sequence[RunSpec]) -> list[Run | Failure]:
        calls.extend(((sp.xn, sp.w, sp.alpha0, sp.cam0),
                      {"max_alternations": sp.max_alternations, "start": sp.start,
                       "pose_max_iter": sp.pose_max_iter, "prior": sp.prior}) for sp in specs)
        return original(specs)

    lifter.runs.run_all = recorded  # type: ignore[method-assign]
    lift_messages(kps[:n_messages], infos, lifter, LiftSettings(smoothing_s=0.0))
    return lifter, calls


def _rel(a: float, b: float) -> float:
    return abs(a - b) / max(abs(b), 1e-12)


def _assert_same(a: Run, b: Run) -> None:
    """Two runs of one problem agree (FUSED_RUN_REL): result, counts and every alternation."""
    assert (a.n_iter, a.converged, len(a.history)) == (b.n_iter, b.converged, len(b.history))
    assert _rel(a.objective, b.objective) <= tol.FUSED_RUN_REL
    for ha, hb in zip(a.history, b.history, strict=True):  # every alternation, both steps
        assert _rel(ha.objective, hb.objective) <= tol.FUSED_RUN_REL
        assert (ha.camera.n_iter, ha.camera.converged, ha.pose.n_iter, ha.pose.converged) == (
            hb.camera.n_iter, hb.camera.converged, hb.pose.n_iter, hb.pose.converged)
        assert _rel(ha.camera.objective, hb.camera.objective) <= tol.FUSED_RUN_REL
        assert _rel(ha.pose.objective, hb.pose.objective) <= tol.FUSED_RUN_REL
    scale = max(np.abs(b.pose.alpha).max(), 1e-12)
    assert np.abs(a.pose.alpha - b.pose.alpha).max() <= tol.FUSED_RUN_REL * scale
    assert np.abs(a.pose.pose - b.pose.pose).max() <= tol.FUSED_RUN_REL * np.abs(b.pose.pose).max()
    assert np.abs(a.camera.camera.rotation - b.camera.camera.rotation).max() <= tol.FUSED_RUN_REL
    assert _rel(a.camera.camera.scale, b.camera.camera.scale) <= tol.FUSED_RUN_REL
    assert np.abs(a.camera.camera.translation - b.camera.camera.translation).max() <= tol.FUSED_RUN_REL
    assert (a.pose.n_iter, a.pose.converged, a.pose.alpha_iter, a.camera.n_iter, a.camera.converged) == (
        b.pose.n_iter, b.pose.converged, b.pose.alpha_iter, b.camera.n_iter, b.camera.converged)
    assert _rel(a.pose.objective, b.pose.objective) <= tol.FUSED_RUN_REL
    assert _rel(a.camera.objective, b.camera.objective) <= tol.FUSED_RUN_REL
    assert abs(a.pose.limb_violation - b.pose.limb_violation) <= tol.FUSED_RUN_REL


@pytest.mark.parametrize(("mode", "bag", "variant"), [
    ("hybrid", "punch_outliers.mcap", "full"), ("hybrid", "two_people.mcap", "full"),
    ("paper", "walk_noisy.mcap", "full"), ("paper", "walk_noisy.mcap", "L1NAWS")])
def test_compiled_run_is_the_python_loop(mode: str, bag: str, variant: str) -> None:
    """The compiled run against the Python loop of alternations on a lift's recorded runs, with
    limbs (the Riemannian alpha-step) and without (the linear one)."""
    lifter, calls = _recorded_runs(mode, bag, 6, variant)
    loop = Runs(lifter.model, lifter.options)
    loop.compiled = False
    compiled = Runs(lifter.model, lifter.options)
    assert compiled.compiled
    kinds = set()
    for args, kwargs in calls:
        kinds.add((kwargs.get("start") is not None, args[3] is not None, kwargs.get("prior") is not None))
        _assert_same(compiled.run(*args, **kwargs), loop.run(*args, **kwargs))
    # new runs, cold and (hybrid) from the previous frame's camera, and (paper) continued screened
    # starts were replayed
    hybrid = mode == "hybrid"
    assert (False, False, hybrid) in kinds
    assert ((False, True, True) if hybrid else (True, False, False)) in kinds
    # a run screened by one alternation and continued, both ways
    for args, kwargs in calls[:6]:
        if kwargs.get("start") is not None:
            continue
        prior = kwargs.get("prior")
        sa = compiled.run(*args[:4], max_alternations=1, prior=prior)
        sb = loop.run(*args[:4], max_alternations=1, prior=prior)
        _assert_same(sa, sb)
        _assert_same(compiled.run(args[0], args[1], sa.pose.alpha, None, start=sa, prior=prior),
                     loop.run(args[0], args[1], sb.pose.alpha, None, start=sb, prior=prior))


def test_the_other_solvers_run_the_python_loop() -> None:
    """Every variant runs compiled on the shipped bases; the cvxpy references and the paper's inner
    ADM (limbs on bases whose limb map is not onto) run the loop."""
    lifter = Lifter(None, LifterOptions())
    assert lifter.runs.compiled
    paper = LifterOptions(mode="paper")
    for variant in VARIANTS:
        assert Runs(lifter.model, paper.replace(variant=variant)).compiled, variant
    for opts in (paper.replace(camera_solver="cvxpy"), paper.replace(pose_solver="cvxpy")):
        assert not Runs(lifter.model, opts).compiled
    small = PoseModel.build(small_pca_bases(), np.sqrt(lifter.model.limb_sq))
    assert small.limb_coordinates is None
    assert not Runs(small, paper).compiled
    assert Runs(small, paper.replace(variant="L1NAWS")).compiled


def test_the_objective_terms_are_their_formulas() -> None:
    """``||a||_1``, the depth row ``s r1 x r2``, the prior's depth rows and the run's objective,
    compiled, against the same formulas in numpy (another summation order: ROUND_OFF relative)."""
    rng = np.random.default_rng(3)
    for n in (0, 5, 8, 13, 128, 129, 200, 1000):
        a = rng.normal(size=n)
        assert _sum_abs(a) == pytest.approx(float(np.sum(np.abs(a))), rel=tol.ROUND_OFF, abs=0.0)
    for _ in range(50):
        m0 = rng.normal(size=(2, 3))
        y, xp, pw = rng.normal(size=(12, 3)), rng.normal(size=(12, 3)), rng.uniform(size=(12, 2))
        m3 = np.cross(m0[0], m0[1]) / np.linalg.norm(m0[0])
        assert np.abs(_depth_row(m0) - m3).max() <= tol.ROUND_OFF * np.abs(m3).max()
        expected = float(pw[:, 1] @ np.abs(xp[:, 2] - (y - y.mean(axis=0)) @ m3))
        assert _depth_term(y.reshape(-1), m0, xp, pw) == pytest.approx(expected, rel=tol.ROUND_OFF)
        assert PriorRows(xp, pw).depth_term(y, m0) == _depth_term(y.reshape(-1), m0, xp, pw)
        # the run's objective F: the camera step's objective, theta ||alpha||_1 and the depth rows
        alpha, cobj, th = rng.normal(size=30), float(rng.uniform(0.1, 2.0)), float(rng.uniform(0.0, 0.5))
        f = _run_objective(cobj, alpha, th, y.reshape(-1), m0, xp, pw)
        assert f == pytest.approx(cobj + th * float(np.sum(np.abs(alpha))) + expected, rel=tol.ROUND_OFF)
        no_depth = np.column_stack([pw[:, 0], np.zeros(12)])
        assert _run_objective(cobj, alpha, th, y.reshape(-1), m0, xp, no_depth) == pytest.approx(
            cobj + th * float(np.sum(np.abs(alpha))), rel=tol.ROUND_OFF)
