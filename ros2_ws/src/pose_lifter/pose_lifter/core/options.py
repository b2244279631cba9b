"""Solver options and the paper's method variants: one table, validated in one place.

The options come in two parts. :class:`UserOptions` is what a user sets: each of its fields is a
parameter of the ROS node (same name, default and range). It is made of five parts, each a
validated options class with its own doc: :class:`FitOptions` (the paper's method),
:class:`PaperOptions` (what only the paper mode reads), :class:`PriorOptions` (the learned
prior), :class:`TrackOptions` (a track) and :class:`OutputOptions` (the published pose);
:data:`OPTION_PARTS` lists their fields.
:class:`ExperimentOptions` is what an experiment sets: the solver's internal penalties and
tolerances and the reference solvers, for experiments, tests and benchmarks, not node
parameters. :class:`LifterOptions` is both, the one object the solver reads.

Every field carries its metadata (:class:`OptionMeta`: a one-line doc, its range or choices). From
that one table come :meth:`LifterOptions.validate`, the node's parameter descriptors and
``config/lifter.yaml`` (:mod:`pose_lifter.ros.params`), so a range cannot differ between the core
and the node. The node also validates every live parameter change through
:meth:`LifterOptions.replace`.

An option that only some modes read says so in its metadata (:attr:`OptionMeta.modes`,
:data:`MODE_OPTIONS`); set to anything but its default while another mode runs, it is refused
(:meth:`LifterOptions.validate`), so every option a user sets is read. Why the defaults are
what they are: ``docs/tuning.md``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Final, Literal, get_args

from .errors import OptionsError

__all__ = [
    "EXPERIMENT_OPTIONS",
    "MODE_OPTIONS",
    "NODE_OPTIONS",
    "OPTION_DEFAULTS",
    "OPTION_META",
    "OPTION_PARTS",
    "VARIANTS",
    "ExperimentOptions",
    "FitOptions",
    "LifterOptions",
    "LimbProportions",
    "Mode",
    "OptionMeta",
    "OutputOptions",
    "PaperOptions",
    "PriorOptions",
    "SubproblemSolver",
    "TrackOptions",
    "UserOptions",
    "Variant",
    "check_option",
    "get_variant",
]


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


Mode = Literal["hybrid", "paper", "learned"]
SubproblemSolver = Literal["admm", "cvxpy"]
LimbProportions = Literal["bases", "anthropometric"]

#: Longest accepted path option (characters).
MAX_PATH_LENGTH: Final[int] = 4096


@dataclass(frozen=True)
class OptionMeta:
    """What one option field accepts.

    The kind of value (bool, int, float, str) is the type of the field's default.

    Attributes
    ----------
    doc : str
        One line: what the option does (the node parameter's description).
    low, high : float or None
        The accepted range of a number (None: not a number, or no range).
    open_low, open_high : bool
        The bound itself is refused (e.g. tolerances in ``(0, 1)``).
    choices : tuple of str
        The accepted values of a choice field (``()``: not one).
    max_length : int or None
        Longest accepted string (paths).
    check : callable or None
        Extra check of the value, raising :class:`OptionsError` (``variant``: case-insensitive
        names and ``"full"``).
    modes : tuple of str
        The modes that read the option (``()``: every mode). In another mode any value but the
        default is refused.
    """

    doc: str
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple[str, ...] = ()
    max_length: int | None = None
    check: Callable[[Any], object] | None = None
    modes: tuple[str, ...] = ()

    def range_text(self) -> str:
        """``"[0, 1e+06]"``, ``"(0, 1)"``, ... (``""`` without a range)."""
        if self.low is None or self.high is None:
            return ""
        return (f"{'(' if self.open_low else '['}{self.low:g}, "
                f"{self.high:g}{')' if self.open_high else ']'}")

    def constraint_text(self) -> str:
        """What the range or choices cannot say by themselves (``""`` when nothing): open bounds,
        the choices, a length limit (the node's ``additional_constraints``)."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.open_low or self.open_high:
            return f"in {self.range_text()}: an open bound itself is refused"
        if self.max_length is not None:
            return f"at most {self.max_length} characters"
        return ""

    def accepts(self, value: float) -> bool:
        """Whether a number lies in the range (NaN never does)."""
        v = float(value)
        if self.low is not None and not (v > self.low if self.open_low else v >= self.low):
            return False
        return self.high is None or bool(v < self.high if self.open_high else v <= self.high)


def _meta(doc: str, low: float | None = None, high: float | None = None, *, open_low: bool = False,
          open_high: bool = False, choices: tuple[str, ...] = (), max_length: int | None = None,
          check: Callable[[Any], object] | None = None, modes: tuple[str, ...] = ()
          ) -> dict[str, OptionMeta]:
    """The ``metadata`` of an option field (key ``"option"``)."""
    return {"option": OptionMeta(doc, low, high, open_low, open_high, choices, max_length, check, modes)}


#: The metadata of an option that only the paper mode reads.
_PAPER: Final[tuple[str, ...]] = ("paper",)


_ITER = 100_000  # the cap of every iteration / start count
_WEIGHT = 1e3  # the cap of every weight and threshold in leg lengths


class _Validated:
    """Validation of a frozen dataclass of option fields on construction."""

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`OptionsError` on any value its field's :class:`OptionMeta` refuses, and
        (with a ``mode`` field) on an option that the mode does not read set to anything but its
        default."""
        fields = dataclasses.fields(self)  # type: ignore[arg-type]
        for f in fields:
            _check(f.name, type(f.default), f.metadata["option"], getattr(self, f.name))
        mode = getattr(self, "mode", None)
        if mode is None:
            return
        for f in fields:
            modes = f.metadata["option"].modes
            value = getattr(self, f.name)
            if modes and mode not in modes and value != f.default:
                raise OptionsError(
                    f"{f.name} = {value!r} is read only in {' or '.join(modes)} mode, not in {mode!r} "
                    f"mode: leave it at its default ({f.default!r}) or set mode to {modes[0]!r}")


@dataclass(frozen=True)
class FitOptions(_Validated):
    """The fit: the paper's method (its variant, sparsity, alternations and cold starts), which 2D
    joints it accepts, its limb-length targets and the hybrid mode's confident-outlier passes.
    Units: 2D input is normalised (see ``Lifter``) so the loss, ``theta`` and the outlier
    threshold are in right-lower-leg units whatever the image size."""

    variant: str = field(default="full", metadata=_meta(
        "Paper variant: 'full' (= L1WAWS) or L1WAWS, L1WANS, ..., L2NANS.",
        choices=("full", *VARIANTS), check=lambda v: get_variant(v)))
    theta: float = field(default=0.1, metadata=_meta(
        "Weight of ||alpha||_1 (sparsity), right-lower-leg units.", 0.0, 1e6))
    alternation_tol: float = field(default=1e-3, metadata=_meta(
        "Stop alternating below this relative objective decrease.", 0.0, 1.0, open_low=True,
        open_high=True))
    warm_flip: bool = field(default=True, metadata=_meta(
        "Also try the depth-mirrored pose (the weak-perspective ambiguity): paper mode on a warm "
        "solve (the previous pose mirrored), hybrid mode on a cold frame (the prior's run "
        "mirrored; a warm frame restarts from the prior)."))
    confidence_threshold: float = field(default=0.1, metadata=_meta(
        "Keypoints with lower confidence are treated as missing.", 0.0, 1.0))
    min_visible_joints: int = field(default=6, metadata=_meta(
        "Skip a skeleton with fewer visible model joints.", 3, 12))
    limb_proportions: LimbProportions = field(default="bases", metadata=_meta(
        "Limb-length targets: 'bases' (training mean) or 'anthropometric'.",
        choices=get_args(LimbProportions)))
    outlier_threshold: float = field(default=0.6, metadata=_meta(
        "Hybrid: reprojection residual (leg lengths) above which a visible joint is dropped as a "
        "confident outlier and the prior re-run without it (0 = off).", 0.0, _WEIGHT))
    outlier_passes: int = field(default=2, metadata=_meta(
        "Hybrid: outlier passes at most.", 1, _ITER))
    @property
    def method(self) -> Variant:
        """The :class:`Variant` named by ``variant``."""
        return get_variant(self.variant)


@dataclass(frozen=True)
class PaperOptions(_Validated):
    """What only the paper mode reads: its cold solve's starts and its runs' caps (the hybrid
    mode's runs have their own, ``hybrid_alternations`` and ``hybrid_pose_max_iter``, and start
    from the prior's pose; the learned mode runs none). With another mode, any value but the
    default is refused (:attr:`OptionMeta.modes`)."""

    max_alternations: int = field(default=10, metadata=_meta(
        "Paper mode only: camera/pose alternations per solve (the paper: 20).", 1, _ITER, modes=_PAPER))
    pose_max_iter: int = field(default=40, metadata=_meta(
        "Paper mode only: iteration cap of the pose-step ADM.", 1, _ITER, modes=_PAPER))
    n_starts: int = field(default=30, metadata=_meta(
        "Paper mode only: starts of a cold (multi-start) solve; 1 = mean pose only (the paper: 30).",
        1, _ITER, modes=_PAPER))


@dataclass(frozen=True)
class PriorOptions(_Validated):
    """The learned prior: the mode that decides whether it runs (hybrid, learned) or not (paper),
    its weights, the temporal prior of tracked frames, its weight in the hybrid fit, its limb
    proportions and its test-time flip averaging."""

    mode: Mode = field(default="hybrid", metadata=_meta(
        "'hybrid' (the learned prior inside the paper's robust fit), 'paper' (the paper's method "
        "alone) or 'learned' (the prior alone).", choices=get_args(Mode)))
    prior_file: str = field(default="", metadata=_meta(
        "Learned prior weights (.npz, PosePrior.save); empty = the packaged default.",
        max_length=MAX_PATH_LENGTH))
    temporal_prior: bool = field(default=True, metadata=_meta(
        "Hybrid/learned, tracked: frames that follow a track's previous ones use the causal "
        "temporal prior (last 4 frames, trained at 30 Hz)."))
    temporal_prior_file: str = field(default="", metadata=_meta(
        "Temporal prior weights (.npz); empty = the packaged default. A NAME_crop.npz beside it (a prior "
        "trained on bodies the image cuts) lifts the tracked frames whose 2D lacks a shoulder.",
        max_length=MAX_PATH_LENGTH))
    prior_weight_xy: float = field(default=0.6, metadata=_meta(
        "Hybrid: weight of the prior's image positions in the L1 objective.", 0.0, _WEIGHT))
    prior_weight_z: float = field(default=0.6, metadata=_meta(
        "Hybrid: weight of the prior's depths in the L1 objective.", 0.0, _WEIGHT))
    prior_limbs: bool = field(default=True, metadata=_meta(
        "Hybrid, tracked: limb constraints with the track's estimated proportions."))
    prior_flip: bool = field(default=True, metadata=_meta(
        "Hybrid and learned: the prior's pose is the mean of its answers for the 2D and for the "
        "mirrored 2D (mirrored back): test-time flip averaging."))


@dataclass(frozen=True)
class TrackOptions(_Validated):
    """A track (hybrid mode, tracked people): the temporal outlier gate, how much the previous
    frame's pose holds a joint the frame lacks, the joints a track fills in, and where its limb
    proportions come from."""

    outlier_gate: float = field(default=1.0, metadata=_meta(
        "Hybrid, tracked: a joint farther than this (leg lengths) from where the track puts it is "
        "missing for that frame (0 = off).", 0.0, _WEIGHT))
    missing_temporal_weight: float = field(default=1.0, metadata=_meta(
        "Hybrid, tracked: weight of the previous frame's pose in the prior target of a joint "
        "missing on this frame (0 = as the others).", 0.0, _WEIGHT))
    fill_missing_frames: int = field(default=6, metadata=_meta(
        "Hybrid, tracked: a joint missing for at most this many frames in a row is given to the "
        "learned prior where the track predicts it (0 = off).", 0, 1000))
    image_limbs: bool = field(default=False, metadata=_meta(
        "Hybrid, tracked: the track's limb proportions also from its image limb lengths over the "
        "fit's scale (their upper quantile over frames), with prior_limbs."))


@dataclass(frozen=True)
class OutputOptions(_Validated):
    """The published pose (hybrid mode, tracked people): the causal smoothing of the fit's
    correction, and the measurement update that moves its joints toward the observed 2D. Output
    only: what a track carries into its next frame is the fit's own pose."""

    correction_smoothing: float = field(default=0.7, metadata=_meta(
        "Hybrid, tracked: the published pose is the prior's plus the fit's correction of it, "
        "averaged over frames with this factor (causal, exponential; 0 = the fit as it is).",
        0.0, 0.99))
    measurement_update: bool = field(default=True, metadata=_meta(
        "Hybrid, tracked: the published pose's joints go where the observed 2D puts them (per "
        "joint, weighted by the track's 2D noise; joints the lift did not use or beyond "
        "measurement_gate keep the pose's), and each limb's depth toward its image foreshortening "
        "(measurement_depth), while the track's 2D is nearly exact (core/track/measurement.py MAX_NOISE). "
        "Output only."))
    measurement_depth: float = field(default=0.5, metadata=_meta(
        "Hybrid, tracked, with measurement_update: weight of the depth a limb's image length gives "
        "(its length from the track's image) against the fit's (0 = the fit's).", 0.0, 1.0))
    measurement_gate: float = field(default=0.3, metadata=_meta(
        "Hybrid, tracked, with measurement_update: a used joint farther than this (leg lengths) "
        "from the smoothed pose is not moved to its 2D on that frame.", 0.0, _WEIGHT))


#: One part of :class:`UserOptions`.
_Part = FitOptions | PaperOptions | PriorOptions | TrackOptions | OutputOptions


@dataclass(frozen=True)
class UserOptions(OutputOptions, TrackOptions, PriorOptions, PaperOptions, FitOptions):
    """What a user sets: the fields of its five parts (:data:`OPTION_PARTS`), in the order the fit
    (:class:`FitOptions`), the paper mode's own (:class:`PaperOptions`), the learned prior
    (:class:`PriorOptions`), a track (:class:`TrackOptions`) and the published pose
    (:class:`OutputOptions`). Each part is a
    validated options class of its own; each field is a parameter of the ROS node (same name,
    default and range, :data:`NODE_OPTIONS`). Each field's doc, range or choices are in its
    metadata (:data:`OPTION_META`); why each default is what it is: ``docs/tuning.md``.
    """

    def part(self, name: str) -> _Part:
        """The part ``name`` of :data:`OPTION_PARTS` (``"fit"``, ``"paper"``, ``"prior"``,
        ``"track"``, ``"output"``) as its own options object, with this object's values."""
        cls = _PART_CLASSES[name]
        return cls(**{f.name: getattr(self, f.name) for f in dataclasses.fields(cls)})


@dataclass(frozen=True)
class ExperimentOptions(_Validated):
    """What an experiment sets: the ADM penalties (``eta``, ``eta_growth``, ``delta``, ``tau``),
    the inner tolerances, the cvxpy reference solvers, and the fit's and the hybrid mode's
    internals measured once (tolerances and iteration caps of the steps, the cold starts'
    screening, the alpha-step's proximal weight, the hybrid's runs, the gated outlier threshold,
    a track's left/right label check, a disturbed track's smoothing gain; why each default:
    ``docs/tuning.md``). For experiments,
    tests and benchmarks; not node parameters (:data:`EXPERIMENT_OPTIONS`).
    """

    inner_max_iter: int = field(default=60, metadata=_meta(
        "Iteration cap of the paper's inner alpha-step ADM (bases whose limb map is not onto).", 1,
        _ITER))
    inner_tol: float = field(default=1e-6, metadata=_meta(
        "Tolerance of the paper's inner alpha-step ADM.", 0.0, 1.0, open_low=True,
        open_high=True))
    eta: float = field(default=0.3, metadata=_meta(
        "Initial penalty of the pose ADM.", 1e-6, 1e6))
    eta_growth: float = field(default=1.1, metadata=_meta(
        "Per-iteration growth of the pose ADM penalty (the paper's eta_k).", 1.0, 2.0))
    delta: float = field(default=1.0, metadata=_meta(
        "Penalty of the inner alpha-step ADM.", 1e-6, 1e6))
    tau: float = field(default=10.0, metadata=_meta(
        "Penalty of the camera ADM (constant).", 1e-6, 1e6))
    camera_solver: SubproblemSolver = field(default="admm", metadata=_meta(
        "Camera step: 'admm' (closed-form ADM) or 'cvxpy' (the reference solver).",
        choices=get_args(SubproblemSolver)))
    pose_solver: SubproblemSolver = field(default="admm", metadata=_meta(
        "Pose step: 'admm' (closed-form ADM) or 'cvxpy' (the reference solver).",
        choices=get_args(SubproblemSolver)))
    newton_tol: float = field(default=1e-9, metadata=_meta(
        "Relative tolerance of each Riemannian Newton alpha-step inside the pose ADM.", 0.0, 1.0,
        open_low=True, open_high=True))
    # --- solver internals of the fit and the hybrid mode (their defaults: docs/tuning.md)
    pose_tol: float = field(default=1e-3, metadata=_meta(
        "Relative residual tolerance of the pose-step ADM.", 0.0, 1.0, open_low=True, open_high=True))
    camera_max_iter: int = field(default=100, metadata=_meta(
        "Iteration cap of the camera-step ADM.", 1, _ITER))
    camera_tol: float = field(default=1e-4, metadata=_meta(
        "Tolerance of the camera-step ADM.", 0.0, 1.0, open_low=True, open_high=True))
    n_refine: int = field(default=3, metadata=_meta(
        "Paper mode only: cold starts continued to convergence after one screening alternation "
        "each.", 1, _ITER, modes=_PAPER))
    screen_pose_max_iter: int = field(default=5, metadata=_meta(
        "Pose-ADM iteration cap of the screening alternation of cold starts.", 1, _ITER))
    warm_flip_screen: bool = field(default=True, metadata=_meta(
        "The mirrored start is continued only if one alternation already beats the warm one."))
    alpha_prox: float = field(default=1.0, metadata=_meta(
        "Proximal weight of the alpha-step (Riemannian Newton on the limb spheres; 0 = none).", 0.0,
        _WEIGHT))
    outlier_threshold_gated: float = field(default=1.0, metadata=_meta(
        "Hybrid: outlier_threshold on tracked frames the outlier gate screened.", 0.0, _WEIGHT))
    label_swaps: bool = field(default=True, metadata=_meta(
        "Hybrid, tracked: an arm's or a leg's left and right labels that the track puts far better "
        "swapped are swapped back for that frame, before the outlier gate (core/track/state.py "
        "SWAP_RATIO)."))
    disturbed_smoothing_gain: float = field(default=0.55, metadata=_meta(
        "Hybrid, tracked: gain of the alpha-beta filter on the prior's part of the published "
        "pose when a track is disturbed (joints the lift did not use); 1 = no filter.", 0.05, 1.0))
    hybrid_alternations: int = field(default=2, metadata=_meta(
        "Hybrid: alternations of each run at most.", 1, _ITER))
    hybrid_pose_max_iter: int = field(default=10, metadata=_meta(
        "Hybrid: pose-step ADM iterations at most per alternation.", 1, _ITER))
    hybrid_camera_max_iter: int = field(default=15, metadata=_meta(
        "Hybrid: camera-step ADM iterations at most per alternation.", 1, _ITER))


@dataclass(frozen=True)
class LifterOptions(ExperimentOptions, UserOptions):
    """Everything that tunes a solve: the :class:`UserOptions` fields, then the
    :class:`ExperimentOptions` fields (one flat, frozen, validated object)."""

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


def _check(name: str, kind: type, meta: OptionMeta, v: Any) -> None:
    """Raise :class:`OptionsError` unless ``v`` is a valid value of the option ``name``."""
    if kind is bool:
        ok, what = isinstance(v, bool), "a bool"
    elif kind is int:
        ok = isinstance(v, int) and not isinstance(v, bool) and meta.accepts(v)
        what = f"an integer in {meta.range_text()}"
    elif kind is float:
        ok = isinstance(v, int | float) and not isinstance(v, bool) and meta.accepts(v)
        what = f"a number in {meta.range_text()}"
    elif meta.choices and meta.check is None:
        ok, what = v in meta.choices, f"one of {meta.choices}"
    else:
        ok = isinstance(v, str) and (meta.max_length is None or len(v) <= meta.max_length)
        what = f"a string of at most {meta.max_length} characters" if meta.max_length else "a string"
    if not ok:
        raise OptionsError(f"{name} must be {what}, got {v!r}")
    if meta.check is not None:
        meta.check(v)


def check_option(name: str, value: Any) -> None:
    """Raise :class:`OptionsError` unless ``value`` is a valid value of the option ``name`` by
    itself (its kind and range; whether the mode reads it is :meth:`LifterOptions.validate`'s)."""
    if name not in OPTION_META:
        raise OptionsError(f"unknown option: {name!r}")
    _check(name, type(OPTION_DEFAULTS[name]), OPTION_META[name], value)


#: Each :class:`LifterOptions` field's metadata, in declaration order (the user options first).
OPTION_META: Final[Mapping[str, OptionMeta]] = MappingProxyType(
    {f.name: f.metadata["option"] for f in dataclasses.fields(LifterOptions)})
#: Each :class:`LifterOptions` field's default.
OPTION_DEFAULTS: Final[Mapping[str, Any]] = MappingProxyType(
    {f.name: f.default for f in dataclasses.fields(LifterOptions)})
#: The :class:`UserOptions` fields: the ROS node declares them as parameters (same names, defaults
#: and ranges), in order.
NODE_OPTIONS: Final[tuple[str, ...]] = tuple(f.name for f in dataclasses.fields(UserOptions))
#: The options class of each part of :class:`UserOptions`, in order.
_PART_CLASSES: Final[Mapping[str, type[_Part]]] = MappingProxyType({
    "fit": FitOptions, "paper": PaperOptions, "prior": PriorOptions, "track": TrackOptions,
    "output": OutputOptions})
#: The :class:`UserOptions` fields by part, in order: the fit, the paper mode's own, the learned
#: prior, a track, the published pose (the node's parameter file and docs/node.md list them so).
OPTION_PARTS: Final[Mapping[str, tuple[str, ...]]] = MappingProxyType({
    part: tuple(f.name for f in dataclasses.fields(cls)) for part, cls in _PART_CLASSES.items()})

#: The options that only some modes read (:attr:`OptionMeta.modes`): name -> those modes.
MODE_OPTIONS: Final[Mapping[str, tuple[str, ...]]] = MappingProxyType(
    {name: meta.modes for name, meta in OPTION_META.items() if meta.modes})

#: The :class:`ExperimentOptions` fields, in order.
EXPERIMENT_OPTIONS: Final[tuple[str, ...]] = tuple(f.name for f in dataclasses.fields(ExperimentOptions))
