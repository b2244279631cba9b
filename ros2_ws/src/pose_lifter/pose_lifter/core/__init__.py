"""pose_lifter.core: the method of Wang et al. (CVPR 2014) in numpy/scipy; never imports rclpy.

Importing the package is cheap: each name of ``__all__`` is imported from its module on first use
(PEP 562), so ``from pose_lifter.core.errors import PoseLifterError`` (the bag reader, the CLI's
error handling) does not load the solver's numba and scipy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .errors import (
        BasisFileError,
        InvalidInputError,
        OptionsError,
        PoseLifterError,
        SolverError,
        TooFewJointsError,
        UnknownLayoutError,
    )
    from .lift.lifter import Lifter
    from .model.bases import PoseBases, learn_classwise_pca_bases, learn_pca_bases, learn_sparse_bases
    from .model.metrics import mpjpe, normalised_error, p_mpjpe, per_joint_error, procrustes_align
    from .model.skeleton import JOINT_NAMES, LIMB_NAMES, LIMBS, limb_lengths, normalise_pose
    from .options import VARIANTS, ExperimentOptions, LifterOptions, UserOptions, Variant, get_variant
    from .results import (
        Camera,
        CameraResult,
        LiftOutcome,
        LiftResult,
        LiftStatus,
        Outcome,
        PoseResult,
        SolveInfo,
        StartKind,
        TrackContext,
        WarmStart,
    )

#: Public name -> the module of this package that defines it.
_MODULE_OF: dict[str, str] = {
    "PoseBases": "model.bases",
    "learn_classwise_pca_bases": "model.bases",
    "learn_pca_bases": "model.bases",
    "learn_sparse_bases": "model.bases",
    "BasisFileError": "errors",
    "InvalidInputError": "errors",
    "OptionsError": "errors",
    "PoseLifterError": "errors",
    "SolverError": "errors",
    "TooFewJointsError": "errors",
    "UnknownLayoutError": "errors",
    "Lifter": "lift.lifter",
    "mpjpe": "model.metrics",
    "normalised_error": "model.metrics",
    "p_mpjpe": "model.metrics",
    "per_joint_error": "model.metrics",
    "procrustes_align": "model.metrics",
    "ExperimentOptions": "options",
    "LifterOptions": "options",
    "UserOptions": "options",
    "VARIANTS": "options",
    "Variant": "options",
    "get_variant": "options",
    "JOINT_NAMES": "model.skeleton",
    "LIMBS": "model.skeleton",
    "LIMB_NAMES": "model.skeleton",
    "limb_lengths": "model.skeleton",
    "normalise_pose": "model.skeleton",
    "Camera": "results",
    "CameraResult": "results",
    "LiftOutcome": "results",
    "LiftResult": "results",
    "LiftStatus": "results",
    "Outcome": "results",
    "PoseResult": "results",
    "SolveInfo": "results",
    "StartKind": "results",
    "TrackContext": "results",
    "WarmStart": "results",
}

__all__ = [
    "JOINT_NAMES",
    "LIMBS",
    "LIMB_NAMES",
    "VARIANTS",
    "BasisFileError",
    "Camera",
    "CameraResult",
    "ExperimentOptions",
    "InvalidInputError",
    "LiftOutcome",
    "LiftResult",
    "LiftStatus",
    "Lifter",
    "LifterOptions",
    "OptionsError",
    "Outcome",
    "PoseBases",
    "PoseLifterError",
    "PoseResult",
    "SolveInfo",
    "SolverError",
    "StartKind",
    "TooFewJointsError",
    "TrackContext",
    "UnknownLayoutError",
    "UserOptions",
    "Variant",
    "WarmStart",
    "get_variant",
    "learn_classwise_pca_bases",
    "learn_pca_bases",
    "learn_sparse_bases",
    "limb_lengths",
    "mpjpe",
    "normalise_pose",
    "normalised_error",
    "p_mpjpe",
    "per_joint_error",
    "procrustes_align",
]


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # once loaded, a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
