"""The lifter: alternation of camera and pose steps, multi-start and warm start."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .bases import PoseBases
from .options import LifterOptions
from .types import LiftResult, WarmStart

__all__ = ["Lifter"]


class Lifter:
    """Lift 2D keypoints (12 model joints) to a 3D pose and a weak-perspective camera.

    Parameters
    ----------
    bases : PoseBases or None
        None loads the packaged default basis file.
    options : LifterOptions or None
    """

    def __init__(self, bases: PoseBases | None = None, options: LifterOptions | None = None) -> None:
        self.bases = bases if bases is not None else PoseBases.load()
        self.options = options if options is not None else LifterOptions()

    def lift(
        self,
        points_2d: NDArray[np.float64],
        confidence: NDArray[np.float64] | None = None,
        warm: WarmStart | None = None,
    ) -> LiftResult:
        """Lift one skeleton.

        Parameters
        ----------
        points_2d : ndarray, shape (12, 2)
            Image coordinates of the 12 model joints (any consistent unit, e.g. pixels;
            image y may point down).
        confidence : ndarray, shape (12,), optional
        warm : WarmStart, optional
            Previous solution of the same person: a single start from it replaces the
            multi-start.
        """
        raise NotImplementedError

    def lift_many(
        self,
        points_2d: NDArray[np.float64],
        confidence: NDArray[np.float64] | None = None,
        warm_start: bool = True,
    ) -> Sequence[LiftResult]:
        """Lift a sequence of one person's frames, shape (T, 12, 2), in order."""
        raise NotImplementedError
