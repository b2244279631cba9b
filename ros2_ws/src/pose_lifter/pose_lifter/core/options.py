"""Solver options and the paper's method variants, validated in one place.

The ROS node validates live parameter changes through :meth:`LifterOptions.replace`, so the
core and the node accept exactly the same values.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Final, Literal

from .errors import OptionsError

__all__ = ["VARIANTS", "LifterOptions", "Variant", "get_variant"]


@dataclass(frozen=True)
class Variant:
    """One of the paper's ablations (Sec. 4.3.1).

    Attributes
    ----------
    name : str
        e.g. ``"L1WAWS"``: L1/L2 loss, With/No Anthropomorphic (limb) constraints,
        With/No Sparsity.
    loss : {"l1", "l2"}
    limbs : bool
    sparsity : bool
    """

    name: str
    loss: Literal["l1", "l2"]
    limbs: bool
    sparsity: bool


def _variant(name: str) -> Variant:
    loss: Literal["l1", "l2"] = "l1" if name[:2] == "L1" else "l2"
    return Variant(name, loss, name[2:4] == "WA", name[4:6] == "WS")


#: The full method is L1WAWS; the other seven are the paper's baselines.
VARIANTS: Final[dict[str, Variant]] = {
    n: _variant(n)
    for n in ("L1WAWS", "L1WANS", "L1NAWS", "L1NANS", "L2WAWS", "L2WANS", "L2NAWS", "L2NANS")
}


def get_variant(name: str) -> Variant:
    """Variant by name (case-insensitive); ``"full"`` is L1WAWS."""
    key = str(name).strip().upper()
    if key == "FULL":
        key = "L1WAWS"
    if key not in VARIANTS:
        raise OptionsError(f"unknown variant {name!r}; expected 'full' or one of {sorted(VARIANTS)}")
    return VARIANTS[key]


@dataclass(frozen=True)
class LifterOptions:
    """Everything that tunes a solve. Units: 2D input is normalised (see ``Lifter``) so the
    loss and ``theta`` are in right-lower-leg units whatever the image size.

    Attributes
    ----------
    variant : str
        Paper variant (``"full"`` = L1WAWS).
    theta : float
        Weight of ``||alpha||_1`` (paper's theta), > 0 when the variant uses sparsity.
    max_alternations : int
        Camera/pose alternations (paper: 20).
    alternation_tol : float
        Stop when the relative objective decrease of one alternation is below this.
    pose_max_iter, pose_tol : int, float
        Outer ADM of the pose step: iteration cap and relative residual tolerance. The
        nonconvex (limb) pose step rarely meets the tolerance, so the cap sets the quality:
        measured on 190 recorded warm lifts of 5 committed bags with the Riemannian alpha-step,
        caps 20 / 30 / 40 give mean objectives 0.7696 / 0.6916 / 0.6654, and the pose step's
        median ratio to the best local reference (6 L1WAWS problems, 30 PCA bases) is about 1.05
        at 30 and 1.02 at 40 (with either Newton-type alpha-solver).
    inner_max_iter, inner_tol : int, float
        Inner (Q, P) ADM of the alpha-step.
    camera_max_iter, camera_tol : int, float
        ADM of the camera step.
    eta, delta, tau : float
        Penalties of the pose ADM (initial), inner ADM and camera ADM (constant: see the
        pitfalls note).
    eta_growth : float
        Per-iteration growth of the pose ADM penalty (the paper's ``eta_k``), >= 1. (1.2 gets
        the nonconvex pose step as far in 20 iterations as 1.1 in 30, but stops the convex
        variants' pose step ~2 % above their optimum: not used.)
    n_starts : int
        Cold-start multi-start count (paper: 30 k-means centres; 1 = mean pose only).
    warm_flip : bool
        With a warm start, also start from the depth-mirrored warm solution (the
        weak-perspective ambiguity: same 2D, reflected depth) and keep the lower objective.
    warm_flip_screen : bool
        Run the mirrored start for one alternation and continue it only when it already beats
        the warm run's objective (False: always to convergence). Measured on the 7 committed
        bags x 30 tracked frames: mean objective 0.7681 -> 0.7703, P-MPJPE 87.9 -> 85.1 mm,
        warm frame 24.6 -> 16.5 ms CPU.
    n_refine : int
        Cold starts are screened by one alternation; the ``n_refine`` lowest-objective ones
        are continued to convergence (``n_refine >= n_starts`` runs every start fully).
    screen_pose_max_iter : int
        Pose-ADM iteration cap of the screening alternation (when ``n_starts > n_refine``).
        Measured on 78 unseen CMU images, 30 starts (Newton alpha-step): cap 20 mean objective
        0.6305, P-MPJPE 68.5 mm, 174 ms; cap 5: 0.6064, 62.6 mm, 93 ms; cap 3: 0.6088,
        61.5 mm, 82 ms (a short first pose step keeps more starts in play).
    confidence_threshold : float
        A joint with confidence below this is treated as missing (weight 0).
    min_visible_joints : int
        Fewer visible joints than this raises ``TooFewJointsError``.
    limb_proportions : {"anthropometric", "bases"}
        Limb-length targets: the anthropometric table, or the training data's mean.
    alpha_step : {"reduced", "full"}
        Lift the alpha-step in the 36-dim pose space (exactly equivalent, fast) or in the
        paper's (k+1)-dim coefficient space.
    alpha_solver : {"riemannian", "newton", "admm"}
        Solver of the alpha-step (the limb-constrained least squares inside the pose ADM):
        ``"riemannian"`` (default) Riemannian Newton on the product of the 8 limb spheres, one
        step per pose-ADM iteration (``alpha.sphere_newton.RIEMANNIAN_MAX_ITER``), with the proximal term
        ``alpha_prox``; ``"newton"`` an SQP on the same problem
        in the reduced coordinates; ``"admm"`` the paper's rank-1 lifted inner ADM.
        ``"riemannian"`` needs the limb map of the bases to be onto (>= 24 independent basis
        directions) and falls back to ``"newton"`` otherwise.
    alpha_prox : float
        Weight ``p`` of the proximal term ``p ||s - s_k||^2`` (``s = V^T alpha``, ``s_k`` the
        previous ADM iterate) the ``"riemannian"`` alpha-step adds (proximal ADM; 0 = none).
        Measured on 190 recorded warm lifts (alpha-step run to convergence, pose_max_iter 20):
        0 -> 1 lowers the mean objective 0.8178 -> 0.7679 at the same speed; 3 gives 0.7720. With
        today's defaults 1 / 2 / 3 / 5 give 0.665 / 0.671 / 0.674 / 0.678.
    camera_solver, pose_solver : {"admm", "cvxpy"}
        Closed-form ADM path, or the cvxpy reference for the convex subproblems.
    warm_duals : bool
        Carry the ADM multipliers of the camera and pose steps from one alternation to the
        next (warm start of the dual as well as the primal variables); False restarts them
        at zero in every step.
    newton_tol : float
        Relative KKT tolerance of each Newton alpha-step inside the pose ADM.
    mode : {"hybrid", "paper", "learned"}
        ``"paper"``: the paper's method alone (multi-start, the fields above). ``"learned"``: the
        learned 2D -> 3D prior alone (:mod:`pose_lifter.core.prior`; no limb constraints, no fit).
        ``"hybrid"`` (default): the paper's robust fit started from the prior's pose with the prior
        kept in its objective as an L1 term, joints the fit finds to disagree with the image
        masked and the prior re-run without them (:class:`pose_lifter.core.lifter.Lifter`).
    prior_file : str
        Weights of the learned prior (``""``: the packaged ``data/prior_mlp.npz``).
    temporal_prior : bool
        Hybrid and learned, tracked: frames that follow a track's previous ones (evenly spaced,
        :class:`pose_lifter.core.tracking.TrackPolicy`) use the causal temporal prior (the last 4
        frames in, no look-ahead, trained at 30 Hz) instead of the single-frame one; cold frames
        and single images use ``prior_file``. Measured on 18 held-out training-split tracks
        (hybrid, tracked): clean 54.6 -> 51.1 mm, noise 0.1 69.9 -> 65.1, 20 % outliers
        71.8 -> 68.0, 15 % missing 65.8 -> 61.1.
    temporal_prior_file : str
        Weights of the temporal prior (``""``: the packaged ``data/prior_mlp_w4.npz``).
    prior_weight_xy, prior_weight_z : float
        Weights of the prior term's image-position and depth rows (relative to a 2D joint of
        confidence 1; each joint's row is further weighted by the prior's inverse per-joint
        error). 0 removes those rows.
    outlier_threshold : float
        Hybrid: a visible joint whose distance from the fit's projection or from the prior's
        image position exceeds this (in the normalised units, about right-lower-leg lengths) and
        ``hybrid.OUTLIER_MEDIAN_FACTOR`` times the frame's median distance is treated as a
        confident outlier: its 2D is dropped, the prior re-run without it, and the fit both
        continued and restarted from the prior's new pose (the lower objective kept). 0 disables
        the outlier pass. Frames the per-track gate screened use ``outlier_threshold_gated``.
    outlier_threshold_gated : float
        Hybrid: ``outlier_threshold`` on the frames the per-track outlier gate
        (``outlier_gate``) has screened. The gate has dropped the joints that jumped, so the pass
        only needs to catch what is left: on 36 held-out training-split tracks 1.0 measured better
        than 0.6 in every condition (20 % outliers 69.5 -> 69.0 mm, clean 53.0 -> 52.8) and it fires
        on 4 % of the frames of a noisy 36-person bag instead of 22 % (each firing re-runs the
        prior and two fits); single images (no gate) keep 0.6: 1.0 there measured 83.9 -> 95.6 mm
        with 20 % outliers on the evaluation split.
    outlier_passes : int
        Hybrid: outlier passes at most (each on the previous pass's fit and prior; stops when a
        pass flags nothing).
    prior_limbs : bool
        Hybrid, tracked: the 8 limb constraints take the person's proportions (the track's
        estimate, :class:`pose_lifter.core.tracking.TrackPolicy`: the calibrated median of the
        prior's limbs) instead of the bases' mean proportions, at the bases' overall size. With
        the hybrid bases (learned with varied limbs) it measured, on the evaluation split,
        proportions 56.4 -> 53.7 mm and clean 49.2 -> 49.6. (Per frame, the prior's own limb
        lengths were measured too noisy: 4 held-out training trials with 20 % outliers,
        110 -> 123 mm.)
    temporal_weight : float
        Hybrid, tracked (:class:`pose_lifter.core.tracking.TrackPolicy`): the largest weight ``w``
        of the previous frame's pose ``Y`` in the prior term's target ``(P + w Y) / (1 + w)``
        (causal temporal smoothing), reached with heavy 2D noise; the policy scales it with the
        track's estimated noise (none on clean input: smoothing is then only lag). With the
        temporal prior (which already sees the track's last frames) 0.3 measured best on 36
        held-out training-split tracks: noise 0.05 / 0.2 55.7 / 74.4 mm against 58.1 / 74.8 at 1.0
        and 55.4 / 76.6 at 0.
    missing_temporal_weight : float
        Hybrid, tracked: the weight of the previous frame's pose in the prior term's target for a
        joint missing on this frame (low confidence, non-finite or gated): the track carries it
        over rather than leave it to the prior alone. 0: as the other joints. With
        ``fill_missing_frames`` (the prior then sees the joint where the track predicts it) 1.0
        measured best on 36 held-out training-split tracks: 20 % outliers / 15 % missing
        58.8 / 54.3 mm against 59.2 / 54.6 at 3.0 and 59.2 / 54.2 at 0.
    outlier_gate : float
        Hybrid, tracked (:class:`pose_lifter.core.tracking.TrackPolicy`): a visible joint farther
        than this many leg lengths from where the track's last frame had it (moved by the visible
        joints' median motion) is treated as missing on that frame, before the prior sees it.
        0 disables the gate.
    fill_missing_frames : int
        Hybrid, tracked: a joint missing on this frame (low confidence, non-finite or gated) and
        unused on fewer than this many frames before it is given to the learned prior at the
        track's prediction of it (where the last frame had it, moved by the visible joints'
        median motion); the 2D fit still ignores it. 0: the prior sees it as missing. Measured
        on 36 held-out training-split tracks (0 -> 3): 20 % outliers 62.3 -> 59.2 mm, 15 %
        missing 56.5 -> 54.6, noise 0.1 59.1 -> 59.1, clean 49.0 -> 49.7 (one dance track whose
        fit was already lost, 150-250 mm, where the gate fires on fast real motion and the fill
        holds the stale position; since guarded: no fill while the track's fit is being lost,
        ``tracking.FILL_MAX_OBJECTIVE_RATIO``). 1 / 2 / 5: outliers 60.2 / 59.5 / 58.6.
    hybrid_alternations : int
        Hybrid: alternations of each run at most (``max_alternations`` is the paper's). The
        prior's start is close to the answer; measured on 6 held-out training-split tracks
        (clean, tracked): 10 / 5 / 3 / 2 alternations give 49.1 / 50.1 / 51.4 / 50.3 mm, with
        noise 0.1 66.8 / 66.4 / 66.2 / 66.7 mm.
    hybrid_pose_max_iter : int
        Hybrid: the pose step's ADM iterations at most in each alternation (``pose_max_iter`` is
        the paper's). Stopping early keeps the fit near the prior's start (a regulariser):
        measured on 36 held-out training-split tracks (clean / noise 0.1 / 20 % outliers / 15 %
        missing), 40 / 20 / 14 / 10 iterations give 49.8 / 59.0 / 58.8 / 54.3, 48.1 / 58.9 /
        57.9 / 53.2, 48.5 / 58.8 / 57.7 / 53.5 and 48.6 / 58.7 / 57.6 / 53.7 mm, at 2.16 / 1.76
        / 1.71 / 1.56 ms a frame (a loaded machine).
    hybrid_flip_warm : bool
        Hybrid: also score the depth-mirrored hypothesis on warm-started frames (it is always
        scored on cold solves, with ``warm_flip``). Off: the prior re-initialises the depth on
        every frame and the mirrored run won none of 180 warm frames of 6 held-out
        training-split tracks, at ~1 ms a frame (bench tracks: warm median 3.2 -> 2.2 ms).
    warm_competes : bool
        Hybrid with a warm start: the solve always starts from the prior's pose (with the
        previous frame's camera); with this, the previous frame's pose also starts a run
        (screened by one alternation, continued when it already beats the prior's). Off: measured
        on 6 held-out training-split tracks (clean, 180 frames) it won most frames on objective
        and lost on error (55-64 mm tracked against 49 mm with the prior's start alone).
    """

    variant: str = "full"
    theta: float = 0.1
    max_alternations: int = 10
    alternation_tol: float = 1e-3
    pose_max_iter: int = 40
    pose_tol: float = 1e-3
    inner_max_iter: int = 60
    inner_tol: float = 1e-6
    camera_max_iter: int = 100
    camera_tol: float = 1e-4
    eta: float = 0.3
    eta_growth: float = 1.1
    delta: float = 1.0
    tau: float = 10.0
    n_starts: int = 30
    n_refine: int = 3
    screen_pose_max_iter: int = 5
    warm_flip: bool = True
    warm_flip_screen: bool = True
    confidence_threshold: float = 0.1
    min_visible_joints: int = 6
    limb_proportions: str = "bases"
    alpha_step: str = "reduced"
    alpha_solver: str = "riemannian"
    alpha_prox: float = 1.0
    camera_solver: str = "admm"
    pose_solver: str = "admm"
    warm_duals: bool = False
    newton_tol: float = 1e-9
    mode: str = "hybrid"
    prior_file: str = ""
    temporal_prior: bool = True
    temporal_prior_file: str = ""
    prior_weight_xy: float = 0.6
    prior_weight_z: float = 0.6
    outlier_threshold: float = 0.6
    outlier_threshold_gated: float = 1.0
    outlier_passes: int = 2
    prior_limbs: bool = True
    temporal_weight: float = 0.3
    outlier_gate: float = 1.0
    missing_temporal_weight: float = 1.0
    fill_missing_frames: int = 3
    warm_competes: bool = False
    hybrid_alternations: int = 2
    hybrid_pose_max_iter: int = 20
    hybrid_flip_warm: bool = False

    def __post_init__(self) -> None:
        self.validate()

    @property
    def method(self) -> Variant:
        """The :class:`Variant` named by ``variant``."""
        return get_variant(self.variant)

    def validate(self) -> None:
        """Raise :class:`OptionsError` on any value out of range."""
        get_variant(self.variant)
        _positive_int = ("max_alternations", "pose_max_iter", "inner_max_iter", "camera_max_iter",
                         "n_starts", "n_refine", "screen_pose_max_iter", "outlier_passes",
                         "hybrid_alternations", "hybrid_pose_max_iter")
        if not isinstance(self.hybrid_flip_warm, bool):
            raise OptionsError(f"hybrid_flip_warm must be a bool, got {self.hybrid_flip_warm!r}")
        for name in _positive_int:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 100_000:
                raise OptionsError(f"{name} must be an integer in [1, 100000], got {v!r}")
        for name in ("theta",):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not 0.0 <= float(v) <= 1e6:
                raise OptionsError(f"{name} must be in [0, 1e6], got {v!r}")
        for name in ("alternation_tol", "pose_tol", "inner_tol", "camera_tol", "newton_tol"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not 0.0 < float(v) < 1.0:
                raise OptionsError(f"{name} must be in (0, 1), got {v!r}")
        for name in ("eta", "delta", "tau"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not 1e-6 <= float(v) <= 1e6:
                raise OptionsError(f"{name} must be in [1e-6, 1e6], got {v!r}")
        for name in ("prior_weight_xy", "prior_weight_z", "outlier_threshold", "outlier_threshold_gated",
                     "temporal_weight",
                     "outlier_gate", "missing_temporal_weight"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= float(v) <= 1e3:
                raise OptionsError(f"{name} must be in [0, 1000], got {v!r}")
        for name in ("prior_file", "temporal_prior_file"):
            v = getattr(self, name)
            if not isinstance(v, str) or len(v) > 4096:
                raise OptionsError(f"{name} must be a path string (at most 4096 characters)")
        for name in ("warm_flip", "warm_flip_screen", "warm_competes", "prior_limbs", "temporal_prior"):
            if not isinstance(getattr(self, name), bool):
                raise OptionsError(f"{name} must be a bool, got {getattr(self, name)!r}")
        if not isinstance(self.eta_growth, (int, float)) or not 1.0 <= float(self.eta_growth) <= 2.0:
            raise OptionsError(f"eta_growth must be in [1, 2], got {self.eta_growth!r}")
        if not isinstance(self.alpha_prox, (int, float)) or not 0.0 <= float(self.alpha_prox) <= 1e3:
            raise OptionsError(f"alpha_prox must be in [0, 1000], got {self.alpha_prox!r}")
        if not 0.0 <= float(self.confidence_threshold) <= 1.0:
            raise OptionsError(
                f"confidence_threshold must be in [0, 1], got {self.confidence_threshold!r}"
            )
        if not isinstance(self.min_visible_joints, int) or not 3 <= self.min_visible_joints <= 12:
            raise OptionsError(
                f"min_visible_joints must be an integer in [3, 12], got {self.min_visible_joints!r}"
            )
        v = self.fill_missing_frames
        if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 1000:
            raise OptionsError(f"fill_missing_frames must be an integer in [0, 1000], got {v!r}")
        if not isinstance(self.warm_duals, bool):
            raise OptionsError(f"warm_duals must be a bool, got {self.warm_duals!r}")
        choices: dict[str, tuple[str, ...]] = {
            "limb_proportions": ("anthropometric", "bases"),
            "alpha_step": ("reduced", "full"),
            "alpha_solver": ("admm", "newton", "riemannian"),
            "camera_solver": ("admm", "cvxpy"),
            "pose_solver": ("admm", "cvxpy"),
            "mode": ("hybrid", "paper", "learned"),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise OptionsError(f"{name} must be one of {allowed}, got {getattr(self, name)!r}")

    def replace(self, **changes: Any) -> LifterOptions:
        """A validated copy with some fields changed (unknown names raise ``OptionsError``)."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise OptionsError(f"unknown option(s): {unknown}")
        try:
            return dataclasses.replace(self, **changes)
        except TypeError as exc:
            raise OptionsError(str(exc)) from exc
