"""The settings of ``pose-lifter lift`` and ``demo`` from their flags and a node params file
(read by :func:`pose_lifter.messages.settings.read_params_file`).

The flags of the node's parameters are generated from the settings table
(:data:`pose_lifter.messages.settings.OFFLINE_PARAMS`, :func:`add_parameter_flags`):
each flag's ``dest`` is the parameter's name. A flag typed on the command line wins over the
params file, whatever its value: ``args.typed`` holds the options typed
(:func:`pose_lifter.cli._typed_options`), so ``--n-starts 30`` wins even where 30 is the
flag's default.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from typing import Any, Final

from pose_lifter.core.errors import OptionsError
from pose_lifter.messages.settings import OFFLINE_PARAMS, ParamSpec
from pose_lifter.offline.settings import LiftSettings

__all__ = ["add_parameter_flags", "keep_topics", "lift_settings", "parameter_values"]


#: What a flag's help adds to its parameter's description offline.
_OFFLINE_NOTES: Final[dict[str, str]] = {
    "output_lag": "offline with --smoothing 0: the node's lagged answers, message for message (one "
                  "process per bag)",
    "mode": "--solver cvxpy implies paper",
}


def _parameter_type(spec: ParamSpec) -> Any:
    """An argparse ``type`` of a number parameter: its kind, checked by its table entry (the node's
    range; :class:`~pose_lifter.core.errors.OptionsError`'s reason as argparse's message)."""
    kind = type(spec.default)

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a{'n integer' if kind is int else ' number'}: {text!r}") \
                from None
        try:
            return spec.checked(value)
        except OptionsError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


def add_parameter_flags(p: argparse.ArgumentParser) -> None:
    """The flags of the node's parameters the offline lift honours, from the settings table
    (:data:`~pose_lifter.messages.settings.OFFLINE_PARAMS`): ``--`` + the name with ``_`` -> ``-``, the
    node's default and range (a bool: ``--name`` / ``--no-name``), ``dest`` the name; and
    ``--solver`` (not a node parameter)."""
    g = p.add_argument_group("the node's parameters (the same names, defaults and ranges; "
                             "docs/node.md, config/lifter.yaml)")
    for spec in OFFLINE_PARAMS:
        text = " ".join(t for t in (spec.description, spec.range_text(), _OFFLINE_NOTES.get(spec.name, ""))
                        if t)
        kind = type(spec.default)
        if kind is bool:
            g.add_argument(spec.flag, dest=spec.name, action=argparse.BooleanOptionalAction,
                           default=spec.default, help=_help(text + " (default: %(default)s)"))
        elif kind is str:
            g.add_argument(spec.flag, dest=spec.name, default=spec.default, choices=spec.choices or None,
                           metavar=(None if spec.choices
                                    else "PATH" if spec.name.endswith("_file") else "TEXT"),
                           help=_help(text + (" (default: %(default)r)" if spec.default else "")))
        else:
            g.add_argument(spec.flag, dest=spec.name, type=_parameter_type(spec), default=spec.default,
                           help=_help(text + " (default: %(default)s)"))
    p.add_argument("--solver", choices=("admm", "cvxpy"), default="admm",
                   help="camera and pose subproblems: closed-form ADMM (fast) or the cvxpy reference "
                   "(which runs the paper mode)")


def _help(text: str) -> str:
    """``text`` as an argparse help string (its own ``%`` escaped, argparse's kept)."""
    return text.replace("%", "%%").replace("%%(default)", "%(default)")


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
        The ``--params-file`` read (:func:`pose_lifter.messages.settings.read_params_file`): it gives the
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
