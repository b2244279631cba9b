"""The settings of ``pose-lifter lift`` and ``demo`` from their flags and a node params file
(read by :func:`pose_lifter.ros.params.read_params_file`; this module does not import the ROS shell).

A flag typed on the command line wins over the params file, whatever its value: ``args.typed``
holds the options typed (:func:`pose_lifter.cli._typed_options`), so ``--starts 30`` wins even
where 30 is the flag's default.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from pose_lifter.core.track.placement import DEFAULT_DISTANCE_M
from pose_lifter.offline.settings import LiftSettings

if TYPE_CHECKING:
    from pose_lifter.core.options import LifterOptions

__all__ = ["flag_options", "keep_topics", "lift_settings"]


def keep_topics(values: Sequence[str] | None) -> list[str] | None:
    """``--keep``: None / ``all`` = every input topic, ``none`` = none, else the topics named."""
    if values is None or list(values) == ["all"]:
        return None
    if list(values) == ["none"]:
        return []
    return list(values)


def flag_options(args: argparse.Namespace, base: dict[str, Any] | None = None,
                 typed: frozenset[str] | None = None) -> LifterOptions:
    """The lifter options of the ``--variant``, ``--solver``, ``--starts`` and ``--mode`` flags
    over the defaults; with ``base`` (a params file's options) over those, where only the flags
    named in ``typed`` (typed on the command line) win, and ``--solver`` always."""
    from pose_lifter.core.options import LifterOptions

    def wins(flag: str) -> bool:
        return base is None or flag in (typed or frozenset())

    options = dict(base or {})
    if wins("variant"):
        options["variant"] = args.variant
    if wins("starts"):
        options["n_starts"] = args.starts
    if wins("mode") or args.solver == "cvxpy":  # the cvxpy references run the paper's mode
        options["mode"] = "paper" if args.solver == "cvxpy" else args.mode
    options.update(camera_solver=args.solver, pose_solver=args.solver)
    return LifterOptions().replace(**options)


def lift_settings(args: argparse.Namespace, params: Any = None) -> LiftSettings:
    """The :class:`~pose_lifter.offline.settings.LiftSettings` of ``lift``'s flags and ``--params-file``.

    Parameters
    ----------
    args : argparse.Namespace
        ``pose-lifter lift``'s arguments, with ``typed``: the options typed on the command line.
    params : pose_lifter.ros.params.OfflineParams, optional
        The ``--params-file`` read: it gives the node's options; a flag typed on the command line
        wins over it, whatever its value.
    """
    keep = keep_topics(args.keep)
    common: dict[str, Any] = dict(every=args.every, max_messages=args.max_messages, topic=args.topic,
                                  camera_info_topic=args.camera_info_topic or None, keep=keep,
                                  smoothing_s=args.smoothing, output_lag=getattr(args, "lag", 0),
                                  hri=args.hri)
    if params is None:
        return LiftSettings(options=flag_options(args), bases=args.bases, warm_start=not args.no_warm_start,
                            lower_leg_length=args.leg_length, default_distance=DEFAULT_DISTANCE_M, **common)
    typed: frozenset[str] = getattr(args, "typed", frozenset())
    full = flag_options(args, dict(params.options), typed)
    path = args.bases or params.bases_file
    warm = False if args.no_warm_start else (True if params.warm_start is None else params.warm_start)
    leg = params.lower_leg_length
    if leg is None or "leg_length" in typed:
        leg = args.leg_length
    distance = DEFAULT_DISTANCE_M if params.default_distance is None else params.default_distance
    if params.ignored:
        print(f"pose-lifter lift: {args.params_file}: ignored offline: {', '.join(params.ignored)}",
              file=sys.stderr)
    defaults = LiftSettings()
    timeout = defaults.track_timeout if params.track_timeout is None else params.track_timeout
    reinit = defaults.reinit_ratio if params.reinit_ratio is None else params.reinit_ratio
    return LiftSettings(options=full, bases=str(path) if path else None, warm_start=warm,
                        lower_leg_length=leg, default_distance=distance, track_timeout=timeout,
                        reinit_ratio=reinit, **common)
