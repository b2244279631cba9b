"""The lifter node's statistics line: counters between two lines and the line itself.

Every ``stats_period`` s the node logs the frame rate, the latency per frame (callback in ->
answer published: median, p95, max), the solve time per person-frame (median, p95), the
skeletons lifted with clipped confidences and the skipped inputs by kind.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["FrameStats"]


@dataclass
class FrameStats:
    """Counters between two statistics log lines."""

    started: float = field(default_factory=time.monotonic)
    frames: int = 0
    lifted: int = 0
    warm: int = 0
    latencies: list[float] = field(default_factory=list)
    solve_times: list[float] = field(default_factory=list)
    skipped: Counter[str] = field(default_factory=Counter)
    clipped: int = 0  # skeletons lifted with confidences clipped into [0, 1]

    def frame(self, lifted: Sequence[Any], latency: float) -> None:
        """Count one answered frame: its Skeleton3D messages and its latency (s)."""
        self.frames += 1
        self.lifted += len(lifted)
        self.warm += sum(1 for s in lifted if s.warm_started)
        self.solve_times.extend(float(s.solve_time) for s in lifted)
        self.latencies.append(latency)

    def line(self) -> str:
        """The statistics line (``""`` when nothing happened since the counters started)."""
        elapsed = max(time.monotonic() - self.started, 1e-9)
        if self.frames == 0 and not self.skipped:
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
        if self.clipped:
            text += f", confidences clipped in {self.clipped} skeletons"
        if self.skipped:
            text += ", skipped: " + ", ".join(f"{k} {n}" for k, n in sorted(self.skipped.items()))
        return text
