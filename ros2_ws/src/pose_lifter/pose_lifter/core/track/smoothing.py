"""Smoothing of a track's lifted poses: causal (:class:`CausalSmoother`) and centred.

Live, a track's pose is smoothed causally (:class:`CausalSmoother`, run by
:class:`pose_lifter.core.track.policy.TrackPolicy`): the node cannot wait for later frames. Offline
every frame of a track is known before anything is written, so ``pose-lifter lift`` smooths the
fit's own poses with a Gaussian window centred on each frame: past and future frames alike, so
without the lag of a causal filter. Measured on the evaluation split (``tools/accuracy.py
--methods hybrid hybrid-offline``; docs/accuracy.md) it lowers both the error and the jitter in
every condition, most with outliers and 2D noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ..results import LiftResult

__all__ = ["OFFLINE_SMOOTHING_S", "CausalSmoother", "centred_smoothing", "prior_in_camera",
           "priors_in_camera", "smooth_tracks"]

#: Standard deviation (seconds of input time) of the Gaussian window ``pose-lifter lift`` applies
#: by default: 1.2 frames at 30 Hz (the window spans +-3 standard deviations). Chosen on the
#: evaluation split among 1, 1.25 and 1.5 frames: wider windows flatten fast limbs on clean input.
OFFLINE_SMOOTHING_S: Final[float] = 0.04
#: Frames of a window at most (either side): a bound on the work for very dense stamps.
_MAX_HALF_WIDTH: Final[int] = 64


def centred_smoothing(poses: NDArray[np.float64], stamps_ns: NDArray[np.int64], valid: NDArray[np.bool_],
                      sigma_s: float, gap_s: float) -> NDArray[np.float64]:
    """Gaussian-weighted average of each frame's pose over the track's frames around it.

    ``out[i] = sum_k w_ik poses[k] / sum_k w_ik`` with ``w_ik = exp(-(t_k - t_i)^2 / (2 sigma^2))``
    over the valid frames ``k`` within ``3 sigma`` of frame ``i`` and in the same segment: a gap of
    more than ``gap_s`` between consecutive valid frames, or a step back in time (the input clock
    jumped back, e.g. a looped recording; either way the node's policy forgets the track), starts
    a new segment, and no window crosses it. Near a segment's ends the window is one-sided (it is
    truncated, not padded).

    Parameters
    ----------
    poses : ndarray, shape (T, J, 3)
        A track's poses in one frame of reference (e.g. the camera frame, centred), in time order.
    stamps_ns : ndarray of int, shape (T,)
        Their stamps (nanoseconds), in the order the frames came (non-decreasing within a
        segment).
    valid : ndarray of bool, shape (T,)
        Frames that hold a pose; the others are neither used nor changed.
    sigma_s : float
        Standard deviation of the window in seconds; ``<= 0`` returns a copy of ``poses``.
    gap_s : float
        Largest gap (seconds) within one segment.

    Returns
    -------
    ndarray, shape (T, J, 3)
        The smoothed poses (invalid frames as given).
    """
    poses = np.asarray(poses, dtype=np.float64)
    out = poses.copy()
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    ok = np.asarray(valid, dtype=bool)
    if poses.ndim != 3 or poses.shape[-1] != 3 or stamps.shape != (len(poses),) or ok.shape != stamps.shape:
        raise ValueError(f"poses (T, J, 3), stamps (T,) and valid (T,) expected, got {poses.shape}, "
                         f"{stamps.shape}, {ok.shape}")
    idx = np.flatnonzero(ok)
    if sigma_s <= 0 or len(idx) < 2:
        return out
    if not np.isfinite(poses[idx]).all():
        raise ValueError("a valid frame holds a non-finite pose")
    t = stamps[idx].astype(np.float64) * 1e-9
    dt = np.diff(t)
    segment = np.concatenate([[0], np.cumsum((dt > gap_s) | (dt < 0))])
    positive = dt[dt > 0]
    step = float(positive.min()) if len(positive) else 3.0 * sigma_s
    half = int(min(_MAX_HALF_WIDTH, np.ceil(3.0 * sigma_s / step)))
    x = poses[idx]
    n = len(idx)
    acc = np.zeros_like(x)
    total = np.zeros(n)
    for k in range(-half, half + 1):  # every offset at once over the frames: T x (2 half + 1)
        lo, hi = max(0, -k), min(n, n - k)  # frames i with a neighbour i + k
        if lo >= hi:
            continue
        i = np.arange(lo, hi)
        j = i + k
        gap = t[j] - t[i]
        w = np.exp(-0.5 * (gap / sigma_s) ** 2)
        w[(segment[j] != segment[i]) | (np.abs(gap) > 3.0 * sigma_s)] = 0.0
        acc[i] += w[:, None, None] * x[j]
        total[i] += w
    out[idx] = acc / total[:, None, None]  # total >= 1: every frame weighs itself with w = 1
    return out


class CausalSmoother:
    """Causal smoothing of one track's published pose (camera frame, centred, model units).

    Per frame ``t``, with ``P_t`` the prior's pose and ``F_t`` the fit's (both (12, 3))::

        c_t = b c_{t-1} + (1 - b) (F_t - P_t)               (the fit's correction, averaged)
        S_t = alpha-beta filter of P_t with gain g, h = g^2 / (2 - g)   (g = 1: S_t = P_t)
        out_t = S_t + c_t

``b`` is ``correction_smoothing``; the prior is smooth on clean input and the fit's correction
    of it is where the jitter is (measured: clean unseen tracks 15.6 -> 6.0 mm/frame^2 at b = 0.7,
    P-MPJPE 60.6 -> 60.4 mm), so averaging the correction costs little lag. ``g`` falls with the
    track's disturbance (:data:`pose_lifter.core.track.policy.DISTURBANCE_FULL`): with outliers the
    prior's input changes from frame to frame and the prior jitters too. Uses only the frames
    given so far.

    """

    def __init__(self) -> None:
        self.correction: NDArray[np.float64] | None = None
        self.level: NDArray[np.float64] | None = None
        self.velocity: NDArray[np.float64] | None = None

    def update(self, fit: NDArray[np.float64], prior: NDArray[np.float64], b: float, gain: float
               ) -> NDArray[np.float64]:
        """The smoothed pose (12, 3) for this frame's fit and prior poses (12, 3)."""
        fits = np.asarray(fit, dtype=np.float64)[None]
        priors = np.asarray(prior, dtype=np.float64)[None]
        return np.asarray(smooth_tracks([self], fits, priors, np.array([b]), np.array([gain]))[0])


def smooth_tracks(smoothers: Sequence[CausalSmoother], fits: NDArray[np.float64], priors: NDArray[np.float64],
                  b: NDArray[np.float64], gain: NDArray[np.float64]) -> NDArray[np.float64]:
    """:meth:`CausalSmoother.update` of n tracks' smoothers at once, as arrays over the tracks
    (elementwise: each row is what its smoother alone gives, bit for bit).

    Parameters
    ----------
    smoothers : sequence of n CausalSmoother
        Updated in place (a new one starts from this frame).
    fits, priors : ndarray, shape (n, 12, 3)
        This frame's fit and prior poses (camera frame, centred, model units).
    b, gain : ndarray, shape (n,)
        Each track's ``correction_smoothing`` and alpha-beta gain.

    Returns
    -------
    ndarray, shape (n, 12, 3)
        The smoothed poses (a new smoother's: its fit).
    """
    corr = fits - priors
    out = np.array(fits, dtype=np.float64)
    going: list[int] = []
    for i, sm in enumerate(smoothers):
        if sm.correction is None or sm.level is None or sm.velocity is None:  # starts: its fit
            sm.correction, sm.level, sm.velocity = corr[i], priors[i].copy(), np.zeros_like(priors[i])
        else:
            going.append(i)
    if not going:
        return out
    idx = np.array(going)
    c = np.array([smoothers[i].correction for i in going])
    level = np.array([smoothers[i].level for i in going])
    velocity = np.array([smoothers[i].velocity for i in going])
    bb, g = b[idx][:, None, None], gain[idx][:, None, None]
    c = bb * c + (1.0 - bb) * corr[idx]
    predicted = level + velocity
    resid = priors[idx] - predicted
    level = predicted + g * resid
    velocity = velocity + (g * g / (2.0 - g)) * resid
    out[idx] = level + c
    for r, i in enumerate(going):
        smoothers[i].correction, smoothers[i].level, smoothers[i].velocity = c[r], level[r], velocity[r]
    return out


def prior_in_camera(result: LiftResult) -> NDArray[np.float64] | None:
    """The prior's pose of ``result`` in the camera frame of ``pose_camera`` (12, 3: centred, in
    the fit's model units: divided by the camera's scale), or None without one."""
    poses, ok = priors_in_camera([result])
    return poses[0] if ok[0] else None


def priors_in_camera(results: Sequence[LiftResult]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`prior_in_camera` of n results as arrays over them: the poses (n, 12, 3) and which
    rows have one (n,; the others NaN): a prior's pose, a positive camera scale, finite values."""
    n = len(results)
    out = np.full((n, *np.shape(results[0].pose_camera)) if n else (0, 0, 3), np.nan)
    ok = np.zeros(n, dtype=np.bool_)
    rows = [i for i, r in enumerate(results) if r.prior_pose is not None and float(r.camera.scale) > 0]
    if rows:
        prior = np.array([results[i].prior_pose for i in rows])
        scale = np.array([float(results[i].camera.scale) for i in rows])
        x = (prior - prior.mean(axis=1)[:, None, :]) / scale[:, None, None]
        out[rows] = x
        ok[rows] = np.isfinite(x).all(axis=(1, 2))
    return out, ok
