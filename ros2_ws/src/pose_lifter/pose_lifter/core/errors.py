"""Typed errors of pose_lifter: one tree under :class:`PoseLifterError`.

Every input the solvers cannot use raises one of these, never a NaN result::

    PoseLifterError
        InvalidInputError (ValueError)    bad input arrays
            TooFewJointsError             too few visible joints for a solve
        UnknownLayoutError (KeyError)     a keypoint layout name
        OptionsError (ValueError)         a solver option out of range or of the wrong type
        BasisFileError (OSError)          a basis file
        PriorFileError (OSError)          a learned-prior weights file
        SolverError (RuntimeError)        a solve diverged (non-finite result) on valid input
        OutOfOrderFrameError              a tracked frame older than its track's last one

Other modules add their own leaves (``mocap.formats.MocapDataError``, ``reference.ReferenceSolverError``
under :class:`SolverError`, ``adapter_node.AdapterError``,
``offline.bags.BagError`` and its ``BagReadError``, ``messages.typestore.TypestoreError``),
so ``except PoseLifterError`` catches every error the package raises on purpose.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Literal

import numpy as np

__all__ = [
    "BasisFileError",
    "InvalidInputError",
    "OptionsError",
    "OutOfOrderFrameError",
    "PoseLifterError",
    "PriorFileError",
    "SolverError",
    "TooFewJointsError",
    "UnknownLayoutError",
    "diverged_as_solver_error",
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


class SolverError(PoseLifterError, RuntimeError):
    """A solve diverged (non-finite iterates or result) although its input passed the checks."""


class OutOfOrderFrameError(PoseLifterError):
    """A tracked frame is older than the track's last frame (within ``track_timeout``)."""


class _DivergedAsSolverError:
    """The context of :func:`diverged_as_solver_error` (a class: entered around every run, where
    a generator-based context manager costs several times more)."""

    __slots__ = ("step",)

    def __init__(self, step: str) -> None:
        self.step = step

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: object
                 ) -> Literal[False]:
        if kind is not None and issubclass(kind, np.linalg.LinAlgError):
            raise SolverError(f"{self.step} diverged ({exc})") from exc
        return False


def diverged_as_solver_error(step: str) -> AbstractContextManager[None]:
    """Re-raise numpy's ``LinAlgError`` (a kernel met an infinite or NaN matrix: the iterates
    diverged) as :class:`SolverError` naming ``step``."""
    return _DivergedAsSolverError(step)
