"""The settings of an offline lift: everything that decides a lifted bag's content.

:class:`LiftSettings` is what :func:`pose_lifter.offline.lift.lift_bag` and
:func:`~pose_lifter.offline.lift.lift_messages` take, and what a collection's manifest keys its
outputs by (:mod:`pose_lifter.offline.collection`). Its defaults are the node's: the parameters
the offline lift honours (:data:`pose_lifter.messages.settings.OFFLINE_PARAMS`, the one settings table
of the node and of ``pose-lifter lift``'s flags; :meth:`LiftSettings.from_parameters` builds the
settings of their values). This module imports neither the solver nor ROS.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pose_lifter.core.track.defaults import AHEAD_LAG, MAX_LAG
from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S
from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_KEYPOINTS
from pose_lifter.messages.settings import OFFLINE_PARAMS, SPECS, FrameSettings

if TYPE_CHECKING:
    from pose_lifter.core.lift.lifter import Lifter
    from pose_lifter.core.options import LifterOptions

__all__ = ["LiftSettings", "file_sha256", "package_version"]


def package_version() -> str:
    """The installed distribution's version (the source tree's ``__version__`` when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    from pose_lifter import __version__

    try:
        return version("pose_lifter")
    except PackageNotFoundError:
        return __version__


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes (hex), read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def _default_options() -> LifterOptions:
    """The defaults of every lifter option (imported here: the module loads without the solver)."""
    from pose_lifter.core.options import LifterOptions

    return LifterOptions()


@dataclass(frozen=True)
class LiftSettings:
    """Everything that decides a lifted bag's content: the lifter's options and files, the
    per-track policy and the output's shape. Picklable (it is what a Dask worker receives) and
    JSON-able (its digest keys the manifest)."""

    options: LifterOptions = field(default_factory=_default_options)
    bases: str | None = None  #: the node's ``bases_file`` (None: the packaged bases of the mode)
    #: the frame pipeline's: the per-track policy, the placement, the input caps (node parameters)
    frame: FrameSettings = field(default_factory=FrameSettings)
    every: int = 1
    max_messages: int | None = None
    topic: str = TOPIC_KEYPOINTS
    camera_info_topic: str | None = TOPIC_CAMERA_INFO
    keep: list[str] | None = None
    # centred, offline only, with the offline prior (0: the node's causal priors and poses)
    smoothing_s: float = OFFLINE_SMOOTHING_S
    # with smoothing_s 0: the node's answers with output_lag (frames), each refined over the next
    output_lag: int = SPECS["output_lag"].default
    publish_markers: bool = SPECS["publish_markers"].default
    marker_lifetime: float = SPECS["marker_lifetime"].default
    #: the node's REP-155 outputs (/humans/bodies/..., /tf) into the output bag
    publish_hri: bool = SPECS["publish_hri"].default

    def __post_init__(self) -> None:
        if not 0 <= self.output_lag <= MAX_LAG:
            raise ValueError(f"output_lag must be 0 to {MAX_LAG} frames, got {self.output_lag}")
        if self.output_lag and self.smoothing_s > 0:
            raise ValueError("a lag gives the live node's lagged answers, whose lift is causal: use it "
                             "without the offline smoothing (--output-lag N --smoothing 0)")

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any], solver: str = "admm", **rest: Any) -> LiftSettings:
        """The settings of the node parameters ``values`` (names of
        :data:`~pose_lifter.messages.settings.OFFLINE_PARAMS`; the others take their defaults), with
        ``solver`` the camera and pose steps' (``"cvxpy"``: the references, in the paper mode)
        and ``rest`` the other fields (``every``, ``topic``, ``smoothing_s``, ...).

        Raises
        ------
        OptionsError
            The options refuse a value, or a value of a mode's own option with another mode.
        """
        from pose_lifter.core.options import NODE_OPTIONS, LifterOptions

        given = {p.name: values[p.name] for p in OFFLINE_PARAMS if p.name in values}
        options = {name: given[name] for name in NODE_OPTIONS if name in given}
        if solver == "cvxpy":  # the cvxpy references run the paper's mode
            options["mode"] = "paper"
        frame = {name: given[name] for name in _FRAME_FIELDS if name in given}
        own = {name: given[name] for name in _OWN if name in given}
        return cls(options=LifterOptions().replace(camera_solver=solver, pose_solver=solver, **options),
                   bases=given.get("bases_file") or None, frame=FrameSettings(**frame), **own, **rest)

    def to_json(self) -> dict[str, Any]:
        """The settings as JSON-ready values (options sorted by name)."""
        d = dataclasses.asdict(self)
        d["options"] = {k: _jsonable(v) for k, v in sorted(d["options"].items())}
        return d

    def digest(self) -> str:
        """SHA-256 over the settings, the package version and the bytes of the files they name
        (bases, prior files): a changed file or package changes the digest."""
        files = [self.bases, self.options.prior_file, self.options.temporal_prior_file]
        named = {str(f): file_sha256(f) for f in files if f and Path(str(f)).is_file()}
        text = json.dumps({"settings": self.to_json(), "version": package_version(), "files": named},
                          sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def build_lifter(self) -> Lifter:
        """The :class:`pose_lifter.core.Lifter` of these settings, its kernels loaded (warm-up).
        With ``smoothing_s > 0`` the lift reads each track's next frames (``reads_ahead``: its
        temporal prior is the packaged offline one unless ``temporal_prior_file`` names another)."""
        from pose_lifter.core.lift.lifter import Lifter
        from pose_lifter.core.model.bases import PoseBases

        opts = self.options
        bases = PoseBases.load(self.bases) if self.bases else None
        lifter = Lifter(bases, opts, reads_ahead=self.smoothing_s > 0 or self.output_lag >= AHEAD_LAG)
        if opts.camera_solver == "admm" and opts.pose_solver == "admm":
            lifter.warm_up()
        return lifter



#: The node parameters that are fields of :class:`LiftSettings` itself.
_OWN: Final[tuple[str, ...]] = ("output_lag", "publish_markers", "marker_lifetime", "publish_hri")
#: The fields of :class:`FrameSettings` (each a node parameter of that name).
_FRAME_FIELDS: Final[tuple[str, ...]] = tuple(f.name for f in dataclasses.fields(FrameSettings))


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple | list):
        return [_jsonable(x) for x in v]
    if isinstance(v, float | int | str | bool) or v is None:
        return v
    return repr(v)
