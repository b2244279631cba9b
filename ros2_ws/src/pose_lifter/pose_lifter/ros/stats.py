"""The lifter node's one counter of frames, skeletons and skipped inputs, and its statistics line.

The node counts each answered frame, skipped input and clipped skeleton once, in a
:class:`FrameCounter`; each report of the counts takes its own window of them on its own period:
the statistics line (:meth:`FrameStats.line`) and ``/diagnostics``
(:mod:`pose_lifter.ros.diagnostics`).

Every ``stats_period`` s the node logs the frame rate, the latency per frame (frame received ->
answer published: median, p95, max), the solve time per person-frame (median, p95), the frames
dropped while it was busy, the frames lifted with and without their depth image (by why), the
skeletons lifted with clipped confidences, those whose track
swapped back their detector's left/right labels (a detector's side confusions, how often) and
the skipped inputs by kind.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["FrameCounter", "FrameStats"]


@dataclass
class FrameStats:
    """The counts of one window (from ``started``, :func:`time.monotonic`, to now)."""

    started: float = field(default_factory=time.monotonic)
    frames: int = 0
    lifted: int = 0
    warm: int = 0
    latencies: list[float] = field(default_factory=list)
    solve_times: list[float] = field(default_factory=list)
    skipped: Counter[str] = field(default_factory=Counter)
    clipped: int = 0  # skeletons lifted with confidences clipped into [0, 1]
    dropped: int = 0  # whole frames dropped unanswered while the node was busy (the oldest first)
    relabelled: int = 0  # skeletons whose track swapped back their detector's left/right labels
    with_depth: int = 0  # frames lifted with their depth image (depth_topic)
    without_depth: Counter[str] = field(default_factory=Counter)  # ... and without, by why

    def frame(self, lifted: Sequence[Any], latency: float) -> None:
        """Count one answered frame: its lifted skeletons (``warm_started``, ``solve_time`` and,
        of a :class:`~pose_lifter.messages.frame.LiftedSkeleton`, ``swapped``) and its latency (s)."""
        self.frames += 1
        self.lifted += len(lifted)
        self.warm += sum(1 for s in lifted if s.warm_started)
        self.relabelled += sum(1 for s in lifted if getattr(s, "swapped", None) is not None)
        self.solve_times.extend(float(s.solve_time) for s in lifted)
        self.latencies.append(latency)

    def elapsed(self) -> float:
        """Seconds since the window started (at least 1 ns)."""
        return max(time.monotonic() - self.started, 1e-9)

    def line(self) -> str:
        """The statistics line (``""`` when nothing happened since the counters started)."""
        elapsed = self.elapsed()
        if self.frames == 0 and not self.skipped and not self.dropped and not self.without_depth:
            return ""
        lat = np.asarray(self.latencies) * 1e3
        solve = np.asarray(self.solve_times) * 1e3
        text = (f"{self.frames} frames ({self.frames / elapsed:.1f} Hz), {self.lifted} skeletons "
                f"({self.warm} warm)")
        if lat.size:  # per frame, callback in -> answer published
            text += (f", latency median {np.median(lat):.1f} ms p95 {np.percentile(lat, 95):.1f} ms "
                     f"max {lat.max():.1f} ms")
        if solve.size:  # per person-frame
            text += f", solve median {np.median(solve):.1f} ms p95 {np.percentile(solve, 95):.1f} ms"
        if self.dropped:
            text += f", {self.dropped} frames dropped (the node was busy)"
        if self.clipped:
            text += f", confidences clipped in {self.clipped} skeletons"
        if self.relabelled:
            text += f", left/right labels swapped back in {self.relabelled} skeletons"
        if self.with_depth or self.without_depth:
            text += f", {self.with_depth} frames with depth"
            if self.without_depth:
                why = ", ".join(f"{k} {n}" for k, n in sorted(self.without_depth.items()))
                text += f" (without: {why})"
        if self.skipped:
            text += ", skipped: " + ", ".join(f"{k} {n}" for k, n in sorted(self.skipped.items()))
        return text


class FrameCounter:
    """The node's one counter: each count goes into the open window of every report.

    A report opens its window (:meth:`open`), takes it on its own period (:meth:`take`: the
    counts since the last take, and a new window starts) and closes it when it stops.
    """

    def __init__(self) -> None:
        self._windows: dict[str, FrameStats] = {}

    def open(self, report: str) -> None:
        """Start counting for ``report`` (from now)."""
        self._windows[report] = FrameStats()

    def close(self, report: str) -> None:
        """Stop counting for ``report``."""
        self._windows.pop(report, None)

    def take(self, report: str) -> FrameStats:
        """The window of ``report`` since its last take (or open); a new window starts."""
        window = self._windows[report]
        self._windows[report] = FrameStats()
        return window

    def frame(self, lifted: Sequence[Any], latency: float) -> None:
        """One answered frame: its lifted skeletons (:meth:`FrameStats.frame`) and its latency (s)."""
        for window in self._windows.values():
            window.frame(lifted, latency)

    def skip(self, kind: str) -> None:
        """One skipped input of a kind."""
        for window in self._windows.values():
            window.skipped[kind] += 1

    def depth(self, kind: str | None) -> None:
        """One frame lifted with its depth image (``kind`` None), or without it (why)."""
        for window in self._windows.values():
            if kind is None:
                window.with_depth += 1
            else:
                window.without_depth[kind] += 1

    def drop(self) -> None:
        """One whole frame dropped unanswered (a newer one came while the node was busy)."""
        for window in self._windows.values():
            window.dropped += 1

    def clip(self) -> None:
        """One skeleton lifted with confidences clipped into [0, 1]."""
        for window in self._windows.values():
            window.clipped += 1
