"""Which skeleton markers the lifter node has on screen, and the ``MarkerArray`` that updates them.

Per frame the node publishes the markers of the skeletons it lifted (their ``Skeleton3D``'s
points, not rebuilt), DELETE markers for the tracks and untracked positions that were shown and
are gone, and, in its first ``MarkerArray``, DELETEALL markers for what an earlier run left on
screen (markers with lifetime 0 outlive the node).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pose_lifter.messages import convert as messages

__all__ = ["MarkerBook"]


class MarkerBook:
    """The markers on screen, from one ``MarkerArray`` to the next.

    Parameters
    ----------
    ns : str
        Marker namespace prefix (``{ns}/joints``, ``{ns}/bones``).
    types : namespace of message factories
    """

    def __init__(self, ns: str, types: Any) -> None:
        self._ns = ns
        self._types = types
        self._tracks: set[int] = set()  # track ids with markers on screen
        self._untracked = 0  # untracked skeletons with markers on screen
        self._cleared = False  # the first MarkerArray starts with DELETEALL

    def update(self, header: Any, shown: Sequence[tuple[int, Sequence[Any]]], lifetime: float) -> Any:
        """The ``MarkerArray`` showing ``shown`` ((track_id, its 12 Points) per skeleton) and
        deleting what is no longer shown; the book then records ``shown`` as on screen."""
        t = self._types
        tracked = {tid for tid, _ in shown if tid >= 0}
        untracked = sum(1 for tid, _ in shown if tid < 0)
        gone = sorted(self._tracks - tracked)
        markers = messages.skeleton_markers_from_points(header, shown, self._ns, lifetime, t,
                                                        deleted_track_ids=gone)
        if not self._cleared:  # what an earlier run left on screen goes first
            markers.markers[:0] = messages.delete_all_markers(header, self._ns, t)
            self._cleared = True
        # untracked skeletons have ids -1, -2, ... by position: delete the positions now unused
        markers.markers.extend(messages.delete_untracked_markers(header, range(untracked, self._untracked),
                                                                 self._ns, t))
        self._tracks = tracked
        self._untracked = untracked
        return markers
