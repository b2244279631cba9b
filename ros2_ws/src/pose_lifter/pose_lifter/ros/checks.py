"""How the lifter node says what it refuses: rate-limited warnings.

The refusals themselves (input caps and sanitising, the one check of what is published) are the
frame pipeline's (:mod:`pose_lifter.messages.frame`, shared with the offline lift): the answer
stream (:class:`~pose_lifter.messages.answer.AnswerStream`) returns each as a short kind and its
reason, which the node counts in the statistics line and warns at most once per
:data:`WARN_PERIOD` per kind (:class:`WarningThrottle`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Final

__all__ = ["MAX_WARNING_CHARS", "WARN_PERIOD", "WarningThrottle"]

#: Seconds between two warnings of one kind (each kind is warned at least once per period).
WARN_PERIOD: Final[float] = 5.0
#: Characters of a warning at most (input-derived text is never logged whole).
MAX_WARNING_CHARS: Final[int] = 300


class WarningThrottle:
    """Warnings rate-limited per kind: the first of a kind, then at most one per ``period``.

    Parameters
    ----------
    warn : callable
        Logs one line (the node logger's ``warning``).
    period : float
        Seconds.
    """

    def __init__(self, warn: Callable[[str], Any], period: float = WARN_PERIOD) -> None:
        self._warn = warn
        self._period = period
        self._last: dict[str, float] = {}  # kind -> monotonic time of its last warning

    def warn(self, kind: str, text: str) -> None:
        now = time.monotonic()
        last = self._last.get(kind)
        if last is not None and now - last < self._period:
            return
        self._last[kind] = now
        self._warn(f"{text[:MAX_WARNING_CHARS]} (warnings of this kind are rate-limited "
                   f"to one per {self._period:g} s; counts in the stats line)")
