"""The frames waiting to be lifted: a bounded queue that drops the oldest whole frame when a
new one arrives and it is full.

A detector publishes at its own rate; when a frame takes longer to lift than the next takes to
arrive (a crowd, a busy machine), lifting every frame lets the latency grow without bound (each
answer later than the last), and the middleware's keep-last queue drops frames without telling
anyone. Before each lift the node moves every frame the middleware holds into this queue
(:meth:`FrameQueue.put` returns the frame a newer one displaced, so that it is counted in
``/diagnostics``) and lifts the oldest one left (:meth:`FrameQueue.pop`): an answer is never
more than ``depth`` lifts behind its frame, and a frame is lifted and answered whole or dropped
whole, never in part.
"""

from __future__ import annotations

from collections import deque
from typing import Generic, TypeVar

__all__ = ["FrameQueue"]

T = TypeVar("T")


class FrameQueue(Generic[T]):
    """At most ``depth`` frames waiting, the oldest dropped first.

    Parameters
    ----------
    depth : int
        Frames that may wait (>= 1).
    """

    def __init__(self, depth: int = 1) -> None:
        if depth < 1:
            raise ValueError(f"a frame queue holds at least one frame, got depth={depth}")
        self.depth = depth
        self._items: deque[T] = deque()

    def __len__(self) -> int:
        return len(self._items)

    def put(self, item: T) -> T | None:
        """Queue ``item``; returns the oldest frame it displaced (dropped), else None."""
        dropped = self._items.popleft() if len(self._items) >= self.depth else None
        self._items.append(item)
        return dropped

    def pop(self) -> T | None:
        """The oldest waiting frame, taken out of the queue; None when none waits."""
        return self._items.popleft() if self._items else None

    def clear(self) -> int:
        """Drop every waiting frame; returns how many."""
        n = len(self._items)
        self._items.clear()
        return n
