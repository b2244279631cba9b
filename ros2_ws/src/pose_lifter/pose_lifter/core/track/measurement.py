"""The per-joint measurement update of a hybrid track's published pose (``LifterOptions.
measurement_update``): where the observed 2D says where a joint is, the published pose puts it
there.

The hybrid fit trades the 2D against its prior's depths, so its image positions stay off the 2D
(on unseen motion a dance fold's output was 60 mm off in x, y; the observed 2D is within ~10 mm
of the truth, perspective included). Per frame of a track, after the output smoothing
(:class:`pose_lifter.core.track.policy.TrackPolicy`), on the published pose ``P`` (12, 3: camera
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
   track's 2D noise ``n`` (``state.Track.noise_level``): ``k = 1`` on clean 2D, ~0.08 at 0.1 leg lengths of
   noise (the offset then averages the noise over frames). A joint not updated on this frame
   keeps HOLD of its offset from where the track predicts it (its last published x, y plus
   HOLD_VELOCITY of its last motion), so a joint that drops out does not jump to the fit's.
4. **Depth**: each limb (upper arm, forearm, thigh, shin) whose two joints were updated gets the
   depth its image length says, ``|dz| = sqrt(L^2 - |dxy|^2)`` (sign from ``P``), ``L`` the track's
   image length of that limb (SPAN_QUANTILE of its aligned 2D lengths over the last SPAN_FRAMES
   frames, left and right averaged: a limb seen across the image shows its length), at least
   OWN_LIMB_SHARE of ``P``'s own limb (a camera may never see the limb across the image), blended into
   ``P``'s ``dz`` with ``measurement_depth * k`` and averaged over frames (DEPTH_SMOOTHING); the
   shoulders and hips keep ``P``'s depths.
5. The pose is centred again and its depths follow a constant-velocity (alpha-beta) filter whose
   gain is ``1 - (1 - DEPTH_GAIN) k`` (the foreshortening depth is noisier than ``P``'s, which is
   smoothed already).

Live (the node), the update runs while the track's 2D noise is at most MAX_NOISE: the 2D is then
nearly exact and worth more than the fit's image positions. A real detector's error is correlated
from frame to frame; the noise estimate (second differences of the 2D,
:mod:`pose_lifter.core.track.state`) sees only a part of it (about half the standard deviation at
a correlation of 0.7), so above it the gain of step 3 would follow the detector's slowly changing
error (measured in docs/accuracy.md, its decisions).

Offline (``pose-lifter lift``: :attr:`~pose_lifter.core.track.policy.TrackPolicy.smoothed_later`),
a track's whole 2D is known before its update runs (:mod:`.later`): the update then reads the 2D
smoothed over past and future frames (which halves white 2D noise of 0.05 leg lengths), runs at
every noise level with that smoothed 2D's own noise, and runs forward and backward in time.

Live it is causal (this and earlier frames only); live and offline it is output-only (the track's fits,
warm starts, gate and estimates never see it) and cheap (a few microseconds a frame). Measured
in ``docs/tuning.md`` and docs/accuracy.md.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..model.skeleton import LEFT_LIMBS, LIMB_GROUP_OF, LIMBS, N_JOINTS, RIGHT_LIMBS
from ..numeric.jit import njit

__all__ = ["MAX_NOISE", "MeasurementUpdate", "compile_kernels", "kalman_gain"]

LIMB_A = np.array([a for a, _ in LIMBS])
LIMB_B = np.array([b for _, b in LIMBS])
#: The limbs whose parent joint is a shoulder or hip, then those whose parent is one of theirs.
_ORDER = np.array([i for i, (a, _) in enumerate(LIMBS) if a not in LIMB_B]
                  + [i for i, (a, _) in enumerate(LIMBS) if a in LIMB_B])
#: The update runs on a track whose 2D noise (``Track.noise_median``, the lifter's normalised
#: units; about 0.003 on exact 2D, 0.026 with white noise of 0.02 leg lengths) is at most this.
#: Held-out training-split tracks (tools/accuracy.py --split val --frames 60 --views 2): realistic
#: detector at 6 / 3 m 62.3 / 65.6 -> 61.0 / 63.1 mm, 20 % outliers 52.0 -> 50.9, clean, missing
#: joints unchanged, white noise 0.05 50.3 -> 50.5.
MAX_NOISE = 0.02
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
#: The depth step's length of a limb is at least this share of the pose's own limb (its 3D length):
#: the image's SPAN_QUANTILE underrates a limb the camera never sees across the image (from 50
#: degrees above, a standing person's thighs and shins are foreshortened on every frame), and the
#: share leaves room for the lift's limb proportions being off. Evaluation split, the node /
#: pose-lifter lift, without -> with it: above 43.6 / 39.6 -> 37.1 / 33.3 mm, clean 36.8 / 33.8
#: -> 36.3 / 33.4, every other condition within 0.1 or better (docs/accuracy.md, its decisions).
OWN_LIMB_SHARE = 0.9


@njit
def kalman_gain(q: float, r: float) -> float:
    """The steady-state Kalman gain of a random walk (variance ``q`` per step) observed with noise
    of variance ``r``: 1 without noise, about ``sqrt(q / r)`` when the noise dominates."""
    if r <= 0.0:
        return 1.0
    p = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    return p / (p + r)


@njit
def _column_quantile(rows: NDArray[np.float64], col: int, q: float) -> float:
    """The ``q`` quantile (linear) of the finite values of column ``col`` of ``rows`` (n, m; NaN =
    none), NaN with fewer than SPAN_MIN_FRAMES // 2 of them."""
    values = np.empty(rows.shape[0])
    count = 0
    for i in range(rows.shape[0]):
        if np.isfinite(rows[i, col]):
            values[count] = rows[i, col]
            count += 1
    if count < max(SPAN_MIN_FRAMES // 2, 1):
        return np.nan
    s = np.sort(values[:count])
    pos = q * (count - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, count - 1)
    return float(s[lo] + (pos - lo) * (s[hi] - s[lo]))


_LEFT, _RIGHT, _GROUP = np.array(LEFT_LIMBS), np.array(RIGHT_LIMBS), np.array(LIMB_GROUP_OF)


@njit
def _align_kernel(points: NDArray[np.float64], xy: NDArray[np.float64], use: NDArray[np.bool_],
                  out: NDArray[np.float64]) -> bool:
    """Least squares ``xy ~ s (points - pc) + qc`` over the joints ``use``; ``out`` = (s, pc_x,
    pc_y, qc_x, qc_y) (the two centroids). False with fewer than 3 joints or a degenerate fit."""
    n = 0
    pcx = pcy = qcx = qcy = 0.0
    for j in range(N_JOINTS):
        if use[j]:
            n += 1
            pcx += points[j, 0]
            pcy += points[j, 1]
            qcx += xy[j, 0]
            qcy += xy[j, 1]
    if n < 3:
        return False
    pcx /= n
    pcy /= n
    qcx /= n
    qcy /= n
    den = 0.0
    num = 0.0
    for j in range(N_JOINTS):
        if use[j]:
            px, py = points[j, 0] - pcx, points[j, 1] - pcy
            den += px * px + py * py
            num += px * (xy[j, 0] - qcx) + py * (xy[j, 1] - qcy)
    if not den > 0.0 or not num > 0.0:
        return False
    out[0], out[1], out[2], out[3], out[4] = num / den, pcx, pcy, qcx, qcy
    return True


class TrackArrays(NamedTuple):
    """One track's state of the update as its kernels read and write it (in place)."""

    offset: NDArray[np.float64]  #: (12, 2) each joint's x, y offset from the pose
    #: (6,) log scale, centre x, centre y, frames with a centre, frames published, depth filter on
    state: NDArray[np.float64]
    prev_points: NDArray[np.float64]  #: (12, 2) the last centred frame's 2D
    prev_updated: NDArray[np.bool_]  #: (12,) the joints it updated
    last: NDArray[np.float64]  #: (12, 3) the last published pose
    last2: NDArray[np.float64]  #: (12, 3) the one before
    depth_offset: NDArray[np.float64]  #: (12,) each joint's depth offset from the pose
    depth_level: NDArray[np.float64]  #: (12,) the depth filter's level
    depth_velocity: NDArray[np.float64]  #: (12,) and velocity
    ok: NDArray[np.bool_]  #: (12,) the joints updated on this frame
    span_row: NDArray[np.float64]  #: (8,) this frame's aligned limb lengths (NaN: not both updated)
    spans: NDArray[np.float64]  #: (SPAN_FRAMES, 8) the last frames' span rows, a ring (NaN: none)
    #: (3,) span rows kept, ``spans`` count when ``limbs`` was last estimated, ``limbs`` valid (1/0)
    meta: NDArray[np.float64]
    limbs: NDArray[np.float64]  #: (8,) the track's limb lengths from the image (:func:`_limb_lengths`)


@njit
def _gated_alignment(pose: NDArray[np.float64], points: NDArray[np.float64], used: NDArray[np.bool_],
                     gate: float, ok: NDArray[np.bool_], al: NDArray[np.float64]) -> bool:
    """Steps 1-2 of the module docstring: the alignment ``al`` (5,) of the ``used`` 2D ``points``
    (12, 2) onto ``pose``'s x, y (:func:`_align_kernel`), redone without the joints beyond
    ``gate``; ``ok`` (12,) the joints kept (none when the alignment fails). Returns whether it
    succeeded."""
    n_used = 0
    for j in range(N_JOINTS):
        ok[j] = False
        n_used += used[j]
    aligned = _align_kernel(points, pose[:, :2], used, al)
    if aligned:
        n_ok = 0
        for j in range(N_JOINTS):
            if used[j]:
                rx = al[0] * (points[j, 0] - al[1]) + al[3] - pose[j, 0]
                ry = al[0] * (points[j, 1] - al[2]) + al[4] - pose[j, 1]
                ok[j] = rx * rx + ry * ry <= gate * gate
                n_ok += ok[j]
        if n_ok < n_used:
            aligned = _align_kernel(points, pose[:, :2], ok, al)
            if not aligned:
                for j in range(N_JOINTS):
                    ok[j] = False
    return aligned


@njit
def _held_offsets(pose: NDArray[np.float64], tr: TrackArrays) -> NDArray[np.float64]:
    """The offsets (12, 2) of joints not updated on this frame: HOLD of the way from ``pose`` to
    where the track predicts them (its last published x, y plus HOLD_VELOCITY of its last
    motion; before any frame, the pose plus its offset)."""
    held = np.empty((N_JOINTS, 2))
    frames = tr.state[4]
    for j in range(N_JOINTS):
        for c in range(2):
            predicted = pose[j, c] + tr.offset[j, c]
            if frames >= 1:
                predicted = tr.last[j, c]
                if frames >= 2:
                    predicted += HOLD_VELOCITY * (tr.last[j, c] - tr.last2[j, c])
            held[j, c] = HOLD * (predicted - pose[j, c])
    return held


@njit
def _image_frame(points: NDArray[np.float64], al: NDArray[np.float64], tr: TrackArrays
                 ) -> tuple[float, float, float]:
    """Step 1's scale and image centre ``(s, c_x, c_y)`` of this frame from its alignment ``al``
    (5,): the scale averaged in logs over frames (SCALE_SMOOTHING), the centre blended
    (SHIFT_SMOOTHING) with the last one moved by the median image motion of the joints updated on
    both frames (at least 3); written into the track's ``state``."""
    state, ok, prev_updated, prev_points = tr.state, tr.ok, tr.prev_updated, tr.prev_points
    ls = math.log(al[0])
    if state[3] > 0:
        ls = SCALE_SMOOTHING * state[0] + (1.0 - SCALE_SMOOTHING) * ls
    state[0] = ls
    scale = math.exp(ls)
    cx = al[1] - al[3] / scale  # the image point at the pose's origin
    cy = al[2] - al[4] / scale
    if state[3] > 0:
        n_both = 0
        for j in range(N_JOINTS):
            n_both += ok[j] and prev_updated[j]
        if n_both >= 3:
            mx = np.empty(n_both)
            my = np.empty(n_both)
            i = 0
            for j in range(N_JOINTS):
                if ok[j] and prev_updated[j]:
                    mx[i] = points[j, 0] - prev_points[j, 0]
                    my[i] = points[j, 1] - prev_points[j, 1]
                    i += 1
            cx = SHIFT_SMOOTHING * (state[1] + np.median(mx)) + (1.0 - SHIFT_SMOOTHING) * cx
            cy = SHIFT_SMOOTHING * (state[2] + np.median(my)) + (1.0 - SHIFT_SMOOTHING) * cy
    state[1], state[2], state[3] = cx, cy, state[3] + 1
    return scale, cx, cy


@njit
def _observe(pose: NDArray[np.float64], points: NDArray[np.float64], k: float, held: NDArray[np.float64],
             frame: tuple[float, float, float], tr: TrackArrays) -> None:
    """Step 3 on an aligned frame: each updated joint's offset follows its 2D in the pose's frame
    (``frame`` = :func:`_image_frame`'s) with the gain ``k``, the others take their ``held``
    offset; the frame's 2D, updated joints and aligned limb lengths (``span_row``) kept."""
    scale, cx, cy = frame
    ok, offset, span_row = tr.ok, tr.offset, tr.span_row
    obs = np.empty((N_JOINTS, 2))
    for j in range(N_JOINTS):
        obs[j, 0] = scale * (points[j, 0] - cx)
        obs[j, 1] = scale * (points[j, 1] - cy)
        tr.prev_points[j, 0], tr.prev_points[j, 1] = points[j, 0], points[j, 1]
        tr.prev_updated[j] = ok[j]
        for c in range(2):
            if ok[j]:
                offset[j, c] += k * (obs[j, c] - pose[j, c] - offset[j, c])
            else:
                offset[j, c] = held[j, c]
    for i in range(LIMB_A.shape[0]):
        a, b = LIMB_A[i], LIMB_B[i]
        if ok[a] and ok[b]:
            dx, dy = obs[b, 0] - obs[a, 0], obs[b, 1] - obs[a, 1]
            span_row[i] = math.sqrt(dx * dx + dy * dy)
        else:
            span_row[i] = np.nan


@njit
def _xy_kernel(pose: NDArray[np.float64], points: NDArray[np.float64], used: NDArray[np.bool_], gate: float,
               k: float, tr: TrackArrays, out: NDArray[np.float64]) -> bool:
    """Steps 1-3 of the module docstring on the track's arrays ``tr``: ``out`` (12, 3) = ``pose``
    with x, y moved by the new offsets; ``tr.ok`` the joints updated (gate ``gate``, gain ``k``);
    ``tr.span_row`` (8,) this frame's aligned limb lengths. Returns whether anything was updated
    (a span row made)."""
    al = np.empty(5)
    aligned = _gated_alignment(pose, points, used, gate, tr.ok, al)
    any_ok = False
    for j in range(N_JOINTS):
        any_ok = any_ok or tr.ok[j]
    held = _held_offsets(pose, tr)
    if aligned and any_ok:
        _observe(pose, points, k, held, _image_frame(points, al, tr), tr)
    else:
        for j in range(N_JOINTS):
            tr.offset[j, 0], tr.offset[j, 1] = held[j, 0], held[j, 1]
    for j in range(N_JOINTS):
        out[j, 0] = pose[j, 0] + tr.offset[j, 0]
        out[j, 1] = pose[j, 1] + tr.offset[j, 1]
        out[j, 2] = pose[j, 2]
    return aligned and any_ok


@njit
def _depth_kernel(pose: NDArray[np.float64], out: NDArray[np.float64], limbs: NDArray[np.float64],
                  beta: float, gain: float, tr: TrackArrays) -> None:
    """Steps 4-5: ``out``'s depths (in place, centred after) for the joints ``tr.ok`` updated;
    ``limbs`` (8,) or empty (no depth step), ``beta`` the weight of their depth; the alpha-beta
    filter (gain ``gain``) starts when ``tr.state[5]`` is 0."""
    ok, depth_offset, state = tr.ok, tr.depth_offset, tr.state
    level, velocity = tr.depth_level, tr.depth_velocity
    prev = depth_offset.copy()
    for j in range(N_JOINTS):
        depth_offset[j] = HOLD * prev[j]
    if limbs.shape[0] > 0:
        z = np.empty(N_JOINTS)
        for j in range(N_JOINTS):
            z[j] = pose[j, 2] + depth_offset[j]
        for i in _ORDER:  # the upper limbs, then the lower ones from their new depths
            a, b = LIMB_A[i], LIMB_B[i]
            if not (ok[a] and ok[b]):
                continue
            dz = pose[b, 2] - pose[a, 2]
            dx, dy = out[b, 0] - out[a, 0], out[b, 1] - out[a, 1]
            ex, ey = pose[b, 0] - pose[a, 0], pose[b, 1] - pose[a, 1]  # the pose's own limb: (ex, ey, dz)
            length = max(limbs[i], OWN_LIMB_SHARE * math.sqrt(ex * ex + ey * ey + dz * dz))
            mag = math.sqrt(max(length * length - dx * dx - dy * dy, 0.0))
            want = z[a] + (1.0 - beta) * dz + beta * (mag if dz >= 0 else -mag)
            depth_offset[b] = DEPTH_SMOOTHING * prev[b] + (1.0 - DEPTH_SMOOTHING) * (want - pose[b, 2])
            z[b] = pose[b, 2] + depth_offset[b]
    mean = np.zeros(3)
    for j in range(N_JOINTS):
        out[j, 2] = pose[j, 2] + depth_offset[j]
        for c in range(3):
            mean[c] += out[j, c] / N_JOINTS
    for j in range(N_JOINTS):
        for c in range(3):
            out[j, c] -= mean[c]
    h = gain * gain / (2.0 - gain)
    zmean = 0.0
    for j in range(N_JOINTS):
        if state[5] == 0:
            level[j] = out[j, 2]
            velocity[j] = 0.0
        else:
            predicted = level[j] + velocity[j]
            resid = out[j, 2] - predicted
            level[j] = predicted + gain * resid
            velocity[j] += h * resid
        zmean += level[j] / N_JOINTS
    state[5] = 1
    for j in range(N_JOINTS):
        out[j, 2] = level[j] - zmean


@njit
def _reset(tr: TrackArrays) -> None:
    """The state of a track not updated yet, in place."""
    for a in (tr.offset, tr.prev_points, tr.last, tr.last2):
        a[:] = 0.0
    for b in (tr.depth_offset, tr.depth_level, tr.depth_velocity, tr.state):
        b[:] = 0.0
    tr.prev_updated[:] = False
    tr.ok[:] = False
    tr.spans[:] = np.nan
    tr.meta[0], tr.meta[1], tr.meta[2] = 0.0, -SPAN_EVERY, 0.0


@njit
def _limb_lengths(tr: TrackArrays) -> bool:
    """Whether the track has limb lengths from the image (``tr.limbs``): the SPAN_QUANTILE of each
    limb's span rows, left and right averaged, re-estimated every SPAN_EVERY rows; none before
    SPAN_MIN_FRAMES rows or with a limb seen too rarely."""
    n_spans = int(tr.meta[0])
    if n_spans < SPAN_MIN_FRAMES:
        return False
    if n_spans >= tr.meta[1] + SPAN_EVERY:
        rows = tr.spans[: min(n_spans, SPAN_FRAMES)]
        est = np.empty(len(LIMBS))
        for i in range(len(LIMBS)):
            est[i] = _column_quantile(rows, i, SPAN_QUANTILE)
        valid = True
        for i in range(len(LIMBS)):
            g = _GROUP[i]
            tr.limbs[i] = 0.5 * (est[_LEFT[g]] + est[_RIGHT[g]])
            valid = valid and np.isfinite(tr.limbs[i])
        tr.meta[1], tr.meta[2] = n_spans, 1.0 if valid else 0.0
    return bool(tr.meta[2] > 0.0)


@njit
def _update_frame(pose: NDArray[np.float64], points: NDArray[np.float64], used: NDArray[np.bool_],
                  noise: float, depth: float, gate: float, tr: TrackArrays, out: NDArray[np.float64]) -> None:
    """One frame of the update (:meth:`MeasurementUpdate.update`, its arguments) on the track's
    arrays ``tr``: ``out`` (12, 3) the published pose."""
    k = kalman_gain(DRIFT * DRIFT, noise * noise)
    if _xy_kernel(pose, points, used, max(gate, GATE_NOISE_FACTOR * noise), k, tr, out):
        tr.spans[int(tr.meta[0]) % SPAN_FRAMES] = tr.span_row
        tr.meta[0] += 1
    has_limbs = _limb_lengths(tr) if depth > 0 else False
    gain = 1.0 - (1.0 - DEPTH_GAIN) * k
    _depth_kernel(pose, out, tr.limbs if has_limbs else tr.limbs[:0], depth * k, gain, tr)
    tr.last2[:] = tr.last
    tr.last[:] = out
    tr.state[4] += 1


@njit
def _run_kernel(poses: NDArray[np.float64], points: NDArray[np.float64], used: NDArray[np.bool_],
                noise: NDArray[np.float64], restart: NDArray[np.bool_], order: NDArray[np.int64],
                depth: float, gate: float, tr: TrackArrays, out: NDArray[np.float64], done: NDArray[np.bool_]
                ) -> None:
    """:meth:`MeasurementUpdate.run`'s frames in ``order`` on the track's arrays ``tr``."""
    for i in order:
        done[i] = False
        if restart[i]:
            _reset(tr)
        if not np.isfinite(noise[i]):
            continue
        _update_frame(poses[i], points[i], used[i], noise[i], depth, gate, tr, out[i])
        if np.isfinite(out[i]).all():
            done[i] = True
        else:
            _reset(tr)


def _f64(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.ascontiguousarray(a, dtype=np.float64)


def _bool(a: NDArray[np.bool_]) -> NDArray[np.bool_]:
    return np.ascontiguousarray(a, dtype=np.bool_)


class MeasurementUpdate:
    """One track's state of the measurement update (module docstring): :meth:`update` per frame,
    :meth:`run` over a sequence of frames."""

    def __init__(self) -> None:
        n, m = N_JOINTS, len(LIMBS)
        self.arrays = TrackArrays(
            offset=np.zeros((n, 2)), state=np.zeros(6), prev_points=np.zeros((n, 2)),
            prev_updated=np.zeros(n, dtype=bool), last=np.zeros((n, 3)), last2=np.zeros((n, 3)),
            depth_offset=np.zeros(n), depth_level=np.zeros(n), depth_velocity=np.zeros(n),
            ok=np.zeros(n, dtype=bool), span_row=np.empty(m), spans=np.full((SPAN_FRAMES, m), np.nan),
            meta=np.array([0.0, -SPAN_EVERY, 0.0]), limbs=np.full(m, np.nan))

    def copy(self) -> MeasurementUpdate:
        """An independent copy of the state (its arrays copied)."""
        out = MeasurementUpdate.__new__(MeasurementUpdate)
        out.arrays = TrackArrays._make(a.copy() for a in self.arrays)
        return out

    def limb_lengths(self) -> NDArray[np.float64] | None:
        """The track's limb lengths from the image (8,; left and right averaged; model units), or
        None before SPAN_MIN_FRAMES frames or with a limb seen too rarely."""
        return self.arrays.limbs.copy() if _limb_lengths(self.arrays) else None

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
        out = np.empty((N_JOINTS, 3))
        _update_frame(_f64(pose), _f64(points), _bool(used), float(noise), float(depth), float(gate),
                      self.arrays, out)
        return out

    def run(self, poses: NDArray[np.float64], points: NDArray[np.float64], used: NDArray[np.bool_],
            noise: NDArray[np.float64], order: NDArray[np.int64], depth: float, gate: float,
            restart: NDArray[np.bool_] | None = None) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """:meth:`update` of a sequence of frames in one call, in ``order``.

        Parameters
        ----------
        poses, points, used : ndarray, shapes (T, 12, 3), (T, 12, 2), (T, 12)
            Per frame, :meth:`update`'s ``pose``, ``points`` and ``used``.
        noise : ndarray, shape (T,)
            Per frame its noise; NaN: not known, the frame is skipped (the state unchanged).
        order : ndarray of int, shape (K,)
            The frames to take, in the order taken (e.g. backward in time).
        depth, gate : float
            As :meth:`update`.
        restart : ndarray of bool, shape (T,), optional
            Frames before which the state starts again (as a new ``MeasurementUpdate``).

        Returns
        -------
        out : ndarray, shape (T, 12, 3)
            Each frame's published pose (rows of frames not done undefined).
        done : ndarray of bool, shape (T,)
            The frames updated: taken, with a noise, and finite. A non-finite update starts
            the state again (the next frame is the first of a new track).
        """
        n = poses.shape[0]
        out = np.empty((n, N_JOINTS, 3))
        done = np.zeros(n, dtype=np.bool_)
        _run_kernel(_f64(poses), _f64(points), _bool(used), _f64(noise),
                    np.zeros(n, dtype=np.bool_) if restart is None else _bool(restart),
                    np.ascontiguousarray(order, dtype=np.int64), float(depth), float(gate), self.arrays, out,
                    done)
        return out, done


_COMPILED = False


def compile_kernels() -> None:
    """Compile this module's kernels (numba, ``core.numeric.jit``) or load them from their cache, once
    per process: updates of a still pose, frame by frame and as a run (a track's first frame
    would otherwise pay for it)."""
    global _COMPILED
    if _COMPILED:
        return
    update = MeasurementUpdate()
    pose = np.zeros((N_JOINTS, 3))
    pose[:, 0] = np.arange(N_JOINTS) % 3
    pose[:, 1] = np.arange(N_JOINTS) // 3
    pose -= pose.mean(axis=0)
    for _ in range(SPAN_MIN_FRAMES + 1):
        update.update(pose, 100.0 * pose[:, :2], np.ones(N_JOINTS, dtype=bool), 0.01, 0.5, 0.3)
    update.run(pose[None], 100.0 * pose[None, :, :2], np.ones((1, N_JOINTS), dtype=bool), np.array([0.01]),
               np.zeros(1, dtype=np.int64), 0.5, 0.3)
    _COMPILED = True
