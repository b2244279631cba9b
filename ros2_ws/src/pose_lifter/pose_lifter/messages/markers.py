"""Which skeleton markers are on screen, and the ``MarkerArray`` that updates them: one book for
the node and the offline lift, so a lifted bag shows what the node showed.

Per frame: the markers of the skeletons lifted (joints and bones per track,
:func:`pose_lifter.messages.cdr.marker_array_cdr`), DELETE markers for the tracks and the
untracked positions that were shown and are gone, and, in the first ``MarkerArray``, DELETEALL
markers for what an earlier run left on screen (markers with lifetime 0 outlive the node).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pose_lifter.messages import cdr

__all__ = ["MarkerBook"]


class MarkerBook:
    """The markers on screen, from one ``MarkerArray`` to the next.

    Parameters
    ----------
    ns : str
        Marker namespace prefix (``{ns}/joints``, ``{ns}/bones``).
    """

    def __init__(self, ns: str) -> None:
        self.ns = ns
        self._tracks: set[int] = set()  # track ids with markers on screen
        self._untracked = 0  # untracked skeletons with markers on screen
        self._cleared = False  # the first MarkerArray starts with DELETEALL

    def update(self, header: Any, track_ids: Sequence[int], joints_m: NDArray[np.float64],
               lifetime: float) -> bytes:
        """The serialised ``MarkerArray`` showing the skeletons (``track_ids``, their joints
        (n, 12, 3) in metres) and deleting what is no longer shown; the book then records them
        as on screen. ``header``: ``stamp.sec``, ``stamp.nanosec``, ``frame_id``."""
        tracked = {t for t in track_ids if t >= 0}
        untracked = sum(1 for t in track_ids if t < 0)
        data = cdr.marker_array_cdr(header, track_ids, joints_m, self.ns, lifetime,
                                    deleted_track_ids=sorted(self._tracks - tracked), clear=not self._cleared,
                                    deleted_untracked=range(untracked, self._untracked))
        self._cleared = True
        self._tracks = tracked
        self._untracked = untracked
        return data
