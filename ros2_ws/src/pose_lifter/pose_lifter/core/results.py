"""Result and state types shared by the solver steps and the lifter.

Every solver result is a :class:`SolveInfo` (``objective``, ``n_iter``, ``converged``, the same
meaning everywhere: the objective the solver minimised at the point it returns, its iterations,
and whether its stopping rule was met before its iteration cap); a step's ADM multipliers (its
warm start, and what it ends with) are :class:`Duals`. A lift of a batch gives each row a
:class:`Outcome`: its :class:`LiftStatus` and reason, and its :class:`LiftResult` when solved
(as osqp's ``info.status``); a row that stopped short of a result carries a :class:`Failure`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import Generic, Self, TypeAlias, TypeVar

import numpy as np
from numpy.typing import NDArray

from .errors import InvalidInputError, OutOfOrderFrameError, PoseLifterError, SolverError, TooFewJointsError

#: Frames of a track's 2D, oldest first: points (k, 12, 2) in input units and which of their
#: joints are used (k, 12).
Frames: TypeAlias = tuple[NDArray[np.float64], NDArray[np.bool_]]
#: What an :class:`Outcome` carries when solved.
R = TypeVar("R")

__all__ = [
    "AlphaResult",
    "Alternation",
    "Camera",
    "CameraResult",
    "Duals",
    "Failure",
    "Frames",
    "LiftOutcome",
    "LiftResult",
    "LiftStatus",
    "Normalisation",
    "Outcome",
    "PoseResult",
    "SolveInfo",
    "StartKind",
    "TrackContext",
    "WarmStart",
    "with_camera_poses",
]


@dataclass(frozen=True)
class Camera:
    """A weak-perspective (scaled orthographic) camera.

    ``x_j = M0 @ y_j + t`` with ``M0 = scale * rotation[:2]``.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Proper rotation, model (body) frame -> camera frame.
    scale : float
        > 0, image units per model unit.
    translation : ndarray, shape (2,)
    """

    rotation: NDArray[np.float64]
    scale: float
    translation: NDArray[np.float64]

    @property
    def projection(self) -> NDArray[np.float64]:
        """``M0 = [m1; m2]``, shape (2, 3) (computed once: a camera's arrays are not changed; kept
        in the instance's ``__dict__`` by hand, as ``functools.cached_property`` does, without its
        lock)."""
        m0: NDArray[np.float64] | None = self.__dict__.get("_projection")
        if m0 is None:
            m0 = self.__dict__["_projection"] = np.asarray(self.scale * self.rotation[:2])
        return m0

    def project(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Project a pose (12, 3) -> (12, 2)."""
        return np.asarray(pose @ self.projection.T + self.translation)


def project_each(poses: NDArray[np.float64], cameras: Sequence[Camera]) -> NDArray[np.float64]:
    """Each pose (n, 12, 3) projected by its camera: (n, 12, 2), each one what
    :meth:`Camera.project` gives it (the same product per pose)."""
    proj = np.array([c.projection for c in cameras])  # (n, 2, 3)
    t = np.array([c.translation for c in cameras])  # (n, 2)
    return np.asarray(poses @ proj.transpose(0, 2, 1) + t[:, None, :])


@dataclass(frozen=True)
class SolveInfo:
    """How a solver ended: the base of every solver result.

    Attributes
    ----------
    objective : float
        The objective the solver minimises, at the returned point.
    n_iter : int
        Iterations run (<= the solver's cap).
    converged : bool
        The stopping rule was met (False: the iteration cap was reached, or a line search failed).
    """

    objective: float
    n_iter: int
    converged: bool


@dataclass(frozen=True)
class Duals:
    """Unscaled ADM multipliers a step ends with, from which another step can start
    (``pose_step(..., duals=...)``, ``camera_step(..., duals=...)``).

    Attributes
    ----------
    data : ndarray
        Of the data split (camera step: ``E = X - M Y - t``, shape (n, 2); pose step:
        ``gamma = c - A alpha``, shape (m,)).
    coupling : ndarray
        Of the coupling constraint (camera step: ``M = scale R[:2]``, shape (2, 3); pose step:
        ``beta = alpha``, shape (k,)).
    """

    data: NDArray[np.float64]
    coupling: NDArray[np.float64]


@dataclass(frozen=True)
class CameraResult(SolveInfo):
    """Output of the camera step: the camera (``objective`` its weighted loss) and the final ADM
    multipliers (None from the reference solver)."""

    camera: Camera
    duals: Duals | None = None


@dataclass(frozen=True)
class AlphaResult(SolveInfo):
    """Output of an alpha-step solver: ``x`` is ``z = [s; 1]`` of a lifted problem (``objective`` =
    ``z^T W z``) or the reduced coordinates ``s`` (``objective`` = ``s^T G s - 2 lin^T s``)."""

    x: NDArray[np.float64]


@dataclass(frozen=True)
class PoseResult(SolveInfo):
    """Output of the pose step (``objective`` = ``loss + theta ||alpha||_1`` + the prior's rows, at
    ``alpha``).

    Attributes
    ----------
    alpha : ndarray, shape (k,)
    pose : ndarray, shape (12, 3)
        ``mean + B alpha`` in the model frame.
    limb_violation : float
        ``max_i | ||C_i y|| - sqrt(L_i) |`` (0 when the variant has no limb constraints).
    alpha_iter : int
        Iterations of the alpha-step solver, summed over the ADM's iterations.
    duals : Duals, optional
        The final unscaled multipliers (for a warm start of the next pose step).
    """

    alpha: NDArray[np.float64]
    pose: NDArray[np.float64]
    limb_violation: float
    alpha_iter: int = 0
    duals: Duals | None = None


@dataclass(frozen=True)
class Alternation:
    """One camera/pose alternation of a run: the run's objective after it and how each step ended."""

    objective: float
    camera: SolveInfo
    pose: SolveInfo


@dataclass(frozen=True)
class Normalisation:
    """The lifter's 2D normalisation of one frame: ``xn = (x - centre) / spread`` (``centre`` (2,) in
    input units; ``spread``: input units per normalised unit)."""

    centre: NDArray[np.float64]
    spread: float


@dataclass(frozen=True)
class WarmStart:
    """A previous solution to start from (the live node keeps one per track)."""

    camera: Camera
    alpha: NDArray[np.float64]


class StartKind(Enum):
    """Where the run a lift kept began."""

    #: One of the multi-start poses of a cold solve (``LiftResult.start_index`` says which).
    COLD = "cold"
    #: The warm start: the track's previous frame.
    WARM = "warm"
    #: The depth-mirrored copy of the best run (the weak-perspective ambiguity).
    MIRRORED = "mirrored"
    #: The learned prior's pose for this frame (hybrid mode).
    PRIOR = "prior"
    #: No run: the learned prior's pose alone (learned mode).
    LEARNED = "learned"


@dataclass(frozen=True)
class TrackContext:
    """What a track knows about this frame of its person (:class:`pose_lifter.core.track.policy.TrackPolicy`
    fills it; every field is optional). Used by the hybrid mode; the learned mode reads ``past``.

    Attributes
    ----------
    limb_proportions : ndarray, shape (8,), optional
        The person's limb proportions (the track's estimate over its frames), used for the limb
        constraints with ``options.prior_limbs``.
    temporal_weight : float or ndarray, shape (12,)
        With a warm start: weight ``w`` (per joint, or one for all) of the warm start's pose ``Y``
        in the prior term's target ``(P + w Y) / (1 + w)``, ``Y``'s image positions moved by the
        median motion of the visible joints since it (0: none; the policy sets it from the track's
        2D noise, up to ``options.temporal_weight``, and to ``options.missing_temporal_weight`` for
        joints missing in this frame).
    past : (ndarray (k, 12, 2), ndarray of bool (k, 12)), optional
        The track's previous frames (oldest first, evenly spaced up to this one) and which of
        their joints were used: the input of a temporal prior (``PosePrior.window > 1``; missing
        history is padded with the oldest frame given, or this one). Ignored by a single-frame
        prior.
    future : (ndarray (k, 12, 2), ndarray of bool (k, 12)), optional
        The track's next frames (oldest first, evenly spaced from this one) and which of their
        joints are visible: read by a temporal prior of a frame inside its window
        (``PosePrior.future_frames > 0``, an offline lift's; missing frames are padded with the
        latest one given, or this one). Ignored by a causal prior.
    gated : bool
        The frame was screened by the per-track outlier gate; the outlier pass then uses
        ``options.outlier_threshold_gated`` instead of ``options.outlier_threshold``.
    fill : (ndarray (12, 2), ndarray of bool (12,)), optional
        Predicted image positions of the joints (input units) and which of them may stand in for
        a joint this frame lacks (missing: low confidence or non-finite) in the learned prior's
        input; the 2D fit still ignores such a joint. A joint the outlier pass flags is not
        filled: it disagreed with the fit or the prior on this frame (filled or not, the held-out
        figures agreed within 0.2 mm).
    """

    limb_proportions: NDArray[np.float64] | None = None
    temporal_weight: float | NDArray[np.float64] = 0.0
    past: Frames | None = None
    gated: bool = False
    fill: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None
    future: Frames | None = None


@dataclass(frozen=True)
class LiftResult:
    """Everything one lift returns.

    Attributes
    ----------
    pose : ndarray, shape (12, 3)
        3D pose in the model frame, in the bases' units: their mean right lower leg is 1 (a
        tracked hybrid lift gives the person its track's limb proportions at the bases' mean
        limb size, so its own leg is within a few per cent of 1). Multiply by a leg length in
        metres for metric output.
    pose_camera : ndarray, shape (12, 3)
        The same pose rotated into the camera frame (x right, y down, z forward), centred,
        same units.
    camera : Camera
        In input image units (pixels): ``points_2d ~ camera.project(pose)``.
    alpha : ndarray, shape (k,)
    objective : float
        Final objective in normalised units (loss + theta ||alpha||_1).
    reprojection_error : float
        Mean 2D distance between visible input joints and the projection, input units.
    limb_violation : float
    n_iter : int
        Camera/pose alternations of the kept start.
    converged : bool
    n_starts : int
        Starts tried.
    start_index : int
        With ``start`` COLD the index of the multi-start pose the kept run began at
        (``PoseBases.with_starts``), else -1.
    weights : ndarray, shape (12,)
        Per-joint weights used in the loss (0 = missing, or dropped as a confident outlier by
        the hybrid mode's outlier pass).
    prior_pose : ndarray, shape (12, 3), optional
        The learned prior's pose for this frame (hybrid and learned modes): image positions in
        input units and depths relative to the joints' mean depth, same units; None in paper mode.
    total_alternations : int
        Camera/pose alternations over all starts (the solve's work: a cold solve's screening
        alternation of every start plus the refined starts' further ones; a warm solve's
        warm and mirrored runs).
    history : tuple of Alternation
        The kept run's alternations in order (objective, and each step's convergence); empty in
        learned mode.
    start : StartKind
        Where the kept run began.
    """

    pose: NDArray[np.float64]
    pose_camera: NDArray[np.float64]
    camera: Camera
    alpha: NDArray[np.float64]
    objective: float
    reprojection_error: float
    limb_violation: float
    n_iter: int
    converged: bool
    n_starts: int
    start_index: int
    weights: NDArray[np.float64]
    total_alternations: int = 0
    prior_pose: NDArray[np.float64] | None = None
    history: tuple[Alternation, ...] = ()
    start: StartKind = StartKind.COLD

    def warm_start(self) -> WarmStart:
        """The state to warm-start the next frame of the same person."""
        return WarmStart(self.camera, self.alpha.copy())

    def with_pose(self, pose: NDArray[np.float64] | None = None,
                  pose_camera: NDArray[np.float64] | None = None) -> LiftResult:
        """This result with ``pose`` and/or ``pose_camera`` (12, 3) replaced, every other field
        shared: ``dataclasses.replace`` without its pass through ``__init__`` (the per-track
        policy and the offline smoothing replace the pose of every frame)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        if pose is not None:
            new.__dict__["pose"] = pose
        if pose_camera is not None:
            new.__dict__["pose_camera"] = pose_camera
        return new

    def with_camera_pose(self, pose_camera: NDArray[np.float64]) -> LiftResult:
        """This result with its camera-frame pose replaced by ``pose_camera`` (12, 3, centred) and
        its body-frame pose derived for the same camera and centre (``pose_camera = (pose -
        mean) R^T``, so ``pose = pose_camera R + mean``): what the output smoothing, the
        measurement update and the offline centred smoothing publish."""
        return with_camera_poses([self], np.asarray(pose_camera, dtype=np.float64)[None])[0]


def with_camera_poses(results: Sequence[LiftResult], poses_camera: NDArray[np.float64]) -> list[LiftResult]:
    """:meth:`LiftResult.with_camera_pose` of n results and their new camera-frame poses
    ``poses_camera`` (n, 12, 3), the body-frame poses computed as arrays over the n (each what
    it is alone)."""
    rotations = np.array([r.camera.rotation for r in results])  # (n, 3, 3)
    body = np.array([r.pose for r in results])  # (n, 12, 3)
    poses = poses_camera @ rotations + body.mean(axis=1)[:, None, :]
    return [r.with_pose(poses[i], np.ascontiguousarray(poses_camera[i])) for i, r in enumerate(results)]


class LiftStatus(IntEnum):
    """How one row of a batch lift ended (:attr:`LiftOutcome.status`)."""

    #: Lifted: the row has its :class:`LiftResult`.
    SOLVED = 0
    #: The input cannot be lifted (:class:`~pose_lifter.core.errors.InvalidInputError`): a shape,
    #: non-finite confidences, the visible joints at one point, a bad track field, or an input the
    #: learned prior refuses.
    INVALID_INPUT = 1
    #: Fewer joints visible than ``min_visible_joints``
    #: (:class:`~pose_lifter.core.errors.TooFewJointsError`).
    TOO_FEW_JOINTS = 2
    #: The solve gave non-finite values on valid input (:class:`~pose_lifter.core.errors.SolverError`).
    DIVERGED = 3
    #: A tracked frame older than its track's last one
    #: (:class:`~pose_lifter.core.errors.OutOfOrderFrameError`; the track is kept).
    OUT_OF_ORDER = 4
    #: An unexpected error (a bug); the reason names it. It costs only its own row.
    FAILED = 5


#: The refusal each status but ``FAILED`` stands for (:meth:`Failure.error`), most specific first
#: (:meth:`Failure.of`).
_REFUSALS: dict[LiftStatus, type[PoseLifterError]] = {
    LiftStatus.TOO_FEW_JOINTS: TooFewJointsError,
    LiftStatus.INVALID_INPUT: InvalidInputError,
    LiftStatus.DIVERGED: SolverError,
    LiftStatus.OUT_OF_ORDER: OutOfOrderFrameError,
}


@dataclass(frozen=True, slots=True)
class Failure:
    """Why a row of a batch has no result: its status (never ``SOLVED``) and the reason."""

    status: LiftStatus
    reason: str

    @classmethod
    def of(cls, err: Exception) -> Failure:
        """The failure an error stands for: the package's refusals by their status and message;
        anything else (a bug) ``FAILED``, named by its type."""
        for status, kind in _REFUSALS.items():
            if isinstance(err, kind):
                return cls(status, str(err))
        return cls(LiftStatus.FAILED, f"{type(err).__name__}: {err}")

    def error(self) -> Exception:
        """The error to raise for it: its status's refusal, or ``RuntimeError`` for ``FAILED``,
        with the reason as its message."""
        return _REFUSALS.get(self.status, RuntimeError)(self.reason)


@dataclass(frozen=True)
class Outcome(Generic[R]):
    """How one row of a batch ended, as osqp's ``info.status``: a lifter's row
    (:data:`LiftOutcome`, :meth:`pose_lifter.core.lift.lifter.Lifter.lift_people`) or a track's
    frame (:data:`pose_lifter.core.track.policy.TrackOutcome`).

    Attributes
    ----------
    status : LiftStatus
    reason : str
        Why the row has no result ("" when it has).
    result : LiftResult, TrackedLift or None
        With ``status`` SOLVED, else None.
    """

    status: LiftStatus
    reason: str = ""
    result: R | None = None

    @classmethod
    def solved(cls, result: R) -> Self:
        return cls(LiftStatus.SOLVED, "", result)

    @classmethod
    def failed(cls, failure: Failure) -> Self:
        return cls(failure.status, failure.reason)

    def error(self) -> Exception:
        """The error the row's status stands for (:meth:`Failure.error`)."""
        return Failure(self.status, self.reason).error()

    def unwrap(self) -> R:
        """The result; raises :meth:`error` when there is none."""
        if self.result is None:
            raise self.error()
        return self.result


#: A lifter's row (:meth:`pose_lifter.core.lift.lifter.Lifter.lift_people`).
LiftOutcome: TypeAlias = Outcome[LiftResult]
