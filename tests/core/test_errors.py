"""One error tree: bad input, bad options and a diverged solve are told apart, all PoseLifterErrors."""

from __future__ import annotations

import numpy as np
import pytest
from pose_lifter import cli
from pose_lifter.core import Lifter
from pose_lifter.core import reference as ref
from pose_lifter.core.baselines import ramakrishna as rk
from pose_lifter.core.errors import (
    InvalidInputError,
    OptionsError,
    PoseLifterError,
    SolverError,
    diverged_as_solver_error,
)
from pose_lifter.core.model.pose_model import PoseModel
from pose_lifter.core.options import LifterOptions
from pose_lifter.core.solve import camera
from pose_lifter.core.solve.pose_step import pose_step
from pose_lifter.messages.typestore import TypestoreError
from pose_lifter.offline import bags
from pose_lifter.offline.bags import BagError, BagReadError
from synthetic_poses import small_pca_bases


@pytest.fixture(scope="module")
def lifter() -> Lifter:
    return Lifter()


def test_bag_errors_join_the_tree_outside_the_core() -> None:
    from pose_lifter.core import errors

    assert not hasattr(errors, "BagError")  # the pure core knows nothing of bags
    assert issubclass(BagError, PoseLifterError) and issubclass(BagReadError, BagError)
    assert issubclass(BagError, RuntimeError) and issubclass(TypestoreError, PoseLifterError)
    with pytest.raises(PoseLifterError, match="bag not found"):
        bags.bag_topics("/nonexistent/x.mcap")


def test_solver_errors_are_not_input_errors() -> None:
    assert issubclass(SolverError, PoseLifterError)
    assert not issubclass(SolverError, InvalidInputError)
    assert issubclass(ref.ReferenceSolverError, SolverError)


def test_a_kernels_linalg_error_becomes_a_solver_error_naming_the_step() -> None:
    with pytest.raises(SolverError, match="run diverged") as info, diverged_as_solver_error("run"):
        raise np.linalg.LinAlgError("Matrix is singular")
    assert isinstance(info.value.__cause__, np.linalg.LinAlgError)
    with pytest.raises(ValueError, match="other"), diverged_as_solver_error("run"):
        raise ValueError("other")  # any other error passes unchanged
    with diverged_as_solver_error("run"):
        pass


def test_a_diverged_camera_step_is_a_solver_error() -> None:
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(12, 2)), rng.normal(size=(12, 3))
    camera.camera_step(x, 1e100 * y, np.ones(12))  # large but fine
    with pytest.raises(SolverError, match="camera step diverged"):
        camera.camera_step(x, 1e160 * y, np.ones(12))  # finite input, its normal equations overflow


@pytest.mark.parametrize("small", [False, True])
def test_a_diverged_pose_step_is_a_solver_error(lifter: Lifter, small: bool) -> None:
    # the compiled step (the shipped bases) and the Python loop with the paper's inner ADM (12 PCA
    # bases: no onto limb map)
    bases = small_pca_bases() if small else None
    model = PoseModel.build(bases, bases.limb_proportions) if bases is not None else lifter.model
    alpha0 = (bases if bases is not None else lifter.bases).start_alphas[0]
    x = np.random.default_rng(0).normal(size=(12, 2))
    m0 = np.hstack([np.eye(2), np.zeros((2, 1))])
    args = (np.zeros(2), np.ones(12), model, alpha0, LifterOptions())
    # large but fine (from ~1e80 on, the Python loop's norms overflow, with numpy's warning)
    assert np.isfinite(pose_step(x, (1e50 if small else 1e100) * m0, *args, max_iter=5).objective)
    with pytest.raises(SolverError, match="pose step diverged"), np.errstate(over="ignore", invalid="ignore"):
        pose_step(x, 1e200 * m0, *args, max_iter=5)


def test_a_malformed_projection_is_invalid_input() -> None:
    with pytest.raises(InvalidInputError, match=r"\(2, 3\)"):
        camera.project_scaled_orthographic(np.eye(3))
    with pytest.raises(ValueError):  # InvalidInputError still is one
        camera.project_scaled_orthographic(np.eye(3))


@pytest.mark.parametrize("bad", [{"max_bases": 0}, {"limb_constraint": "each"}, {"min_visible_joints": 2}])
def test_bad_ramakrishna_options_are_options_errors(bad: dict[str, object]) -> None:
    with pytest.raises(OptionsError):
        rk.RamakrishnaOptions(**bad)  # type: ignore[arg-type]


def test_a_bad_ramakrishna_basis_cap_is_an_options_error(lifter: Lifter) -> None:
    with pytest.raises(OptionsError, match="max_bases"):
        rk.ramakrishna_lift(np.zeros((12, 2)), None, lifter.bases, max_bases=0)


def test_the_cli_reports_a_diverged_solve_as_a_data_error() -> None:
    assert cli._is_data_error(SolverError("pose step diverged"))
    assert isinstance(SolverError("x"), cli._library_errors())
    assert isinstance(BagError("x"), cli._library_errors()) and not cli._is_data_error(BagError("x"))
