"""Which skeleton markers are on screen, from one ``MarkerArray`` to the next: one book for the
node and the offline lift, so a lifted bag shows what the node showed.

Per frame the book says what leaves the screen (:class:`MarkerChange`): the tracks and the
untracked positions that were shown and are gone, and, before the first ``MarkerArray``, all
that an earlier run left (markers with lifetime 0 outlive the node).
:func:`pose_lifter.messages.cdr.marker_array_cdr` writes the markers of the skeletons lifted
(joints and bones per track) with those deletions.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

__all__ = ["MarkerBook", "MarkerChange"]


class MarkerChange(NamedTuple):
    """What leaves the screen with a frame's ``MarkerArray`` (the keywords of
    :func:`pose_lifter.messages.cdr.marker_array_cdr`).

    Attributes
    ----------
    deleted_track_ids : list of int
        The tracks shown before and not now (DELETE), ascending.
    clear : bool
        DELETEALL first (the stream's first ``MarkerArray``).
    deleted_untracked : range
        The untracked positions shown before and not now (DELETE).
    """

    deleted_track_ids: list[int]
    clear: bool
    deleted_untracked: range


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

    def update(self, track_ids: Sequence[int]) -> MarkerChange:
        """What leaves the screen when the skeletons ``track_ids`` (untracked: < 0) are shown;
        the book then records them as on screen."""
        tracked = {t for t in track_ids if t >= 0}
        untracked = sum(1 for t in track_ids if t < 0)
        change = MarkerChange(deleted_track_ids=sorted(self._tracks - tracked), clear=not self._cleared,
                              deleted_untracked=range(untracked, self._untracked))
        self._cleared = True
        self._tracks = tracked
        self._untracked = untracked
        return change
