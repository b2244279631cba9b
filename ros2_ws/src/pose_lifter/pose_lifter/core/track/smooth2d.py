"""The offline smoothing of a track's 2D over past and future frames: a Rauch-Tung-Striebel
smoother of a constant-velocity model per joint coordinate (:func:`smooth_track_2d`), which the
refiner (:mod:`.later`) runs before its measurement update.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..model.skeleton import N_JOINTS
from ..numeric.jit import njit

__all__ = ["SMOOTH_ACCEL", "SMOOTH_FRAME_S", "SMOOTH_NOISE_FLOOR", "SMOOTH_PRIOR_VAR", "smooth_track_2d"]

#: Offline smoothing of the 2D (:func:`smooth_track_2d`): the constant-velocity model's random
#: acceleration, per frame^2 at 30 Hz, as a share of the track's 2D size (the median over frames of
#: the RMS distance of its joints from their centre). Clean mocap of the held-out training-split
#: tracks: median 0.012, 90th percentile 0.045; 0.025 halves white 2D noise of 0.05 leg lengths
#: (0.015 and 0.04 lifted within 0.2 mm of it on the cross-action folds, 0.4 on val).
SMOOTH_ACCEL = 0.025
#: The frame period the acceleration is given at (s).
SMOOTH_FRAME_S = 1.0 / 30.0
#: The smoothed 2D's measurement noise is at least this share of the track's 2D size.
SMOOTH_NOISE_FLOOR = 0.001
#: The smoother's prior variance of a series' first position and velocity (in the track's 2D
#: size, squared): uninformative against the measurements' (at most ~0.01), and small enough
#: that the passes lose no digits to it.
SMOOTH_PRIOR_VAR = 100.0


@njit
def _rts_kernel(z: NDArray[np.float64], seen: NDArray[np.bool_], dt: NDArray[np.float64], q: float, r: float,
                out: NDArray[np.float64], var: NDArray[np.float64]) -> None:
    """Per column of ``z`` (T, S; read where ``seen``) the Rauch-Tung-Striebel smoothed position of
    a constant-velocity model: position and velocity (prior N(0, SMOOTH_PRIOR_VAR) each), a random
    acceleration of variance ``q`` per unit step (``dt`` (T,) the steps, ``dt[0]`` unused),
    measurement variance ``r``. ``out`` and ``var`` (T, S): the smoothed positions and their
    variances (NaN for a column never seen)."""
    n, m = z.shape
    xf = np.empty((n, 2))
    pf = np.empty((n, 3))  # p00, p01, p11
    xp = np.empty((n, 2))
    pp = np.empty((n, 3))
    for s in range(m):
        x0 = x1 = 0.0
        p00 = p11 = SMOOTH_PRIOR_VAR
        p01 = 0.0
        any_seen = False
        for t in range(n):
            if t > 0:
                h = dt[t]
                x0 = x0 + h * x1
                a00 = p00 + 2.0 * h * p01 + h * h * p11
                a01 = p01 + h * p11
                p00 = a00 + q * h ** 4 / 4.0
                p01 = a01 + q * h ** 3 / 2.0
                p11 = p11 + q * h * h
            xp[t, 0], xp[t, 1] = x0, x1
            pp[t, 0], pp[t, 1], pp[t, 2] = p00, p01, p11
            if seen[t, s]:
                any_seen = True
                gs = p00 + r
                k0, k1 = p00 / gs, p01 / gs
                innov = z[t, s] - x0
                x0 += k0 * innov
                x1 += k1 * innov
                p11 = p11 - k1 * p01
                p01 = p01 - k0 * p01
                p00 = p00 - k0 * p00
            xf[t, 0], xf[t, 1] = x0, x1
            pf[t, 0], pf[t, 1], pf[t, 2] = p00, p01, p11
        if not any_seen:
            for t in range(n):
                out[t, s] = np.nan
                var[t, s] = np.nan
            continue
        s0, s1 = xf[n - 1, 0], xf[n - 1, 1]
        q00, q01, q11 = pf[n - 1, 0], pf[n - 1, 1], pf[n - 1, 2]
        out[n - 1, s], var[n - 1, s] = s0, q00
        for t in range(n - 2, -1, -1):
            h = dt[t + 1]
            f00, f01, f11 = pf[t, 0], pf[t, 1], pf[t, 2]
            # C = Pf F' Pp^-1 (2 x 2), F = [[1, h], [0, 1]]
            b00, b01 = f00 + h * f01, f01
            b10, b11 = f01 + h * f11, f11
            e00, e01, e11 = pp[t + 1, 0], pp[t + 1, 1], pp[t + 1, 2]
            det = e00 * e11 - e01 * e01
            i00, i01, i11 = e11 / det, -e01 / det, e00 / det
            c00, c01 = b00 * i00 + b01 * i01, b00 * i01 + b01 * i11
            c10, c11 = b10 * i00 + b11 * i01, b10 * i01 + b11 * i11
            d0, d1 = s0 - xp[t + 1, 0], s1 - xp[t + 1, 1]
            n0 = xf[t, 0] + c00 * d0 + c01 * d1
            n1 = xf[t, 1] + c10 * d0 + c11 * d1
            g00, g01, g11 = q00 - e00, q01 - e01, q11 - e11
            # C G C'
            t00 = c00 * g00 + c01 * g01
            t01 = c00 * g01 + c01 * g11
            t10 = c10 * g00 + c11 * g01
            t11 = c10 * g01 + c11 * g11
            q00 = f00 + t00 * c00 + t01 * c01
            q01 = f01 + t00 * c10 + t01 * c11
            q11 = f11 + t10 * c10 + t11 * c11
            s0, s1 = n0, n1
            out[t, s], var[t, s] = s0, q00


def smooth_track_2d(points: NDArray[np.float64], used: NDArray[np.bool_], stamps_ns: NDArray[np.int64]
                    ) -> tuple[NDArray[np.float64], float]:
    """One track's 2D smoothed over its past and future frames (the offline update's input).

    Per joint and axis, the Rauch-Tung-Striebel smoother of a constant-velocity model: a random
    acceleration of SMOOTH_ACCEL of the track's 2D size per frame^2 at 30 Hz (scaled to the
    frames' own steps), a white measurement noise estimated from the 2D (the median absolute
    second difference over three consecutive used frames, less the model's acceleration; at
    least SMOOTH_NOISE_FLOOR of the size), the joints the lift used as its measurements. It
    minimises, per series, the sum of the squared measurement residuals over the noise variance
    and the squared accelerations over their variance (the exact solution of that least-squares
    problem, in two passes).

    Parameters
    ----------
    points : ndarray, shape (T, 12, 2)
        The 2D of the track's frames, in time order (input units).
    used : ndarray of bool, shape (T, 12)
        The joints the lift used on each frame.
    stamps_ns : ndarray of int, shape (T,)
        The frames' stamps (increasing).

    Returns
    -------
    smoothed : ndarray, shape (T, 12, 2)
        The smoothed 2D (NaN for a joint never used).
    ratio : float
        The median over used joints and frames of the smoothed position's standard deviation over
        the measurement noise's (in (0, 1]; 1 with fewer than 3 frames, nothing smoothed then).
    """
    n = points.shape[0]
    out = np.empty((n, N_JOINTS, 2))
    ratio = _smooth_kernel(np.ascontiguousarray(points, dtype=np.float64),
                           np.ascontiguousarray(used, dtype=np.bool_),
                           np.asarray(stamps_ns, dtype=np.float64), out)
    return out, ratio


@njit
def _track_size(points: NDArray[np.float64], used: NDArray[np.bool_]) -> float:
    """:func:`smooth_track_2d`'s size of a track: the median over its frames with at least two used
    joints of their RMS distance from the frame's centre (0 with fewer than 3 frames or none).
    The squared distances are summed in numpy's pairwise order (8 partial sums, then the rest), so
    the size is numpy's ``sum(axis=...)`` to the last bit."""
    n = points.shape[0]
    spread = np.empty(n)
    m = 0
    for t in range(n):
        count = 0
        cx = cy = 0.0
        for j in range(N_JOINTS):
            if used[t, j]:
                count += 1
                cx += points[t, j, 0]
                cy += points[t, j, 1]
        if count <= 1:
            continue
        cx, cy = cx / count, cy / count
        d = np.zeros(N_JOINTS)
        for j in range(N_JOINTS):
            if used[t, j]:
                d[j] = (points[t, j, 0] - cx) ** 2 + (points[t, j, 1] - cy) ** 2
        total = ((d[0] + d[1]) + (d[2] + d[3])) + ((d[4] + d[5]) + (d[6] + d[7]))
        for j in range(8, N_JOINTS):
            total += d[j]
        spread[m] = math.sqrt(total / count)
        m += 1
    return float(np.median(spread[:m])) if n >= 3 and m > 0 else 0.0


@njit
def _smooth_kernel(points: NDArray[np.float64], used: NDArray[np.bool_], stamps_ns: NDArray[np.float64],
                   out: NDArray[np.float64]) -> float:
    """:func:`smooth_track_2d` (its arguments; ``out`` (T, 12, 2) the smoothed 2D): returns the
    ratio."""
    n = points.shape[0]
    size = _track_size(points, used)
    if not size > 0.0:  # too few frames or joints to smooth: the 2D as given
        for t in range(n):
            for j in range(N_JOINTS):
                for c in range(2):
                    out[t, j, c] = points[t, j, c] if used[t, j] else np.nan
        return 1.0
    m = 2 * N_JOINTS
    zs = np.empty((n, m))
    seen = np.empty((n, m), dtype=np.bool_)
    for t in range(n):
        for j in range(N_JOINTS):
            for c in range(2):
                zs[t, 2 * j + c] = (points[t, j, c] if used[t, j] else 0.0) / size
                seen[t, 2 * j + c] = used[t, j]
    dt = np.empty(n)
    dt[0] = 1.0
    for t in range(1, n):
        dt[t] = max((stamps_ns[t] - stamps_ns[t - 1]) / (SMOOTH_FRAME_S * 1e9), 1e-3)
    d2 = np.empty(max(n - 2, 0) * m)
    k = 0
    for t in range(n - 2):
        for s in range(m):
            if seen[t + 2, s] and seen[t + 1, s] and seen[t, s]:
                d2[k] = abs(zs[t + 2, s] - 2.0 * zs[t + 1, s] + zs[t, s])
                k += 1
    q = SMOOTH_ACCEL ** 2
    sd = 1.4826 * np.median(d2[:k]) if k else 0.0  # the robust standard deviation
    sig2 = sd * sd / 6.0
    r = max(sig2 - q / 6.0, SMOOTH_NOISE_FLOOR ** 2)
    smooth = np.empty((n, m))
    var = np.empty((n, m))
    _rts_kernel(zs, seen, dt, q, r, smooth, var)
    kept = np.empty(n * m)
    k = 0
    for t in range(n):
        for s in range(m):
            out[t, s // 2, s % 2] = smooth[t, s] * size
            if seen[t, s]:
                kept[k] = var[t, s]
                k += 1
    return min(math.sqrt(np.median(kept[:k]) / r), 1.0)
