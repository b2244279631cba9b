"""Typed errors of the pose_lifter core.

Every input the solvers cannot use raises one of these, never a NaN result.
"""

from __future__ import annotations

__all__ = [
    "BasisFileError",
    "InvalidInputError",
    "OptionsError",
    "PoseLifterError",
    "PriorFileError",
    "TooFewJointsError",
    "UnknownLayoutError",
]


class PoseLifterError(Exception):
    """Base class of every error raised by the pose_lifter core."""


class InvalidInputError(PoseLifterError, ValueError):
    """An input array has the wrong shape or non-finite values."""


class TooFewJointsError(InvalidInputError):
    """Fewer joints are visible (confidence above threshold) than a solve needs."""


class UnknownLayoutError(PoseLifterError, KeyError):
    """A keypoint layout name is not one of the supported layouts."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0]) if self.args else "unknown layout"


class BasisFileError(PoseLifterError, OSError):
    """A basis file is missing, unreadable or inconsistent."""


class PriorFileError(PoseLifterError, OSError):
    """A learned-prior weights file is missing, unreadable or inconsistent."""


class OptionsError(PoseLifterError, ValueError):
    """A solver option is out of range or of the wrong type."""
