"""The state of one tracked person (:class:`Track`) and the rules that read it: the track's 2D
noise estimate, its limb proportions (from the learned prior's poses, calibrated, and from the
image), the temporal outlier gate, where each joint should be on the next frame, and the evenly
spaced past frames a temporal prior reads. :class:`pose_lifter.core.track.policy.TrackPolicy` keeps
one per track id.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from ..model.skeleton import (
    COUNTERPART,
    JOINTS_LEFT,
    LEFT_LIMBS,
    LIMB_GROUP_OF,
    LIMBS,
    N_JOINTS,
    RIGHT_LIMBS,
)
from ..numeric.fast import row_norms
from ..numeric.jit import njit
from .measurement import MAX_NOISE, MeasurementUpdate
from .smoothing import CausalSmoother

if TYPE_CHECKING:
    from ..results import LiftResult, WarmStart

__all__ = ["Track", "calibrated_limb_proportions", "image_spans", "label_check", "swap_back",
           "tracks_limb_proportions", "visible_joints"]

LIMB_A = np.array([a for a, _ in LIMBS])
LIMB_B = np.array([b for _, b in LIMBS])
_LEFT_LIMBS = np.array(LEFT_LIMBS)
_RIGHT_LIMBS = np.array(RIGHT_LIMBS)
_GROUP_OF = np.array(LIMB_GROUP_OF)


#: Detector noise: per frame, the median over joints of the 2D input's acceleration
#: ``|x_t - 2 x_{t-1} + x_{t-2}| / sqrt(6)`` (three evenly spaced frames; the lifter's normalised
#: units), and over the track's last NOISE_FRAMES frames their median: an estimate of the
#: detector's noise std that motion hardly moves (measured on 18 held-out training-split tracks
#: at 30 Hz: median 0.003 clean, 0.026 / 0.062 / 0.128 / 0.242 with noise 0.02 / 0.05 / 0.1 /
#: 0.2 leg lengths). A track's data weight is NOISE_REFERENCE over it (at most 1, at least
#: NOISE_MIN_WEIGHT) once NOISE_MIN_FRAMES frames are in: how far its image limb lengths are
#: trusted (``image_limbs``); the measurement update reads the noise itself.
NOISE_FRAMES = 30
NOISE_MIN_FRAMES = 5
NOISE_REFERENCE = 0.02
NOISE_MIN_WEIGHT = 0.25
#: Frames of a track whose prior limb proportions are kept, and how many are needed before the
#: track's estimate replaces the bases' proportions.
LIMB_FRAMES = 90
#: Past frames a track keeps: the input of a temporal prior (``PosePrior.window - 1`` of them) and
#: the last two for the noise estimate.
MAX_PAST = 8
MIN_LIMB_FRAMES = 10
#: Limb proportions from the image (``LifterOptions.image_limbs``): the IMAGE_LIMB_QUANTILE
#: quantile of each limb's image length over the fit's scale, once IMAGE_LIMB_MIN_FRAMES frames
#: are in, weighted IMAGE_LIMB_WEIGHT (times the track's data weight) against the prior's median.
#: Measured on unseen-motion tracks (clean, 90 frames, 3 azimuths; mean |log error| of the 8
#: proportions): dance (a fold prior) prior's 0.100, image q90 0.043, q95 0.045, max 0.050;
#: subject 02's jump/punch/swordplay (packaged prior) 0.026 / 0.025 / 0.023 / 0.026.
IMAGE_LIMB_QUANTILE = 0.9
IMAGE_LIMB_MIN_FRAMES = 30
IMAGE_LIMB_WEIGHT = 1.0
IMAGE_LIMB_EVERY = 10
#: The prior's limb estimate is biased (a regression to the mean: the packaged priors under-state
#: how much a person's thighs and shins differ from the mean, slopes > 1). Per bone group (upper
#: arm, forearm, thigh, shin), the person's log-proportions (mean over the groups removed) are
#: ``slope * estimate + offset``: least squares over held-out training-split tracks whose limbs
#: were scaled by up to +-20 % (printed by ``tools/limb_calibration.py`` at commit 1b0676e, fitted
#: to the packaged priors: fit again when they change).
LIMB_CALIBRATION: tuple[NDArray[np.float64], NDArray[np.float64]] = (
    np.array([0.84, 0.96, 1.28, 1.21]), np.array([-0.011, 0.044, -0.112, -0.099]))
#: The temporal outlier gate (``LifterOptions.outlier_gate``) leaves a frame alone when it would
#: gate more than this fraction of its visible joints, and gates one joint on at most
#: GATE_MAX_FRAMES consecutive frames.
GATE_MAX_FRACTION = 0.5
GATE_NOISE_FACTOR = 5.0
GATE_MAX_FRAMES = 3
#: ... and only when the track's last fit is at most this old (input stamps).
GATE_MAX_AGE_NS = 250_000_000
#: The left/right label check (``LifterOptions.label_swaps``), before the gate: an arm's
#: (shoulder, elbow, wrist) or a leg's (hip, knee, ankle) left and right labels are swapped back
#: when, summed over its visible joints, their distances from where the track puts the joints
#: with the labels swapped are at most SWAP_RATIO times those with the labels as given, and
#: shorter by more than SWAP_MARGIN leg lengths per joint (at least two joints); on at most
#: SWAP_MAX_FRAMES frames in a row (a longer swap is the track's error: the detector's labels win).
SWAP_RATIO = 0.5
SWAP_MARGIN = 0.2
SWAP_MAX_FRAMES = 3
#: The gate's and the label check's limits, as the compiled screenings read them.
SCREEN_LIMITS = np.array([GATE_MAX_FRACTION, GATE_MAX_FRAMES, SWAP_MAX_FRAMES, SWAP_RATIO, SWAP_MARGIN])
_OTHER = np.array(COUNTERPART, dtype=np.int64)  # as the compiled check reads it
#: The groups whose labels the check swaps: the arms' joints, the legs' (their left joints).
_GROUPS = np.array([JOINTS_LEFT[:3], JOINTS_LEFT[3:]], dtype=np.int64)


def swap_back(values: NDArray[np.float64], swapped: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``values`` (12, ...) with the left and right rows of the arms (``swapped[0]``) and of the
    legs (``swapped[1]``) exchanged (a copy)."""
    order = np.arange(N_JOINTS)
    for g in np.flatnonzero(swapped):
        both = np.concatenate([_GROUPS[g], _OTHER[_GROUPS[g]]])
        order[both] = _OTHER[both]
    return np.asarray(values, dtype=np.float64)[order]
#: A lost joint is filled in (``LifterOptions.fill_missing_frames``) only while the track's last
#: objective is at most this many times the median of its last 15: on a track whose fit is being
#: lost, the fill held stale positions (36 held-out training-split tracks: clean 48.1 -> 47.4 mm
#: with the guard, 20 % outliers and 15 % missing unchanged at 57.7 and 53.2; 1.2 and 1.5 gave
#: clean 47.5 with outliers 58.5 and 57.6).
FILL_MAX_OBJECTIVE_RATIO = 2.0
#: The fraction of joints the lift did not use is kept over a track's last DISTURBANCE_FRAMES
#: frames (the output smoothing's disturbance, :data:`pose_lifter.core.track.policy.DISTURBANCE_FULL`).
DISTURBANCE_FRAMES = 15


def calibrated_limb_proportions(estimate: NDArray[np.float64]) -> NDArray[np.float64]:
    """The track's limb proportions (..., 8) from the median of the prior's (..., 8), corrected by
    :data:`LIMB_CALIBRATION`; left and right stay equal (:meth:`Lifter.limb_proportions_of`)."""
    e = np.asarray(estimate, dtype=np.float64)
    g = np.log(np.maximum(e[..., _LEFT_LIMBS], 1e-12))
    m = np.add.reduce(g, axis=-1, keepdims=True) / g.shape[-1]  # the mean log, per row
    slope, offset = LIMB_CALIBRATION
    out = np.exp(m + slope * (g - m) + offset)
    return np.asarray(out[..., _GROUP_OF])


def tracks_limb_proportions(tracks: Sequence[Track], image: Sequence[bool]
                            ) -> list[NDArray[np.float64] | None]:
    """Each track's limb proportions (8,), as arrays over the tracks: the calibrated median of the
    prior's over its last LIMB_FRAMES frames, and with ``image`` blended (in logs, each at
    geometric mean 1) with :meth:`Track.image_limb_proportions` by IMAGE_LIMB_WEIGHT times the
    track's data weight (noisy 2D lengthens the spans); None before MIN_LIMB_FRAMES frames."""
    out: list[NDArray[np.float64] | None] = [None] * len(tracks)
    by_count: dict[int, list[int]] = {}  # the tracks by their number of frames kept
    for i, t in enumerate(tracks):
        if t.n_limbs >= MIN_LIMB_FRAMES:
            by_count.setdefault(min(t.n_limbs, LIMB_FRAMES), []).append(i)
    for k, rows in by_count.items():
        s = np.array([tracks[i].limbs[:k] for i in rows])  # (m, k, 8)
        s.sort(axis=1)
        median = s[:, k // 2] if k % 2 else (s[:, k // 2 - 1] + s[:, k // 2]) / 2.0
        for i, prior in zip(rows, calibrated_limb_proportions(median), strict=True):
            out[i] = prior
    blend = [(i, spans) for i, t in enumerate(tracks) if out[i] is not None and image[i]
             and (spans := t.image_limb_proportions()) is not None]
    if blend:
        lp = np.log(np.array([out[i] for i, _ in blend]))
        ls = np.log(np.array([spans for _, spans in blend]))
        lam = IMAGE_LIMB_WEIGHT * np.array([tracks[i].data_weight() for i, _ in blend])[:, None]
        lpm, lsm = np.mean(lp, axis=1, keepdims=True), np.mean(ls, axis=1, keepdims=True)
        for (i, _), row in zip(blend, np.exp((1.0 - lam) * (lp - lpm) + lam * (ls - lsm) + lpm), strict=True):
            out[i] = row
    return out


@dataclass
class Track:
    """What the per-track policy keeps of one tracked person: its warm start and last stamp, its
    recent objectives, limb-proportion estimates, 2D noise, past frames and fits, which joints it
    gated or did not use, and the state of its published pose's smoothing and measurement update.
    """

    warm: WarmStart | None
    last_stamp_ns: int
    objectives: deque[float] = field(default_factory=lambda: deque(maxlen=15))
    #: the prior's limb proportions of the track's last LIMB_FRAMES frames (a ring of rows: the
    #: median needs no order) and how many frames have been added
    limbs: NDArray[np.float64] = field(default_factory=lambda: np.zeros((LIMB_FRAMES, 8)))
    n_limbs: int = 0
    #: the image limb lengths over the fit's scale of the last LIMB_FRAMES frames (a ring, NaN
    #: where unused) and the last estimate from them (:meth:`image_limb_proportions`)
    spans: NDArray[np.float64] = field(default_factory=lambda: np.full((LIMB_FRAMES, 8), np.nan))
    n_spans: int = 0
    span_estimate: NDArray[np.float64] | None = None
    noise: deque[float] = field(default_factory=lambda: deque(maxlen=NOISE_FRAMES))
    history: deque[tuple[int, NDArray[np.float64], NDArray[np.bool_]]] = field(
        default_factory=lambda: deque(maxlen=MAX_PAST))
    #: (stamp, where each joint was (12, 2): its detection when the lift used it, else the fit's
    #: projection, in input units; the camera's scale, input units per model unit)
    fits: deque[tuple[int, NDArray[np.float64], float]] = field(default_factory=lambda: deque(maxlen=2))
    gated: NDArray[np.int64] = field(default_factory=lambda: np.zeros(N_JOINTS, dtype=np.int64))
    #: consecutive frames the arms' and the legs' labels were swapped back, up to the last one (2,)
    swapped: NDArray[np.int64] = field(default_factory=lambda: np.zeros(2, dtype=np.int64))
    #: consecutive frames each joint was not used by the lift, up to the last one
    unused: NDArray[np.int64] = field(default_factory=lambda: np.zeros(N_JOINTS, dtype=np.int64))
    #: the fraction of joints the lift did not use, per frame (the output smoothing's disturbance)
    unused_share: deque[float] = field(default_factory=lambda: deque(maxlen=DISTURBANCE_FRAMES))
    smoother: CausalSmoother | None = None
    #: the last lift's depths (12,; camera frame, centred, leg units), camera scale (input units
    #: per leg unit) and the image position of its centroid (2,): the perspective correction of
    #: the next frame
    depths: tuple[NDArray[np.float64], float, NDArray[np.float64]] | None = None
    measurement: MeasurementUpdate | None = None
    #: the medians of ``noise`` and ``objectives`` while they are unchanged (None: not computed)
    _noise_median: float | None = None
    _objective_median: float | None = None

    def add_objective(self, objective: float) -> None:
        self.objectives.append(objective)
        self._objective_median = None

    def objective_median(self) -> float:
        """The median of the track's last objectives (at least one)."""
        if self._objective_median is None:
            self._objective_median = float(statistics.median(self.objectives))
        return self._objective_median

    def screen_ahead(self, points: NDArray[np.float64], vis: NDArray[np.bool_],
                     predicted: NDArray[np.float64], ahead: NDArray[np.float64],
                     ahead_vis: NDArray[np.bool_], limit: float, check_labels: bool = True
                     ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """The next frames ``ahead`` (k, 12, 2) as the track screens them: frame by frame from
        this one (its joints ``vis`` (12,) kept, the others where the track ``predicted`` them),
        with ``check_labels`` an arm's or a leg's labels swapped back as :func:`label_check` says
        from where the frame before had its joints (moved by the median motion; at most
        SWAP_MAX_FRAMES in a row, counting this frame's), then a visible joint farther than
        ``limit`` leg lengths (or GATE_NOISE_FACTOR times the track's noise) from where the frame
        before had it, after removing the median motion of the joints seen on both, dropped (not
        when that would drop more than GATE_MAX_FRACTION of them): the label check and the gate
        over the frames an offline lift reads ahead, whose swaps and confident outliers would
        otherwise reach the prior. Returns the frames (a copy, labels as the track has them) and
        the joints kept (k, 12)."""
        scale = max(self.fits[-1][2], 1e-12)
        limit = max(limit, GATE_NOISE_FACTOR * self.noise_level())
        ref = np.where(vis[:, None], np.asarray(points, dtype=np.float64), predicted)
        frames = np.array(ahead, dtype=np.float64)
        kept = _screen_ahead_kernel(np.ascontiguousarray(ref), frames, np.array(ahead_vis, dtype=np.bool_),
                                    limit * scale, scale, self.swapped.copy(), check_labels, SCREEN_LIMITS)
        return frames, kept

    def measured(self, result: LiftResult, points: NDArray[np.float64], follows: bool, on: bool,
                 depth: float, gate: float) -> LiftResult | None:
        """A live frame of this (hybrid) track: ``result`` (the fit, smoothed) with its pose replaced
        by the track's measurement update (:mod:`.measurement`; restarted on a frame that does not
        ``follow`` the track), or None when the update is off (``on``: ``measurement_update``), the
        track has no 2D noise estimate yet or its noise is above MAX_NOISE. ``points`` (12, 2) the
        2D the lift read; ``depth``, ``gate``: :meth:`MeasurementUpdate.update`'s."""
        if not on or not follows:
            self.measurement = None
        if not on or not self.noise:  # its first two frames: how far to trust the 2D is not known yet
            return None
        noise = self.noise_median()
        if noise > MAX_NOISE:  # the 2D is no better than the fit's image positions
            self.measurement = None
            return None
        if self.measurement is None:
            self.measurement = MeasurementUpdate()
        out = self.measurement.update(result.pose_camera, points, result.weights > 0, noise, depth, gate)
        if not np.isfinite(out).all():
            self.measurement = None
            return None
        return result.with_camera_pose(out)

    def fit_is_sound(self) -> bool:
        """False when the last frame's objective exceeds FILL_MAX_OBJECTIVE_RATIO times the median
        of the track's last ones (the fit is losing the person: its positions are no prediction)."""
        if len(self.objectives) < 3:
            return True
        return self.objectives[-1] <= FILL_MAX_OBJECTIVE_RATIO * self.objective_median()

    def past(self, stamp_ns: int, frames: int) -> tuple[NDArray[np.float64], NDArray[np.bool_]] | None:
        """The last ``frames`` frames (oldest first, as ``(points (k, 12, 2), used (k, 12))``) that
        are evenly spaced up to ``stamp_ns`` (within 20 %), or None."""
        if frames <= 0 or not self.history:
            return None
        step = stamp_ns - self.history[-1][0]
        if step <= 0:
            return None
        kept: list[tuple[int, NDArray[np.float64], NDArray[np.bool_]]] = []
        later = stamp_ns
        for entry in reversed(self.history):
            if len(kept) == frames or abs((later - entry[0]) - step) > 0.2 * step:
                break
            kept.append(entry)
            later = entry[0]
        if not kept:
            return None
        kept.reverse()
        return np.array([k[1] for k in kept]), np.array([k[2] for k in kept])

    def noise_level(self) -> float:
        """The track's 2D noise estimate (normalised units; 0 before NOISE_MIN_FRAMES frames)."""
        if len(self.noise) < NOISE_MIN_FRAMES:
            return 0.0
        return self.noise_median()

    def noise_median(self) -> float:
        """The median of the track's last 2D noise estimates (at least one)."""
        if self._noise_median is None:
            self._noise_median = float(statistics.median(self.noise))
        return self._noise_median

    def data_weight(self) -> float:
        if len(self.noise) < NOISE_MIN_FRAMES:
            return 1.0
        level = self.noise_level()
        return min(max(NOISE_REFERENCE / max(level, 1e-12), NOISE_MIN_WEIGHT), 1.0)

    def limb_proportions(self, image: bool = False) -> NDArray[np.float64] | None:
        """The track's limb proportions (8,): :func:`tracks_limb_proportions` of this track."""
        return tracks_limb_proportions([self], [image])[0]

    def image_limb_proportions(self) -> NDArray[np.float64] | None:
        """Per limb (8,; left and right averaged) the IMAGE_LIMB_QUANTILE quantile of its image
        length over the fit's scale on the track's last LIMB_FRAMES frames (a limb seen across
        the image plane shows its length: the upper quantile is it, robust to a few bad frames);
        None before IMAGE_LIMB_MIN_FRAMES frames or with a limb seen on fewer. Recomputed every
        IMAGE_LIMB_EVERY frames."""
        if self.n_spans < IMAGE_LIMB_MIN_FRAMES:
            return None
        if self.span_estimate is None or self.n_spans % IMAGE_LIMB_EVERY == 0:
            rows = self.spans[: min(self.n_spans, LIMB_FRAMES)]
            ok = np.isfinite(rows)
            if (ok.sum(axis=0) < IMAGE_LIMB_MIN_FRAMES // 2).any():
                return None
            est = np.array([np.quantile(rows[ok[:, i], i], IMAGE_LIMB_QUANTILE) for i in range(8)])
            pairs = 0.5 * (est[_LEFT_LIMBS] + est[_RIGHT_LIMBS])
            out = pairs[_GROUP_OF]
            self.span_estimate = out if np.isfinite(out).all() and (out > 0).all() else None
        return self.span_estimate

    def add_spans(self, row: NDArray[np.float64]) -> None:
        """This frame's image limb lengths over the fit's scale (8,; NaN where a limb's joint was
        not used by the lift: :func:`image_spans`)."""
        self.spans[self.n_spans % LIMB_FRAMES] = row
        self.n_spans += 1

    def add_limbs(self, proportions: NDArray[np.float64]) -> None:
        self.limbs[self.n_limbs % LIMB_FRAMES] = proportions
        self.n_limbs += 1


def image_spans(points: NDArray[np.float64], used: NDArray[np.bool_], scale: NDArray[np.float64]
                ) -> NDArray[np.float64]:
    """n frames' image limb lengths (n, 8) over their fits' ``scale`` (n,) from their 2D ``points``
    (n, 12, 2); NaN where a limb's joint was not ``used`` (n, 12) by the lift."""
    row = row_norms(points[:, LIMB_A] - points[:, LIMB_B]) / np.maximum(scale, 1e-12)[:, None]
    return np.where(used[:, LIMB_A] & used[:, LIMB_B], row, np.nan)


@njit
def label_check(x: NDArray[np.float64], vis: NDArray[np.bool_], predicted: NDArray[np.float64], scale: float,
                counters: NDArray[np.int64], swapped: NDArray[np.bool_], limits: NDArray[np.float64]) -> bool:
    """The left/right label check of one frame (SWAP_RATIO; ``scale``: the track's last fit's,
    input units per leg length; ``limits``: SCREEN_LIMITS): swaps the arms' and the legs' left
    and right rows of ``x`` (12, 2) and ``vis`` (12,) in place where their visible joints are far
    nearer ``predicted`` (12, 2) swapped; sets ``swapped`` (2,) and ``counters`` (2,, the groups'
    frames swapped in a row); True when a group was swapped."""
    margin = limits[4] * max(scale, 1e-12)
    out = False
    for g in range(_GROUPS.shape[0]):
        given, other, m = 0.0, 0.0, 0
        for k in range(_GROUPS.shape[1]):
            for j in (_GROUPS[g, k], _OTHER[_GROUPS[g, k]]):
                if vis[j]:
                    o = _OTHER[j]
                    given += math.hypot(x[j, 0] - predicted[j, 0], x[j, 1] - predicted[j, 1])
                    other += math.hypot(x[j, 0] - predicted[o, 0], x[j, 1] - predicted[o, 1])
                    m += 1
        if (m >= 2 and counters[g] < limits[2] and other <= limits[3] * given
                and given - other > m * margin):
            for k in range(_GROUPS.shape[1]):
                a = _GROUPS[g, k]
                b = _OTHER[a]
                x[a, 0], x[b, 0] = x[b, 0], x[a, 0]
                x[a, 1], x[b, 1] = x[b, 1], x[a, 1]
                vis[a], vis[b] = vis[b], vis[a]
            counters[g] += 1
            swapped[g] = True
            out = True
        else:
            counters[g] = 0
    return out


@njit
def _median_motion(x: NDArray[np.float64], vis: NDArray[np.bool_], cur: NDArray[np.float64]
                   ) -> tuple[float, float]:
    """The median over the joints ``vis`` (12,; at least one) of ``x - cur`` (12, 2), per axis."""
    n = 0
    for j in range(vis.size):
        if vis[j]:
            n += 1
    dx = np.empty(n)
    dy = np.empty(n)
    k = 0
    for j in range(vis.size):
        if vis[j]:
            dx[k] = x[j, 0] - cur[j, 0]
            dy[k] = x[j, 1] - cur[j, 1]
            k += 1
    return np.median(dx), np.median(dy)


@njit
def _screen_ahead_kernel(ref: NDArray[np.float64], ahead: NDArray[np.float64], kept: NDArray[np.bool_],
                         limit: float, scale: float, counters: NDArray[np.int64], check_labels: bool,
                         limits: NDArray[np.float64]) -> NDArray[np.bool_]:
    """:meth:`Track.screen_ahead`'s loop over the next frames ``ahead`` (k, 12, 2) from the
    positions ``ref`` (12, 2): with ``check_labels``, a frame's labels swapped back where the
    positions of the frame before, moved by the median motion, say so (:func:`label_check`,
    ``counters`` (2,) its frames in a row, in place; ``ahead`` changed in place); then ``kept``
    (k, 12, visible on entry) with the joints farther than ``limit`` (input units) from the frame
    before's, after the median motion of the joints seen on both, cleared (in place, and
    returned; ``limits``: SCREEN_LIMITS)."""
    nj = ref.shape[0]
    cur = ref.copy()
    predicted = np.empty_like(cur)
    swapped = np.zeros(2, dtype=np.bool_)
    for f in range(ahead.shape[0]):
        if not kept[f].any():
            continue
        mx, my = _median_motion(ahead[f], kept[f], cur)
        if check_labels:
            for j in range(nj):
                predicted[j, 0], predicted[j, 1] = cur[j, 0] + mx, cur[j, 1] + my
            if label_check(ahead[f], kept[f], predicted, scale, counters, swapped, limits):
                mx, my = _median_motion(ahead[f], kept[f], cur)
        n = 0
        for j in range(nj):
            if kept[f, j]:
                n += 1
        out = np.zeros(nj, dtype=np.bool_)
        n_out = 0
        for j in range(nj):
            if kept[f, j]:
                ex = ahead[f, j, 0] - cur[j, 0] - mx
                ey = ahead[f, j, 1] - cur[j, 1] - my
                if math.sqrt(ex * ex + ey * ey) > limit:
                    out[j] = True
                    n_out += 1
        drop = n_out <= limits[0] * n
        for j in range(nj):
            if drop and out[j]:
                kept[f, j] = False
            if kept[f, j]:
                cur[j, 0], cur[j, 1] = ahead[f, j, 0], ahead[f, j, 1]
            else:
                cur[j, 0] += mx
                cur[j, 1] += my
    return kept


def compile_kernels() -> None:
    """Compile this module's kernel (numba, ``core.numeric.jit``) or load it from its cache: one screen
    of a still frame ahead (an offline track's first frame would otherwise pay for it)."""
    still = np.zeros((1, N_JOINTS, 2))
    _screen_ahead_kernel(still[0], still, np.ones((1, N_JOINTS), dtype=np.bool_), 1.0, 1.0,
                         np.zeros(2, dtype=np.int64), True, SCREEN_LIMITS)


def visible_joints(points: NDArray[np.float64], confidence: NDArray[np.float64] | None,
             threshold: float) -> NDArray[np.bool_] | None:
    """(..., 12) of points (..., 12, 2): the joints with finite coordinates and confidence >=
    ``threshold`` (the lifter's rule), or None when the shapes are wrong."""
    x = np.asarray(points, dtype=np.float64)
    conf = None if confidence is None else np.asarray(confidence, dtype=np.float64)
    if x.shape[-2:] != (N_JOINTS, 2) or (conf is not None and conf.shape != x.shape[:-1]):
        return None
    vis = cast("NDArray[np.bool_]", np.isfinite(x).all(axis=-1))
    return vis if conf is None else vis & (conf >= threshold)
