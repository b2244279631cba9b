"""The settings of ``pose-lifter lift`` and ``demo`` from their flags and a node params file
(read by :func:`pose_lifter.ros.params.read_params_file`; this module does not import the ROS shell).

The flags of the node's parameters are generated from the settings table
(:data:`pose_lifter.ros.params.OFFLINE_PARAMS`, :func:`pose_lifter.cli._add_parameter_flags`):
each flag's ``dest`` is the parameter's name. A flag typed on the command line wins over the
params file, whatever its value: ``args.typed`` holds the options typed
(:func:`pose_lifter.cli._typed_options`), so ``--n-starts 30`` wins even where 30 is the
flag's default.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from typing import Any

from pose_lifter.offline.settings import LiftSettings
from pose_lifter.ros.params import OFFLINE_PARAMS

__all__ = ["keep_topics", "lift_settings", "parameter_values"]


def keep_topics(values: Sequence[str] | None) -> list[str] | None:
    """``--keep``: None / ``all`` = every input topic, ``none`` = none, else the topics named."""
    if values is None or list(values) == ["all"]:
        return None
    if list(values) == ["none"]:
        return []
    return list(values)


def parameter_values(args: argparse.Namespace, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The node parameters of a lift: each flag's value (the table's default when not typed),
    the params file's ``params`` over the defaults, and a flag typed on the command line
    (``args.typed``) over the file."""
    typed: frozenset[str] = getattr(args, "typed", frozenset())
    values = {}
    for p in OFFLINE_PARAMS:
        from_file = params is not None and p.name in params and p.name not in typed
        values[p.name] = params[p.name] if from_file and params is not None else getattr(args, p.name)
    return values


def lift_settings(args: argparse.Namespace, params: Mapping[str, Any] | None = None) -> LiftSettings:
    """The :class:`~pose_lifter.offline.settings.LiftSettings` of ``lift``'s (or ``demo``'s) flags
    and ``--params-file``.

    Parameters
    ----------
    args : argparse.Namespace
        The command's arguments, with ``typed``: the options typed on the command line.
    params : mapping, optional
        The ``--params-file`` read (:func:`pose_lifter.ros.params.read_params_file`): it gives the
        node's parameters; a flag typed on the command line wins over it, whatever its value.

    Raises
    ------
    OptionsError
        A value the options refuse (e.g. an option of the paper mode with another mode).
    """
    rest: dict[str, Any] = dict(every=args.every, smoothing_s=args.smoothing)
    if hasattr(args, "topic"):  # lift's, not demo's
        rest.update(max_messages=args.max_messages, topic=args.topic,
                    camera_info_topic=args.camera_info_topic or None, keep=keep_topics(args.keep))
    return LiftSettings.from_parameters(parameter_values(args, params), args.solver, **rest)
