"""pose_lifter.core: the method of Wang et al. (CVPR 2014) in numpy/scipy; never imports rclpy."""

from .bases import PoseBases, learn_classwise_pca_bases, learn_pca_bases, learn_sparse_bases
from .errors import (
    BasisFileError,
    InvalidInputError,
    OptionsError,
    PoseLifterError,
    SolverError,
    TooFewJointsError,
    UnknownLayoutError,
)
from .layouts import LAYOUTS, get_layout, to_model_joints
from .lifter import Lifter
from .metrics import mpjpe, normalised_error, p_mpjpe, per_joint_error, procrustes_align
from .options import VARIANTS, LifterOptions, Variant, get_variant
from .skeleton import JOINT_NAMES, LIMB_NAMES, LIMBS, limb_lengths, normalise_pose
from .types import Camera, CameraResult, LiftResult, PoseResult, WarmStart

__all__ = [
    "JOINT_NAMES",
    "LAYOUTS",
    "LIMBS",
    "LIMB_NAMES",
    "VARIANTS",
    "BasisFileError",
    "Camera",
    "CameraResult",
    "InvalidInputError",
    "LiftResult",
    "Lifter",
    "LifterOptions",
    "OptionsError",
    "PoseBases",
    "PoseLifterError",
    "PoseResult",
    "SolverError",
    "TooFewJointsError",
    "UnknownLayoutError",
    "Variant",
    "WarmStart",
    "get_layout",
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
    "to_model_joints",
]
