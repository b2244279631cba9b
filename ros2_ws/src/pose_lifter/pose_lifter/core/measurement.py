"""The per-joint measurement update of a hybrid track's published pose (``LifterOptions.
measurement_update``): where the observed 2D says where a joint is, the published pose puts it
there.

The hybrid fit trades the 2D against its prior's depths, so its image positions stay off the 2D
(on unseen motion a dance fold's output was 60 mm off in x, y; the observed 2D is within ~10 mm
of the truth, perspective included). Per frame of a track, after the output smoothing
(:class:`pose_lifter.core.tracking.TrackPolicy`), on the published pose ``P`` (12, 3: camera
frame, centred, model units) and the frame's 2D ``x`` (12, 2, input units):

1. **The 2D in the pose's frame**: ``o_j = s (x_j - c)``, the scale ``s`` and image centre ``c``
   by least squares onto ``P``'s x, y over the joints the lift used, ``s`` averaged over frames
   in logs (SCALE_SMOOTHING) and ``c`` blended (SHIFT_SMOOTHING) with the last centre moved by the
   median image motion of the joints used on both frames (a changing set of joints would
   otherwise shift it).
2. **Gate**: a used joint farther than ``measurement_gate`` leg lengths (at least
   GATE_NOISE_FACTOR times the track's 2D noise) from ``P`` is not updated (a confident outlier
   the lift kept); the alignment is redone without it.
3. **x, y**: per joint an offset ``d_j`` (``P_j,xy + d_j`` is published) follows ``o_j - P_j,xy``
   with the gain ``k`` of a random walk (the fit's error, DRIFT per frame) observed through the
   track's 2D noise ``n`` (``_Track.noise``): ``k = 1`` on clean 2D, ~0.08 at 0.1 leg lengths of
   noise (the offset then averages the noise over frames). A joint not updated on this frame
   keeps HOLD of its offset from where the track predicts it (its last published x, y plus
   HOLD_VELOCITY of its last motion), so a joint that drops out does not jump to the fit's.
4. **Depth**: each limb (upper arm, forearm, thigh, shin) whose two joints were updated gets the
   depth its image length says, ``|dz| = sqrt(L^2 - |dxy|^2)`` (sign from ``P``), ``L`` the track's
   image length of that limb (SPAN_QUANTILE of its aligned 2D lengths over the last SPAN_FRAMES
   frames, left and right averaged: a limb seen across the image shows its length), blended into
   ``P``'s ``dz`` with ``measurement_depth * k`` and averaged over frames (DEPTH_SMOOTHING); the
   shoulders and hips keep ``P``'s depths.
5. The pose is centred again and its depths follow a constant-velocity (alpha-beta) filter whose
   gain is ``1 - (1 - DEPTH_GAIN) k`` (the foreshortening depth is noisier than ``P``'s, which is
   smoothed already).

Causal (this and earlier frames only), output-only (the track's fits, warm starts, gate and
estimates never see it) and cheap (tens of microseconds). Measured in ``docs/tuning.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ._fast import mean_rows, median_rows
from .skeleton import LEFT_LIMBS, LIMB_GROUP_OF, LIMBS, N_JOINTS, RIGHT_LIMBS

__all__ = ["MeasurementUpdate", "kalman_gain"]

LIMB_A = np.array([a for a, _ in LIMBS])
LIMB_B = np.array([b for _, b in LIMBS])
#: The limbs whose parent joint is a shoulder or hip, then those whose parent is one of theirs.
_STAGES = (np.array([i for i, (a, _) in enumerate(LIMBS) if a not in LIMB_B]),
           np.array([i for i, (a, _) in enumerate(LIMBS) if a in LIMB_B]))
#: Change per frame (model units) of the fit's x, y error, for the gain of step 3.
DRIFT = 0.01
#: The gate is at least this many times the track's 2D noise (noisy 2D: its own scale).
GATE_NOISE_FACTOR = 4.0
#: A joint not updated keeps this share of its offset from where the track predicts it, which is
#: its last published x, y plus HOLD_VELOCITY times its last motion.
HOLD = 0.95
HOLD_VELOCITY = 0.5
#: Averaging of the 2D's scale (in logs) and blend of its centre with the predicted one.
SCALE_SMOOTHING = 0.9
SHIFT_SMOOTHING = 0.5
#: Limb lengths from the image: this quantile of the last SPAN_FRAMES frames' aligned 2D lengths,
#: once SPAN_MIN_FRAMES frames are in (fewer: no depth step), recomputed every SPAN_EVERY frames.
SPAN_QUANTILE = 0.9
SPAN_FRAMES = 90
SPAN_MIN_FRAMES = 5
SPAN_EVERY = 5
#: Averaging of the depth step's correction over frames, and the alpha-beta gain of the output's
#: depths at full trust in the 2D (step 5).
DEPTH_SMOOTHING = 0.5
DEPTH_GAIN = 0.6


def kalman_gain(q: float, r: float) -> float:
    """The steady-state Kalman gain of a random walk (variance ``q`` per step) observed with noise
    of variance ``r``: 1 without noise, about ``sqrt(q / r)`` when the noise dominates."""
    if r <= 0.0:
        return 1.0
    p = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    return p / (p + r)


def _column_quantiles(rows: NDArray[np.float64], q: float) -> NDArray[np.float64]:
    """Per column of ``rows`` (n, m; NaN = none) the ``q`` quantile (linear) of its finite values,
    NaN where a column has fewer than SPAN_MIN_FRAMES // 2 of them."""
    s = np.sort(rows, axis=0)  # NaN last
    count = np.isfinite(rows).sum(axis=0)
    pos = q * np.maximum(count - 1, 0)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, np.maximum(count - 1, 0))
    cols = np.arange(rows.shape[1])
    out = s[lo, cols] + (pos - lo) * (s[hi, cols] - s[lo, cols])
    return np.where(count >= max(SPAN_MIN_FRAMES // 2, 1), out, np.nan)


def _align(points: NDArray[np.float64], xy: NDArray[np.float64], use: NDArray[np.bool_]
           ) -> tuple[float, NDArray[np.float64], NDArray[np.float64]] | None:
    """Least squares ``xy ~ s (points - pc) + qc`` over the joints ``use``: ``(s, pc, qc)`` (the
    two centroids), or None with fewer than 3 joints or a degenerate fit."""
    if np.count_nonzero(use) < 3:
        return None
    p, q = points[use], xy[use]
    pc, qc = mean_rows(p), mean_rows(q)
    pp = p - pc
    den = float((pp * pp).sum())
    s = float((pp * (q - qc)).sum()) / den if den > 0 else 0.0
    if not s > 0:
        return None
    return s, pc, qc


_LEFT, _RIGHT, _GROUP = np.array(LEFT_LIMBS), np.array(RIGHT_LIMBS), np.array(LIMB_GROUP_OF)


class MeasurementUpdate:
    """One track's state of the measurement update (module docstring); :meth:`update` per frame."""

    def __init__(self) -> None:
        self.offset = np.zeros((N_JOINTS, 2))
        self.depth_offset = np.zeros(N_JOINTS)
        self.spans = np.full((SPAN_FRAMES, len(LIMBS)), np.nan)
        self.n_spans = 0
        self.limbs: NDArray[np.float64] | None = None
        self.limbs_at = -SPAN_EVERY
        self.log_scale: float | None = None
        self.centre: NDArray[np.float64] | None = None
        self.prev_points: NDArray[np.float64] | None = None
        self.prev_updated = np.zeros(N_JOINTS, dtype=bool)
        self.depth_level: NDArray[np.float64] | None = None
        self.depth_velocity = np.zeros(N_JOINTS)
        self.last: NDArray[np.float64] | None = None
        self.last2: NDArray[np.float64] | None = None

    def limb_lengths(self) -> NDArray[np.float64] | None:
        """The track's limb lengths from the image (8,; left and right averaged; model units), or
        None before SPAN_MIN_FRAMES frames or with a limb seen too rarely."""
        if self.n_spans < SPAN_MIN_FRAMES:
            return None
        if self.n_spans >= self.limbs_at + SPAN_EVERY:
            est = _column_quantiles(self.spans[: min(self.n_spans, SPAN_FRAMES)], SPAN_QUANTILE)
            out = (0.5 * (est[_LEFT] + est[_RIGHT]))[_GROUP]
            self.limbs = out if np.isfinite(out).all() else None
            self.limbs_at = self.n_spans
        return self.limbs

    def update(self, pose: NDArray[np.float64], points: NDArray[np.float64], used: NDArray[np.bool_],
               noise: float, depth: float, gate: float) -> NDArray[np.float64]:
        """The published pose (12, 3) for this frame.

        Parameters
        ----------
        pose : ndarray, shape (12, 3)
            The pose the track would publish (camera frame, centred, model units).
        points : ndarray, shape (12, 2)
            The frame's 2D (input units; only the ``used`` joints are read).
        used : ndarray of bool, shape (12,)
            The joints the lift used (``LiftResult.weights > 0``).
        noise : float
            The track's 2D noise (model units, >= 0).
        depth : float
            ``measurement_depth``: weight of the limbs' image-length depth (0 = ``pose``'s).
        gate : float
            ``measurement_gate`` (leg lengths).
        """
        pose = np.asarray(pose, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64)
        xy = pose[:, :2]
        gate = max(gate, GATE_NOISE_FACTOR * noise)
        k = kalman_gain(DRIFT * DRIFT, noise * noise)
        al = _align(points, xy, used)
        ok = np.zeros(N_JOINTS, dtype=bool)
        if al is not None:
            r = al[0] * (points - al[1]) + al[2] - xy
            ok = used & ((r * r).sum(axis=1) <= gate * gate)
            if np.count_nonzero(ok) < np.count_nonzero(used):
                al = _align(points, xy, ok)
                if al is None:
                    ok[:] = False
        # where a joint that is not updated goes: where the track predicts it
        predicted = xy + self.offset
        if self.last is not None:
            predicted = self.last[:, :2]
            if self.last2 is not None:
                predicted = predicted + HOLD_VELOCITY * (self.last[:, :2] - self.last2[:, :2])
        held = HOLD * (predicted - xy)
        if al is not None and ok.any():
            s, pc, qc = al
            ls = math.log(s)
            if self.log_scale is not None:
                ls = SCALE_SMOOTHING * self.log_scale + (1.0 - SCALE_SMOOTHING) * ls
            self.log_scale = ls
            scale = math.exp(ls)
            centre = pc - qc / scale  # the image point at the pose's origin
            if self.centre is not None and self.prev_points is not None:
                both = ok & self.prev_updated
                if np.count_nonzero(both) >= 3:
                    moved = self.centre + median_rows(points[both] - self.prev_points[both])
                    centre = SHIFT_SMOOTHING * moved + (1.0 - SHIFT_SMOOTHING) * centre
            self.centre = centre
            self.prev_points, self.prev_updated = points.copy(), ok.copy()
            obs = scale * (points - centre)
            step = self.offset + k * (obs - xy - self.offset)
            self.offset = np.where(ok[:, None], step, held)
            span_ok = ok[LIMB_A] & ok[LIMB_B]
            d = obs[LIMB_B] - obs[LIMB_A]
            self.spans[self.n_spans % SPAN_FRAMES] = np.where(span_ok, np.sqrt((d * d).sum(axis=1)), np.nan)
            self.n_spans += 1
        else:
            self.offset = held
        out = pose.copy()
        out[:, :2] += self.offset
        limbs = self.limb_lengths() if depth > 0 else None
        prev_depth = self.depth_offset
        depth_offset = HOLD * prev_depth
        if limbs is not None:
            beta = depth * k
            z = pose[:, 2] + depth_offset
            for stage in _STAGES:  # the upper limbs, then the lower ones from their new depths
                a, b = LIMB_A[stage], LIMB_B[stage]
                dz = pose[b, 2] - pose[a, 2]
                dxy = out[b, :2] - out[a, :2]
                mag = np.sqrt(np.maximum(limbs[stage] ** 2 - (dxy * dxy).sum(axis=1), 0.0))
                want = z[a] + (1.0 - beta) * dz + beta * np.where(dz >= 0, mag, -mag)
                step = DEPTH_SMOOTHING * prev_depth[b] + (1.0 - DEPTH_SMOOTHING) * (want - pose[b, 2])
                depth_offset[b] = np.where(ok[a] & ok[b], step, depth_offset[b])
                z[b] = pose[b, 2] + depth_offset[b]
        self.depth_offset = depth_offset
        out[:, 2] += depth_offset
        out -= mean_rows(out)
        gain = 1.0 - (1.0 - DEPTH_GAIN) * k
        if self.depth_level is None:
            self.depth_level = out[:, 2].copy()
        else:
            predicted_z = self.depth_level + self.depth_velocity
            resid = out[:, 2] - predicted_z
            self.depth_level = predicted_z + gain * resid
            self.depth_velocity = self.depth_velocity + (gain * gain / (2.0 - gain)) * resid
        out[:, 2] = self.depth_level
        out -= mean_rows(out)
        self.last2, self.last = self.last, out
        return out
