"""The frames waiting for the node's lifting thread: a bounded queue that drops the oldest whole
frame when a new one arrives and it is full.

A detector publishes at its own rate; when a frame takes longer to lift than the next takes to
arrive (a crowd, a busy machine), lifting every frame would let the latency grow without bound
(each answer later than the last), and the middleware's keep-last queue would drop frames
without telling anyone. The node's subscription callback only puts the frame here
(:meth:`FrameQueue.put`, which returns the frame it dropped so that it is counted in
``/diagnostics``) and its lifting thread takes them in arrival order (:meth:`FrameQueue.get`):
an answer is never more than ``depth + 1`` lifts behind its frame, and a frame is lifted and
answered whole or dropped whole, never in part.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Generic, TypeVar

__all__ = ["FrameQueue"]

T = TypeVar("T")


class FrameQueue(Generic[T]):
    """At most ``depth`` frames waiting, the oldest dropped first; thread-safe.

    Parameters
    ----------
    depth : int
        Frames that may wait while one is being lifted (>= 1).
    """

    def __init__(self, depth: int = 1) -> None:
        if depth < 1:
            raise ValueError(f"a frame queue holds at least one frame, got depth={depth}")
        self.depth = depth
        self._items: deque[T] = deque()
        self._cv = threading.Condition()
        self._closed = False

    def __len__(self) -> int:
        with self._cv:
            return len(self._items)

    def put(self, item: T) -> T | None:
        """Queue ``item``; returns the oldest frame it displaced (dropped), else None. A closed
        queue takes nothing and returns ``item`` itself (dropped)."""
        with self._cv:
            if self._closed:
                return item
            dropped = self._items.popleft() if len(self._items) >= self.depth else None
            self._items.append(item)
            self._cv.notify()
            return dropped

    def get(self) -> T | None:
        """The oldest waiting frame, waiting for one; None once the queue is closed (what still
        waits is not handed out)."""
        with self._cv:
            while not self._items and not self._closed:
                self._cv.wait()
            if self._closed:
                return None
            return self._items.popleft()

    def clear(self) -> int:
        """Drop every waiting frame; returns how many."""
        with self._cv:
            n = len(self._items)
            self._items.clear()
            return n

    def close(self) -> None:
        """Wake every :meth:`get` with None, now and from now on."""
        with self._cv:
            self._closed = True
            self._items.clear()
            self._cv.notify_all()
