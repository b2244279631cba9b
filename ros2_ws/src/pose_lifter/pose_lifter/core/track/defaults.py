"""Defaults of the per-track policy (:class:`pose_lifter.core.track.policy.TrackPolicy`), read by the
node's parameters, the frame pipeline and the offline lift's settings.

This module imports nothing, so the CLI and the offline settings read the defaults without
loading the solver.
"""

from __future__ import annotations

from typing import Final

__all__ = ["AHEAD_LAG", "DEFAULT_REINIT_RATIO", "DEFAULT_TRACK_TIMEOUT_S", "MAX_LAG"]

#: Seconds of input time a track's warm start stays valid (the node's ``track_timeout``).
DEFAULT_TRACK_TIMEOUT_S: Final[float] = 1.0
#: A warm solve whose objective exceeds this times the track's recent median is redone cold
#: (the node's ``reinit_ratio``).
DEFAULT_REINIT_RATIO: Final[float] = 2.0
#: The largest ``output_lag`` (frames) of the node and ``pose-lifter lift --output-lag``: a lagged frame
#: and its window fit in the frames a track keeps for it (:data:`.lagged.WINDOW`).
MAX_LAG: Final[int] = 10
#: From this ``output_lag`` on, the lift itself waits for the frames its offline prior reads ahead
#: (3) and reads them, as ``pose-lifter lift``; the rest of the lag refines it.
AHEAD_LAG: Final[int] = 6
