"""The screening of a frame's tracked people before their lift (hybrid mode, a frame that follows
its track's last one), as one compiled pass over the frame's people: where each track puts the
joints on this frame, the temporal outlier gate (``LifterOptions.outlier_gate``: a joint that
jumped is missing for this frame) and each track's 2D noise estimate
(:data:`~pose_lifter.core.track.state.NOISE_FRAMES`); and the next frames an offline lift's prior
reads, screened by the same gate (:func:`next_frames`). :mod:`pose_lifter.core.track.policy`
screens a frame's people with :func:`screen_frames`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..model.skeleton import N_JOINTS
from ..numeric.jit import njit
from .state import (
    GATE_MAX_AGE_NS,
    GATE_NOISE_FACTOR,
    SCREEN_LIMITS,
    Track,
    label_check,
    swap_back,
    visible_joints,
)

if TYPE_CHECKING:
    from ..lift.lifter import Lifter
    from ..results import Frames
    from .records import FramesAhead

__all__ = ["Screened", "ToScreen", "compile_kernels", "next_frames", "screen_frames"]

_SQRT6 = math.sqrt(6.0)


class ToScreen(NamedTuple):
    """One person's frame to screen (:func:`screen_frames`)."""

    track: Track | None  #: its track (None: untracked or new)
    follows: bool  #: the frame is warm-started from its track's last one
    lifter: Lifter  #: the lifter of its track's policy (options, the noise's normalised units)
    points: NDArray[np.float64]  #: (12, 2), input units
    confidence: NDArray[np.float64] | None  #: (12,)
    stamp_ns: int


@dataclass(frozen=True)
class Screened:
    """A frame after its screening."""

    #: the confidence the lifter reads (a gated joint's set to 0)
    confidence: NDArray[np.float64] | None
    #: the joints visible and not gated (12,) (None: malformed input)
    visible: NDArray[np.bool_] | None
    #: where the track puts each joint (12, 2), input units (None: not known)
    predicted: NDArray[np.float64] | None
    #: the temporal outlier gate screened the frame
    gated: bool
    #: the arms' and the legs' left and right labels swapped back (2,; ``LifterOptions.label_swaps``;
    #: None: the frame's own labels): the lift reads :func:`~.state.swap_back` of the frame's 2D
    swapped: NDArray[np.bool_] | None = None


def screen_frames(frames: Sequence[ToScreen]) -> list[Screened]:
    """Each frame screened (distinct tracks): the hybrid frames that follow their tracks in one
    pass (:func:`_screen_tracks`, which also adds each track's 2D noise), the others as they
    come (their visible joints, by the lifter's confidence threshold)."""
    out: list[Screened | None] = [None] * len(frames)
    rows: list[tuple[int, NDArray[np.bool_]]] = []
    for i, f in enumerate(frames):
        opts = f.lifter.options
        hybrid = opts.mode == "hybrid"
        # the frame's visible joints (None for malformed input: the lifter refuses it with the reason)
        vis = visible_joints(f.points, f.confidence, opts.confidence_threshold)
        if hybrid and f.track is not None and f.follows and vis is not None:
            rows.append((i, vis))
            continue
        out[i] = Screened(f.confidence, vis, None, False)
    if rows:
        got = [frames[i] for i, _ in rows]
        s = _screen_tracks([f.track for f in got if f.track is not None], [f.lifter for f in got],
                           np.array([f.points for f in got], dtype=np.float64),
                           np.array([v for _, v in rows]), [f.stamp_ns for f in got],
                           [f.lifter.options.outlier_gate for f in got],
                           [f.lifter.options.min_visible_joints for f in got],
                           [f.lifter.options.label_swaps for f in got])
        for r, ((i, _), f) in enumerate(zip(rows, got, strict=True)):
            opts, confidence = f.lifter.options, f.confidence
            swapped = None
            if s.swapped[r].any():  # the labels as the track has them
                swapped = s.swapped[r].copy()
                confidence = None if confidence is None else swap_back(confidence, swapped)
            if s.gated[r].any():  # a gated joint is missing for this frame
                confidence = np.where(s.gated[r], 0.0, np.ones(N_JOINTS) if confidence is None
                                      else np.asarray(confidence, dtype=np.float64))
            out[i] = Screened(confidence, s.visible[r], s.predicted[r] if s.has_prediction[r] else None,
                              opts.outlier_gate > 0, swapped)
    return [x for x in out if x is not None]


def next_frames(lifter: Lifter, track: Track | None, ahead: FramesAhead | None, stamp_ns: int,
                past: Frames | None, current: NDArray[np.float64], frame: Screened) -> Frames | None:
    """The next frames a temporal prior with future frames reads (``lifter``'s; with ``past``: the
    frames of ``ahead`` evenly spaced on from ``stamp_ns`` at the step of the track's last frame,
    within 20 %, as :meth:`Track.past`; each frame's visible joints by the confidence threshold
    and, on a frame the temporal gate screened, :meth:`Track.screen_ahead` from this frame's 2D
    ``current`` (12, 2)), or None."""
    if ahead is None or track is None or past is None:
        return None
    temporal = lifter.temporal_prior
    if temporal is None or not temporal.future_frames:
        return None
    step = stamp_ns - track.last_stamp_ns
    n, last = 0, stamp_ns  # the next frames up to the first uneven step (a few: plain ints)
    for t in np.asarray(ahead.stamps_ns[:temporal.future_frames], dtype=np.int64).tolist():
        if abs(t - last - step) > 0.2 * step:
            break
        n, last = n + 1, t
    if n == 0:
        return None
    frames = np.asarray(ahead.points[:n], dtype=np.float64)
    seen = visible_joints(frames, None if ahead.confidence is None else ahead.confidence[:n],
                          lifter.options.confidence_threshold)
    if seen is None or frames.ndim != 3:
        return None
    if frame.gated and frame.visible is not None and frame.predicted is not None:
        # the label check and the temporal gate over the next frames too: their swaps and
        # confident outliers stay out
        frames, seen = track.screen_ahead(current, frame.visible, frame.predicted, frames, seen,
                                          lifter.options.outlier_gate, lifter.options.label_swaps)
    return frames, seen

class _Screening(NamedTuple):
    """:func:`_screen_tracks`' answer: one row per frame of a tracked person (n rows)."""

    #: the joints visible and not gated, (n, 12)
    visible: NDArray[np.bool_]
    #: the joints the temporal outlier gate removed, (n, 12) (a row of False: none)
    gated: NDArray[np.bool_]
    #: where the track puts each joint on this frame, (n, 12, 2), input units: where the last
    #: frame had it (its detection when the lift used it, else the fit's projection) moved by the
    #: median motion of this frame's joints kept since (the person's or the camera's); NaN rows
    #: without a last frame at most GATE_MAX_AGE_NS old or without a visible joint
    predicted: NDArray[np.float64]
    #: (n,) the row has a prediction
    has_prediction: NDArray[np.bool_]
    #: (n, 2) the arms' and the legs' labels were swapped back (``visible``, ``gated`` and
    #: ``predicted`` are of the 2D with them swapped)
    swapped: NDArray[np.bool_]


def _screen_tracks(tracks: Sequence[Track], lifters: Sequence[Lifter], points: NDArray[np.float64],
                  visible: NDArray[np.bool_], stamps_ns: Sequence[int], gate_limits: Sequence[float],
                  min_visible: Sequence[int], label_swaps: Sequence[bool]) -> _Screening:
    """The temporal screening of n tracked people's frames, each following its track's last one
    (distinct tracks), in one compiled pass: where each track puts the joints, the left/right
    label check, the temporal outlier gate, and the track's 2D noise (see NOISE_FRAMES).

    The label check (rows with ``label_swaps[i]`` and a prediction): an arm's or a leg's left
    and right labels are swapped back when the track puts its joints far better swapped
    (SWAP_RATIO, SWAP_MARGIN; at most SWAP_MAX_FRAMES frames in a row). A detector confuses a
    person's sides now and then (a limb crossing the other, a person seen from behind); a
    swapped arm near the other one passes the gate and would be lifted on the wrong side. The
    prediction, the gate and the noise then read the 2D with the labels swapped back.

    The gate (row ``i`` with ``gate_limits[i] > 0``): the visible joints farther than
    ``gate_limits[i]`` leg lengths (or GATE_NOISE_FACTOR times the track's noise) from where the
    track puts them are missing for this frame, and the prediction is made again from the joints
    kept; not when that would leave fewer than ``min_visible[i]`` joints or gate more than
    GATE_MAX_FRACTION of the visible ones (the prediction, not the detector, is then wrong), and
    a joint is gated on at most GATE_MAX_FRAMES frames in a row. A constant-velocity prediction was
    measured worse: the fits' jitter doubles in it (7 % of good joints beyond 0.8 leg on held-out
    tracks with 20 % outliers, against 2 % for the last position). The noise: this frame's 2D
    acceleration over the joints kept and seen on the track's last two frames, when the three
    frames are evenly spaced in time (within 20 %), over the lifter's input scale.

    Parameters
    ----------
    tracks, lifters : sequences of n
        Each frame's track and the lifter of its policy (the noise's normalised units).
    points : ndarray, shape (n, 12, 2)
        The frames' 2D, input units.
    visible : ndarray of bool, shape (n, 12)
        Their visible joints (finite, confident).
    stamps_ns, gate_limits, min_visible, label_swaps : sequences of n
        The frames' stamps; the gate's limit in leg lengths (<= 0: no gate), the fewest joints it
        may leave and whether the labels are checked (the policy's options).
    """
    n = len(tracks)
    pts = np.zeros((n, 4, N_JOINTS, 2))  # this frame, the last fit's positions, the last two frames
    masks = np.zeros((n, 3, N_JOINTS), dtype=np.bool_)  # visible; the last two frames' joints used
    rows = np.zeros((n, 3))  # the last fit's scale, the gate's limit, the fewest joints it leaves
    # a last fit to predict from, gate, observe the noise, check the labels
    flags = np.zeros((n, 4), dtype=np.bool_)
    counters = np.empty((n, N_JOINTS + 2), dtype=np.int64)  # frames gated, then swapped, in a row
    pts[:, 0] = points
    masks[:, 0] = visible
    flags[:, 3] = label_swaps
    for i, (track, stamp) in enumerate(zip(tracks, stamps_ns, strict=True)):
        counters[i, :N_JOINTS] = track.gated
        counters[i, N_JOINTS:] = track.swapped
        if track.fits:
            t1, p1, scale = track.fits[-1]
            if 0 < stamp - t1 <= GATE_MAX_AGE_NS:
                pts[i, 1] = p1
                rows[i, 0] = scale
                flags[i, 0] = True
        if gate_limits[i] > 0:
            flags[i, 1] = True
            rows[i, 1] = max(gate_limits[i], GATE_NOISE_FACTOR * track.noise_level())
            rows[i, 2] = min_visible[i]
        if len(track.history) >= 2:
            (t0, x0, v0), (t1, x1, v1) = track.history[-2], track.history[-1]
            d1, d2 = t1 - t0, stamp - t1
            if d1 > 0 and d2 > 0 and abs(d2 - d1) <= 0.2 * d1:
                pts[i, 2], pts[i, 3] = x1, x0
                masks[i, 1], masks[i, 2] = v1, v0
                flags[i, 2] = True
    kept, gated, predicted, has_prediction, swapped, acc, noise_vis = _screen_kernel(
        pts, masks, rows, flags, counters, SCREEN_LIMITS)
    spread = np.full(n, np.nan)
    for lifter in {id(x): x for x in lifters}.values():  # the frames of each lifter together
        rows = np.array([i for i, x in enumerate(lifters) if x is lifter and not math.isnan(acc[i])],
                        dtype=np.int64)
        if rows.size:
            spread[rows] = lifter.input_scales(pts[rows, 0], noise_vis[rows].astype(np.float64))
    for i, track in enumerate(tracks):
        track.gated = counters[i, :N_JOINTS]
        track.swapped = counters[i, N_JOINTS:]
        if not math.isnan(acc[i]) and not math.isnan(spread[i]):
            track.noise.append(float(acc[i]) / float(spread[i]))
            track._noise_median = None
    return _Screening(kept, gated, predicted, has_prediction, swapped)


@njit
def _screen_kernel(pts: NDArray[np.float64], masks: NDArray[np.bool_], rows: NDArray[np.float64],
                   flags: NDArray[np.bool_], counters: NDArray[np.int64], limits: NDArray[np.float64]
                   ) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.float64], NDArray[np.bool_],
                              NDArray[np.bool_], NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`_screen_tracks`' pass over its rows (its arrays, named there; ``limits``: the gate's
    largest fraction and its most frames in a row, the label check's most frames in a row, ratio
    and margin). Swaps the labels of ``pts[:, 0]`` in place where the check says so; updates
    ``counters`` (n, 14: each joint's frames gated in a row, then the arms' and the legs' frames
    swapped in a row) in place; returns the joints kept (n, 12), those gated (n, 12), the
    predictions (n, 12, 2) and which rows have one (n,), the groups swapped (n, 2), and each
    row's noise observation (n,; NaN: none) with the joints it was taken over (n, 12)."""
    n, nj = pts.shape[0], pts.shape[2]
    kept = masks[:, 0].copy()
    gated = np.zeros((n, nj), dtype=np.bool_)
    predicted = np.full((n, nj, 2), np.nan)
    has_prediction = np.zeros(n, dtype=np.bool_)
    swapped = np.zeros((n, 2), dtype=np.bool_)
    acc = np.full(n, np.nan)
    noise_vis = np.zeros((n, nj), dtype=np.bool_)
    for i in range(n):
        x = pts[i, 0]
        if flags[i, 0] and _predict(x, kept[i], pts[i, 1], predicted[i]):
            has_prediction[i] = True
            if flags[i, 3] and label_check(x, kept[i], predicted[i], rows[i, 0], counters[i, nj:], swapped[i],
                                           limits):
                _predict(x, kept[i], pts[i, 1], predicted[i])
            if flags[i, 1] and _gate(x, kept[i], predicted[i], rows[i], counters[i, :nj], gated[i], limits):
                for j in range(nj):
                    kept[i, j] = kept[i, j] and not gated[i, j]
                has_prediction[i] = _predict(x, kept[i], pts[i, 1], predicted[i])
        if flags[i, 2]:
            acc[i] = _acceleration(pts[i], masks[i], kept[i], noise_vis[i])
    return kept, gated, predicted, has_prediction, swapped, acc, noise_vis


@njit
def _median_sorted(s: NDArray[np.float64]) -> float:
    """The median of sorted values ``s`` (at least one): the middle one or the mean of the two."""
    m = s.size // 2
    return float(s[m]) if s.size % 2 else (s[m - 1] + s[m]) / 2.0


@njit
def _predict(x: NDArray[np.float64], vis: NDArray[np.bool_], last: NDArray[np.float64],
             out: NDArray[np.float64]) -> bool:
    """``out`` (12, 2) = ``last`` moved by the median motion ``x - last`` of the joints ``vis``
    (per axis); False (``out`` NaN) without a visible joint."""
    k = 0
    for j in range(vis.size):
        if vis[j]:
            k += 1
    if k == 0:
        out[:] = np.nan
        return False
    dx, dy = np.empty(k), np.empty(k)
    k = 0
    for j in range(vis.size):
        if vis[j]:
            dx[k], dy[k] = x[j, 0] - last[j, 0], x[j, 1] - last[j, 1]
            k += 1
    mx, my = _median_sorted(np.sort(dx)), _median_sorted(np.sort(dy))
    for j in range(vis.size):
        out[j, 0], out[j, 1] = last[j, 0] + mx, last[j, 1] + my
    return True


@njit
def _gate(x: NDArray[np.float64], vis: NDArray[np.bool_], predicted: NDArray[np.float64],
          row: NDArray[np.float64], counters: NDArray[np.int64], out: NDArray[np.bool_],
          limits: NDArray[np.float64]) -> bool:
    """The gate of one frame (see :func:`_screen_tracks`; ``row``: the last fit's scale, the limit
    in leg lengths, the fewest joints kept): sets ``out`` (12,) and ``counters``; False (``out``
    all False, ``counters`` 0) when nothing is gated."""
    den = max(row[0], 1e-12)
    n_out, n_vis = 0, 0
    for j in range(vis.size):
        if vis[j]:
            n_vis += 1
            dx, dy = x[j, 0] - predicted[j, 0], x[j, 1] - predicted[j, 1]
            if math.sqrt(dx * dx + dy * dy) / den > row[1] and counters[j] < limits[1]:
                out[j] = True
                n_out += 1
    if n_out == 0 or n_vis - n_out < row[2] or n_out > limits[0] * n_vis:
        out[:] = False
        counters[:] = 0
        return False
    for j in range(vis.size):
        counters[j] = counters[j] + 1 if out[j] else 0
    return True


@njit
def _acceleration(pts: NDArray[np.float64], masks: NDArray[np.bool_], vis: NDArray[np.bool_],
                  used: NDArray[np.bool_]) -> float:
    """The median over joints of ``|x_t - 2 x_{t-1} + x_{t-2}| / sqrt(6)`` (``pts[0]``,
    ``pts[2]``, ``pts[3]``) over the joints ``vis`` seen on the last two frames (``masks[1]``,
    ``masks[2]``), which it sets in ``used``; NaN with fewer than 3."""
    k = 0
    for j in range(vis.size):
        used[j] = vis[j] and masks[1, j] and masks[2, j]
        if used[j]:
            k += 1
    if k < 3:
        return np.nan
    acc = np.empty(k)
    k = 0
    for j in range(vis.size):
        if used[j]:
            ax = pts[0, j, 0] - 2.0 * pts[2, j, 0] + pts[3, j, 0]
            ay = pts[0, j, 1] - 2.0 * pts[2, j, 1] + pts[3, j, 1]
            acc[k] = math.sqrt(ax * ax + ay * ay) / _SQRT6
            k += 1
    return _median_sorted(np.sort(acc))



def compile_kernels() -> None:
    """Compile this module's kernel (numba, ``core.numeric.jit``) or load it from its cache: the
    screening of one still frame (a node's first tracked frame would otherwise pay for it)."""
    still = np.zeros((1, 4, N_JOINTS, 2))
    masks = np.ones((1, 3, N_JOINTS), dtype=np.bool_)
    _screen_kernel(still, masks, np.array([[1.0, 1.0, 6.0]]), np.ones((1, 4), dtype=np.bool_),
                   np.zeros((1, N_JOINTS + 2), dtype=np.int64), SCREEN_LIMITS)
