"""The fused joints answered at once, followed per track by a constant-velocity Kalman filter.

A fused joint (:mod:`.fuse`) carries its frame's errors: the depth reading's (the sensor's noise,
the patch it read, a surface the tests let through) and the lift's frame-to-frame noise, while the
body moves smoothly. Each coordinate of each joint (camera frame, metres) is modelled as a position
and a velocity driven by white acceleration of spectral density :data:`ACCEL_PSD` (m^2/s^3),
observed through the frame's fused joint with that joint's variance (the fusion's standard
deviation squared); the filter's position is answered. It minimises, per coordinate and in closed
form, the expected squared error of the position given the frames so far (no frame after it is
waited for). On the training split's trials the packaged prior was not fitted on (realistic
detector, the depth sensor model, level, 16 tracks of 60 frames): at 3 m jitter 46 -> 22 mm/frame^2,
metric MPJPE 55.7 -> 53.9 mm, P-MPJPE 49.9 -> 49.0; at 5 m 55 -> 25, 57.4 -> 54.2, 49.4 -> 47.0; at
1.5 m 81 -> 30, 117.5 -> 114.4, 91.1 -> 91.2 (``ACCEL_PSD`` 3; 10 and 30 within 0.6 mm, jitter 4-11
mm/frame^2 higher). The answers keep each frame's own standard deviations: the filtered joints err
a little less than those say (coverage in docs/depth.md).

It follows the answers given at once: the node without ``output_lag`` and ``pose-lifter lift
--smoothing 0`` (what the node answers). The lagged node and the offline lift average the fused
joints over a centred window instead (:mod:`.smooth`). A track's filter starts again on its first
fused frame, after a gap longer than ``gap_s`` (the track timeout) and when the input clock steps
back; a frame without a depth image is answered as placed and leaves the filter as it was.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["ACCEL_PSD", "INITIAL_SPEED_STD", "TrackFilter", "filter_track"]

#: Spectral density of the white acceleration of every joint coordinate, m^2/s^3 (module docstring).
ACCEL_PSD: Final[float] = 3.0
#: Standard deviation of a joint's speed on a track's first fused frame, m/s.
INITIAL_SPEED_STD: Final[float] = 2.0


class _State:
    """One track's filter: positions and velocities (12, 3), the covariances' entries (12, 3)
    ``p00`` (position), ``p01``, ``p11`` (velocity), the stamp of its last frame."""

    def __init__(self, stamp_ns: int, joints: NDArray[np.float64], var: NDArray[np.float64]) -> None:
        self.stamp_ns = stamp_ns
        self.x = joints.copy()
        self.v = np.zeros_like(joints)
        self.p00 = var.copy()
        self.p01 = np.zeros_like(var)
        self.p11 = np.full_like(var, INITIAL_SPEED_STD**2)


class TrackFilter:
    """Per track, the constant-velocity Kalman filter of its fused joints (module docstring).

    Parameters
    ----------
    gap_s : float
        A longer gap between a track's fused frames (or a step back in time) starts its filter
        again (the node's track timeout; may be changed between frames).
    accel_psd : float
        :data:`ACCEL_PSD`.
    """

    def __init__(self, gap_s: float, accel_psd: float = ACCEL_PSD) -> None:
        self.gap_s, self.accel_psd = gap_s, accel_psd
        self._tracks: dict[int, _State] = {}

    def update(self, track_id: int, stamp_ns: int, joints_m: NDArray[np.float64],
               std_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """The filtered joints (12, 3), metres, of ``track_id``'s fused frame ``joints_m`` (12, 3)
        with standard deviations ``std_m`` (12, 3) at ``stamp_ns``: the prediction from the track's
        last frame corrected by this one (the frame itself on the track's first fused frame)."""
        z = np.asarray(joints_m, dtype=np.float64)
        r = np.square(np.asarray(std_m, dtype=np.float64))
        s = self._tracks.get(track_id)
        dt = 0.0 if s is None else (stamp_ns - s.stamp_ns) * 1e-9
        if s is None or not 0.0 < dt <= self.gap_s or not (np.isfinite(z).all() and np.isfinite(r).all()):
            self._tracks[track_id] = _State(stamp_ns, z, r)
            return z.copy()
        q = self.accel_psd
        # predict: x += dt v; P = F P F^T + q [[dt^3/3, dt^2/2], [dt^2/2, dt]]
        s.x += dt * s.v
        s.p00 += 2.0 * dt * s.p01 + dt * dt * s.p11 + q * dt**3 / 3.0
        s.p01 += dt * s.p11 + q * dt * dt / 2.0
        s.p11 += q * dt
        # correct with the frame: gain K = P[:, 0] / (p00 + r)
        k0 = s.p00 / (s.p00 + r)
        k1 = s.p01 / (s.p00 + r)
        innovation = z - s.x
        s.x += k0 * innovation
        s.v += k1 * innovation
        s.p11 -= k1 * s.p01
        s.p01 *= 1.0 - k0
        s.p00 *= 1.0 - k0
        s.stamp_ns = stamp_ns
        return s.x.copy()

    def forget(self, before_ns: int) -> None:
        """Forget the tracks whose last fused frame is older than ``before_ns``."""
        for track in [t for t, s in self._tracks.items() if s.stamp_ns < before_ns]:
            del self._tracks[track]

    def clear(self) -> None:
        self._tracks.clear()


def filter_track(stamps_ns: Sequence[int] | NDArray[np.int64], joints_m: NDArray[np.float64],
                 std_m: NDArray[np.float64], fused: NDArray[np.bool_], gap_s: float) -> NDArray[np.float64]:
    """One track's fused frames filtered in time order (:class:`TrackFilter`): ``joints_m`` and
    ``std_m`` (T, 12, 3) at ``stamps_ns`` (T,); only the frames ``fused`` (T,) change."""
    out = np.array(joints_m, dtype=np.float64)
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    f = TrackFilter(gap_s)
    for i in np.flatnonzero(np.asarray(fused, dtype=bool)).tolist():
        out[i] = f.update(0, int(stamps[i]), out[i], std_m[i])
    return out
