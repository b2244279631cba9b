"""The per-track policy: one rule for how a tracked person's frames are lifted, used by the ROS node
and by the offline lift alike (so a bag lifted offline gives what the node would publish).

For each frame of a track (``track_id >= 0``; negative ids are untracked, every frame cold):

* a stamp older than the track's last one by at most ``track_timeout`` is out of order: the frame
  is refused (:class:`OutOfOrderFrameError`) and the track kept; older still means the input clock
  jumped back (a looping bag): the track is forgotten and the frame lifted cold;
* within ``track_timeout`` of the last frame the solve is warm-started from it (paper mode: its
  pose and camera; hybrid mode: its camera, the prior's pose starting every frame);
* re-initialisation: when a warm solve's objective exceeds ``reinit_ratio`` times the median of the
  track's last 15 objectives, the frame is also solved cold and the lower objective kept
  (the fit has degraded: a wrong depth basin or a lost person);
* a frame that cannot be lifted drops the track's warm start (the next frame starts cold);
* per-track limb lengths (bones do not change within a person): the median of the learned prior's
  limb proportions over the track's last LIMB_FRAMES frames, once it has MIN_LIMB_FRAMES
  of them, is passed to the lifter for its limb constraints (hybrid mode,
  ``LifterOptions.prior_limbs``, on by default), after :data:`LIMB_CALIBRATION`;
* hybrid mode: the track's 2D noise (NOISE_FRAMES) weights the 2D term down and blends the
  previous frame's pose into the prior's target (temporal smoothness, up to
  ``LifterOptions.temporal_weight``);
* hybrid mode, temporal outlier gate (``LifterOptions.outlier_gate``): a visible joint farther than
  ``outlier_gate`` leg lengths from where the track's last frame had it (relative to the median
  motion of the joints) is treated as missing for this frame, before the prior sees it (a
  detection that jumped; a person's joints move far less in one frame); such a joint, like any
  missing one, takes the previous frame's pose into its prior target with
  ``LifterOptions.missing_temporal_weight`` (the track carries it over) and, when the track used
  it on one of its last ``LifterOptions.fill_missing_frames`` frames, enters the learned prior's
  input where the track predicts it (:meth:`_Track.predict`; the 2D fit still ignores it). Not when it would
  leave fewer than ``min_visible_joints`` or gate more than GATE_MAX_FRACTION of the visible
  joints (the prediction, not the detector, is then wrong), and a joint is gated on at most
  GATE_MAX_FRAMES frames in a row (so the track re-acquires a joint it lost).

* hybrid mode, causal output smoothing (:class:`_Smoother`): the published pose is the prior's
  pose on this frame plus the fit's correction of it (fit minus prior) averaged over the track's
  frames (``LifterOptions.correction_smoothing``, exponential); on a disturbed track (joints the
  lift did not use, or 2D noise) the prior's part is also followed by a constant-velocity
  (alpha-beta) filter whose gain falls to ``LifterOptions.disturbed_smoothing_gain``. Only the
  output: the track's warm start, limb and noise estimates and gate keep the fit's own pose, so
  no smoothing feeds back into the next frame's fit. Every step reads only this and earlier
  frames (no look-ahead: the node and the offline lift publish the same).

Tracks unseen for longer than ``track_timeout`` (input stamps) are forgotten by :meth:`expire`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ._fast import mean_rows, median_rows, row_norms
from .errors import PoseLifterError
from .lifter import Lifter
from .measurement import MeasurementUpdate
from .measurement import compile_kernels as compile_measurement_kernels
from .results import LiftResult, TrackContext, WarmStart
from .skeleton import LEFT_LIMBS, LIMB_GROUP_OF, LIMBS, RIGHT_LIMBS

LIMB_A = np.array([a for a, _ in LIMBS])
LIMB_B = np.array([b for _, b in LIMBS])
_LEFT_LIMBS = np.array(LEFT_LIMBS)
_RIGHT_LIMBS = np.array(RIGHT_LIMBS)
_GROUP_OF = np.array(LIMB_GROUP_OF)
_SQRT6 = math.sqrt(6.0)

__all__ = ["OutOfOrderFrameError", "TrackPolicy", "TrackedLift"]


#: Detector noise: per frame, the median over joints of the 2D input's acceleration
#: ``|x_t - 2 x_{t-1} + x_{t-2}| / sqrt(6)`` (three evenly spaced frames; the lifter's normalised
#: units), and over the track's last NOISE_FRAMES frames their median: an estimate of the
#: detector's noise std that motion hardly moves (measured on 18 held-out training-split tracks
#: at 30 Hz: median 0.003 clean, 0.026 / 0.062 / 0.128 / 0.242 with noise 0.02 / 0.05 / 0.1 /
#: 0.2 leg lengths). The hybrid 2D term is weighted by NOISE_REFERENCE over it (at most 1, at
#: least NOISE_MIN_WEIGHT) once NOISE_MIN_FRAMES frames are in: noisy 2D trusts the prior more.
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
#: were scaled by up to +-20 % (``tools/limb_calibration.py``, which prints these; fitted to the
#: packaged priors: re-run it when they change).
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
#: A lost joint is filled in (``LifterOptions.fill_missing_frames``) only while the track's last
#: objective is at most this many times the median of its last 15: on a track whose fit is being
#: lost, the fill held stale positions (36 held-out training-split tracks: clean 48.1 -> 47.4 mm
#: with the guard, 20 % outliers and 15 % missing unchanged at 57.7 and 53.2; 1.2 and 1.5 gave
#: clean 47.5 with outliers 58.5 and 57.6).
FILL_MAX_OBJECTIVE_RATIO = 2.0
#: Output smoothing (:class:`_Smoother`): the fraction of unused joints (missing, gated or dropped
#: by the outlier pass) over the track's last DISTURBANCE_FRAMES frames, or one minus its 2D data
#: weight, whichever is larger, is its disturbance; at DISTURBANCE_FULL and above the prior's
#: alpha-beta gain is ``disturbed_smoothing_gain``, at 0 it is 1 (no filter), linear between.
DISTURBANCE_FRAMES = 15
DISTURBANCE_FULL = 0.2
#: ... and 2D noise counts as NOISE_DISTURBANCE times one minus the track's data weight (the fit
#: already smooths noisy tracks through ``temporal_weight``; measured on 14 unseen-motion tracks
#: with noise 0.1 and a gain of 0.4: factor 0 / 0.2 / 1 gave 56.6 / 26.3 / 20.2 mm/frame^2 at
#: P-MPJPE 69.4 / 69.6 / 70.7 mm).
NOISE_DISTURBANCE = 0.25


def _visible(points: NDArray[np.float64], confidence: NDArray[np.float64] | None,
             threshold: float) -> NDArray[np.bool_] | None:
    """(12,): the joints with finite coordinates and confidence >= ``threshold`` (the lifter's
    rule), or None when the shapes are wrong."""
    x = np.asarray(points, dtype=np.float64)
    conf = None if confidence is None else np.asarray(confidence, dtype=np.float64)
    if x.shape != (12, 2) or (conf is not None and conf.shape != (12,)):
        return None
    vis = cast("NDArray[np.bool_]", np.isfinite(x).all(axis=1))
    return vis if conf is None else vis & (conf >= threshold)


class OutOfOrderFrameError(PoseLifterError):
    """A tracked frame is older than the track's last frame (within ``track_timeout``)."""


@dataclass
class _Track:
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
    gated: NDArray[np.int64] = field(default_factory=lambda: np.zeros(12, dtype=np.int64))
    #: consecutive frames each joint was not used by the lift, up to the last one
    unused: NDArray[np.int64] = field(default_factory=lambda: np.zeros(12, dtype=np.int64))
    #: the fraction of joints the lift did not use, per frame (the output smoothing's disturbance)
    unused_share: deque[float] = field(default_factory=lambda: deque(maxlen=DISTURBANCE_FRAMES))
    smoother: _Smoother | None = None
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
            self._objective_median = float(median_rows(np.asarray(self.objectives)))
        return self._objective_median

    def gate(self, points: NDArray[np.float64], vis: NDArray[np.bool_], predicted: NDArray[np.float64] | None,
             limit: float, min_visible: int) -> NDArray[np.bool_] | None:
        """The visible joints farther than ``limit`` leg lengths (or GATE_NOISE_FACTOR times the
        track's noise) from where the last frame had them (its detection when the lift used it,
        else the fit's projection), after removing the median motion of the visible joints; None
        when nothing is gated (see GATE_MAX_FRACTION). A constant-velocity prediction was
        measured worse: the fits' jitter doubles in it (7 % of good joints beyond 0.8 leg on
        held-out tracks with 20 % outliers, against 2 % for the last position)."""
        if predicted is None:
            return None
        scale = self.fits[-1][2]
        d = np.where(vis[:, None], np.asarray(points, dtype=np.float64), predicted) - predicted
        dist = row_norms(d) / max(scale, 1e-12)
        limit = max(limit, GATE_NOISE_FACTOR * self.noise_level())  # noisy 2D: its own scale
        out = vis & (dist > limit) & (self.gated < GATE_MAX_FRAMES)
        n_out, n_vis = int(np.count_nonzero(out)), int(np.count_nonzero(vis))
        if n_out == 0 or n_vis - n_out < min_visible or n_out > GATE_MAX_FRACTION * n_vis:
            self.gated[:] = 0
            return None
        self.gated = np.where(out, self.gated + 1, 0)
        return np.asarray(out, dtype=bool)

    def predict(self, points: NDArray[np.float64], vis: NDArray[np.bool_],
                stamp_ns: int) -> NDArray[np.float64] | None:
        """Where each joint (12, 2) should be on this frame: where the last frame had it (its
        detection when the lift used it, else the fit's projection) moved by the median motion of
        this frame's visible joints since (the person's or the camera's). None without a last
        frame at most GATE_MAX_AGE_NS old, or without a visible joint."""
        if not self.fits or not vis.any():
            return None
        t1, p1, _ = self.fits[-1]
        if not 0 < stamp_ns - t1 <= GATE_MAX_AGE_NS:
            return None
        return np.asarray(p1 + median_rows(np.asarray(points, dtype=np.float64)[vis] - p1[vis]))

    def fit_is_sound(self) -> bool:
        """False when the last frame's objective exceeds FILL_MAX_OBJECTIVE_RATIO times the median
        of the track's last ones (the fit is losing the person: its positions are no prediction)."""
        if len(self.objectives) < 3:
            return True
        return self.objectives[-1] <= FILL_MAX_OBJECTIVE_RATIO * self.objective_median()

    def observe_noise(self, lifter: Lifter, points: NDArray[np.float64], visible: NDArray[np.bool_],
                      stamp_ns: int) -> None:
        """Add this frame's 2D acceleration (see NOISE_FRAMES) when the last two frames and this
        one are evenly spaced in time."""
        if len(self.history) < 2:
            return
        (t0, x0, v0), (t1, x1, v1) = self.history[-2], self.history[-1]
        d1, d2 = t1 - t0, stamp_ns - t1
        if d1 <= 0 or d2 <= 0 or abs(d2 - d1) > 0.2 * d1:
            return
        x = np.asarray(points, dtype=np.float64)
        vis = v0 & v1 & visible
        if np.count_nonzero(vis) < 3:
            return
        acc = row_norms(x[vis] - 2.0 * x1[vis] + x0[vis]) / _SQRT6
        try:
            spread = lifter.input_scale(x, vis.astype(np.float64))
        except PoseLifterError:
            return
        self.noise.append(float(median_rows(acc)) / spread)
        self._noise_median = None

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
            self._noise_median = float(median_rows(np.asarray(self.noise)))
        return self._noise_median

    def data_weight(self) -> float:
        if len(self.noise) < NOISE_MIN_FRAMES:
            return 1.0
        level = self.noise_level()
        return min(max(NOISE_REFERENCE / max(level, 1e-12), NOISE_MIN_WEIGHT), 1.0)  # np.clip

    def limb_proportions(self, image: bool = False) -> NDArray[np.float64] | None:
        """The track's limb proportions (8,): the calibrated median of the prior's, and with
        ``image`` blended (in logs, each at geometric mean 1) with :meth:`image_limb_proportions`
        by IMAGE_LIMB_WEIGHT times the track's data weight (noisy 2D lengthens the spans)."""
        if self.n_limbs < MIN_LIMB_FRAMES:
            return None
        prior = calibrated_limb_proportions(median_rows(self.limbs[: min(self.n_limbs, LIMB_FRAMES)]))
        spans = self.image_limb_proportions() if image else None
        if spans is None:
            return prior
        lam = IMAGE_LIMB_WEIGHT * self.data_weight()
        lp, ls = np.log(prior), np.log(spans)
        return np.asarray(np.exp((1.0 - lam) * (lp - lp.mean()) + lam * (ls - ls.mean()) + lp.mean()))

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

    def add_spans(self, points: NDArray[np.float64], used: NDArray[np.bool_], scale: float) -> None:
        """This frame's image limb lengths over the fit's ``scale`` (NaN where a limb's joint
        was not used by the lift)."""
        x = np.asarray(points, dtype=np.float64)
        row = row_norms(x[LIMB_A] - x[LIMB_B]) / max(scale, 1e-12)
        self.spans[self.n_spans % LIMB_FRAMES] = np.where(used[LIMB_A] & used[LIMB_B], row, np.nan)
        self.n_spans += 1

    def add_limbs(self, proportions: NDArray[np.float64]) -> None:
        self.limbs[self.n_limbs % LIMB_FRAMES] = proportions
        self.n_limbs += 1


class _Smoother:
    """Causal smoothing of one track's published pose (camera frame, centred, model units).

    Per frame ``t``, with ``P_t`` the prior's pose and ``F_t`` the fit's (both (12, 3))::

        c_t = b c_{t-1} + (1 - b) (F_t - P_t)               (the fit's correction, averaged)
        S_t = alpha-beta filter of P_t with gain g, h = g^2 / (2 - g)   (g = 1: S_t = P_t)
        out_t = S_t + c_t

    ``b`` is ``correction_smoothing``; the prior is smooth on clean input and the fit's correction
    of it is where the jitter is (measured: clean unseen tracks 15.6 -> 6.0 mm/frame^2 at b = 0.7,
    P-MPJPE 60.6 -> 60.4 mm), so averaging the correction costs little lag. ``g`` falls with the
    track's disturbance (see DISTURBANCE_FULL): with outliers the prior's input changes from frame
    to frame and the prior jitters too. Uses only the frames given so far.
    """

    def __init__(self) -> None:
        self.correction: NDArray[np.float64] | None = None
        self.level: NDArray[np.float64] | None = None
        self.velocity = np.zeros((12, 3))

    def update(self, fit: NDArray[np.float64], prior: NDArray[np.float64], b: float, gain: float
               ) -> NDArray[np.float64]:
        """The smoothed pose (12, 3) for this frame's fit and prior poses (12, 3)."""
        corr = fit - prior
        if self.correction is None or self.level is None:
            self.correction, self.level = corr, prior.copy()
            return np.asarray(fit, dtype=np.float64).copy()
        self.correction = b * self.correction + (1.0 - b) * corr
        predicted = self.level + self.velocity
        resid = prior - predicted
        self.level = predicted + gain * resid
        self.velocity = self.velocity + (gain * gain / (2.0 - gain)) * resid
        return np.asarray(self.level + self.correction)


def _prior_camera(result: LiftResult) -> NDArray[np.float64] | None:
    """The prior's pose of ``result`` in the camera frame of ``pose_camera`` (12, 3: centred, in
    the fit's model units: divided by the camera's scale), or None without one."""
    prior = result.prior_pose
    scale = float(result.camera.scale)
    if prior is None or not scale > 0:
        return None
    out = (prior - mean_rows(prior)) / scale
    return out if np.isfinite(out).all() else None


def calibrated_limb_proportions(estimate: NDArray[np.float64]) -> NDArray[np.float64]:
    """The track's limb proportions (8,) from the median of the prior's (8,), corrected by
    :data:`LIMB_CALIBRATION`; left and right stay equal (:meth:`Lifter.limb_proportions_of`)."""
    e = np.asarray(estimate, dtype=np.float64)
    g = np.log(np.maximum(e[_LEFT_LIMBS], 1e-12))
    m = np.add.reduce(g) / g.size  # g.mean()
    slope, offset = LIMB_CALIBRATION
    out = np.exp(m + slope * (g - m) + offset)
    return np.asarray(out[_GROUP_OF])


@dataclass(frozen=True)
class TrackedLift:
    """One lifted frame of a track.

    Attributes
    ----------
    result : LiftResult
    warm_started : bool
        Solved from the track's previous frame.
    reinitialised : bool
        The warm solve had degraded and a cold solve replaced it (its objective was lower).
    fit_pose_camera : ndarray, shape (12, 3), optional
        The fit's own ``pose_camera`` when the output smoothing replaced ``result.pose`` and
        ``result.pose_camera`` (hybrid mode; the rest of ``result`` is the fit's), else None.
    """

    result: LiftResult
    warm_started: bool
    reinitialised: bool
    fit_pose_camera: NDArray[np.float64] | None = None


class TrackPolicy:
    """Per-track warm starts, re-initialisation and expiry around one :class:`Lifter`.

    Parameters
    ----------
    lifter : Lifter
    track_timeout : float
        Seconds of input time after which a track's warm start is not used (and, in
        :meth:`expire`, the track is forgotten).
    warm_start : bool
        False: every frame cold (the policy still refuses out-of-order frames).
    reinit_ratio : float
        A warm solve whose objective exceeds this times the track's recent median is redone cold
        (``<= 0``: never).
    """

    def __init__(self, lifter: Lifter, track_timeout: float = 1.0, warm_start: bool = True,
                 reinit_ratio: float = 2.0) -> None:
        self._tracks: dict[int, _Track] = {}
        self.configure(lifter, track_timeout, warm_start, reinit_ratio)
        compile_measurement_kernels()  # now, not on a track's first frame

    def configure(self, lifter: Lifter, track_timeout: float, warm_start: bool, reinit_ratio: float) -> None:
        """Change the lifter or the settings; the tracks are kept (forgotten when ``warm_start``
        is turned off)."""
        self.lifter = lifter
        self.track_timeout_ns = round(float(track_timeout) * 1e9)
        self.warm_start = bool(warm_start)
        self.reinit_ratio = float(reinit_ratio)
        if not self.warm_start:
            self._tracks.clear()

    def __len__(self) -> int:
        return len(self._tracks)

    def clear(self) -> None:
        """Forget every track (e.g. after a change of bases: old coefficients are meaningless)."""
        self._tracks.clear()

    def restore(self, track_id: int, warm: WarmStart | None, stamp_ns: int) -> None:
        """Set a track's state (its warm start and last stamp), e.g. carried over from another
        policy; its objective history starts empty."""
        self._tracks[track_id] = _Track(warm, stamp_ns)

    def expire(self, stamp_ns: int) -> None:
        """Forget the tracks unseen for more than ``track_timeout`` before ``stamp_ns``."""
        stale = [t for t, s in self._tracks.items() if stamp_ns - s.last_stamp_ns > self.track_timeout_ns]
        for t in stale:
            del self._tracks[t]

    def lift(self, track_id: int, stamp_ns: int, points: NDArray[np.float64],
             confidence: NDArray[np.float64] | None = None) -> TrackedLift:
        """Lift one frame of a track (model joints, as :meth:`Lifter.lift`).

        Raises
        ------
        OutOfOrderFrameError
            An out-of-order frame of a known track (the track is kept).
        InvalidInputError, TooFewJointsError
            From the lifter; the track's warm start is dropped.
        """
        track = self._tracks.get(track_id) if track_id >= 0 else None
        warm: WarmStart | None = None
        if track is not None:
            age = stamp_ns - track.last_stamp_ns
            if -self.track_timeout_ns <= age < 0:
                raise OutOfOrderFrameError(
                    f"track {track_id}: stamp {-age / 1e9:.3f} s older than its last frame")
            if age < -self.track_timeout_ns:  # the input clock jumped back (e.g. a looping bag)
                del self._tracks[track_id]
                track = None
            elif age <= self.track_timeout_ns and self.warm_start:
                warm = track.warm
        opts = self.lifter.options
        limbs = track.limb_proportions(opts.image_limbs) if track is not None else None
        hybrid = opts.mode == "hybrid"
        # the frame's visible joints (None for malformed input: the lifter refuses it with the reason)
        vis = _visible(points, confidence, opts.confidence_threshold)
        follows = hybrid and track is not None and warm is not None and vis is not None
        screened = follows and opts.outlier_gate > 0
        # where the track puts each joint on this frame (the gate's and the fill's reference)
        predicted = None
        if follows:
            assert track is not None and vis is not None
            predicted = track.predict(points, vis, stamp_ns)
        if screened:
            assert track is not None and vis is not None
            gated = track.gate(points, vis, predicted, opts.outlier_gate, opts.min_visible_joints)
            if gated is not None:  # a gated joint is missing for this frame
                confidence = np.where(gated, 0.0, np.ones(12) if confidence is None
                                      else np.asarray(confidence, dtype=np.float64))
                vis = vis & ~gated
                predicted = track.predict(points, vis, stamp_ns)  # the motion of the joints kept
        if follows:  # a frame that follows the last one
            assert track is not None and vis is not None
            track.observe_noise(self.lifter, points, vis, stamp_ns)
        dw = track.data_weight() if hybrid and track is not None else 1.0
        # smoothing only pays with noisy 2D (on clean input it is lag): scaled with the noise
        tw = np.full(12, opts.temporal_weight * (1.0 - dw) / (1.0 - NOISE_MIN_WEIGHT))
        if warm is not None and vis is not None and opts.missing_temporal_weight > 0:
            # a joint the detector lost on this frame is carried over from the track's last pose
            tw = np.where(vis, tw, np.maximum(tw, opts.missing_temporal_weight))
        try:
            past = None
            if track is not None and warm is not None and opts.mode != "paper":
                temporal = self.lifter.temporal_prior
                past = track.past(stamp_ns, (temporal or self.lifter.prior).window - 1)
            fill = None
            if predicted is not None and opts.fill_missing_frames > 0:
                assert track is not None
                if track.fit_is_sound():
                    fill = (predicted, track.unused < opts.fill_missing_frames)
            context = TrackContext(limbs, dw, tw, past, screened, fill)
            result = self.lifter.lift(points, confidence, warm=warm, track=context)
            reinit = False
            if (warm is not None and track is not None and self.reinit_ratio > 0
                    and len(track.objectives) >= 3):
                if result.objective > self.reinit_ratio * track.objective_median():
                    cold = self.lifter.lift(points, confidence, warm=None, track=context)
                    if cold.objective < result.objective:
                        result, reinit = cold, True
        except PoseLifterError:
            if track is not None:
                track.warm = None
            raise
        if track_id >= 0:
            if track is None:
                track = self._tracks[track_id] = _Track(None, stamp_ns)
            track.warm = result.warm_start()
            track.last_stamp_ns = stamp_ns
            used = result.weights > 0
            track.unused = np.where(used, 0, track.unused + 1)
            track.add_objective(float(result.objective))
            if result.prior_pose is not None:
                track.add_limbs(self.lifter.limb_proportions_of(result.prior_pose))
            x = np.array(points, dtype=np.float64)  # the track's own copy
            track.history.append((stamp_ns, x, used))
            cam = result.camera
            # where each joint was: its detection when the lift used it, else the fit's projection
            track.fits.append((stamp_ns, np.where(used[:, None], x, cam.project(result.pose)),
                               float(cam.scale)))
            if hybrid and opts.image_limbs:
                track.add_spans(x, used, float(cam.scale))
            if hybrid:
                # the output's state carries over a re-initialised frame (its jump is smoothed)
                published = self._smooth(track, result, warm is not None, dw)
                updated = self._measure(track, published or result, points, warm is not None)
                out = updated if updated is not None else published
                if out is not None:
                    return TrackedLift(out, warm is not None, reinit, result.pose_camera)
        return TrackedLift(result, warm is not None, reinit)

    def _measure(self, track: _Track, result: LiftResult, points: NDArray[np.float64], follows: bool
                 ) -> LiftResult | None:
        """``result`` (the fit, smoothed) with its pose replaced by the measurement update's (see
        :mod:`.measurement`), or None when it is off or the track has no 2D noise estimate yet."""
        opts = self.lifter.options
        if not opts.measurement_update:
            track.measurement = None
            return None
        if not follows or track.measurement is None:
            track.measurement = MeasurementUpdate()
        if not track.noise:  # its first two frames: how far to trust the 2D is not known yet
            return None
        noise = track.noise_median()
        out = track.measurement.update(result.pose_camera, points, result.weights > 0, noise,
                                       opts.measurement_depth, opts.measurement_gate)
        if not np.isfinite(out).all():
            track.measurement = None
            return None
        pose = out @ result.camera.rotation + mean_rows(result.pose)
        return replace(result, pose=np.ascontiguousarray(pose), pose_camera=np.ascontiguousarray(out))

    def _smooth(self, track: _Track, result: LiftResult, follows: bool, data_weight: float
                ) -> LiftResult | None:
        """``result`` with its pose replaced by the track's smoothed one (see :class:`_Smoother`),
        or None when smoothing is off or the frame starts the smoother again (a cold solve)."""
        opts = self.lifter.options
        track.unused_share.append(float(np.count_nonzero(result.weights <= 0)) / 12.0)
        if opts.correction_smoothing <= 0 and opts.disturbed_smoothing_gain >= 1:
            track.smoother = None
            return None
        prior = _prior_camera(result)
        if prior is None:
            track.smoother = None
            return None
        if not follows or track.smoother is None:
            track.smoother = _Smoother()
        shares = track.unused_share
        disturbance = max(sum(shares) / len(shares), NOISE_DISTURBANCE * (1.0 - data_weight))
        gain = 1.0 - min(1.0, disturbance / DISTURBANCE_FULL) * (1.0 - opts.disturbed_smoothing_gain)
        out = track.smoother.update(result.pose_camera, prior, opts.correction_smoothing, gain)
        if not np.isfinite(out).all():  # ndarray.all: no numpy wrapper on the per-frame path
            track.smoother = None
            return None
        rot = result.camera.rotation
        # the body-frame pose with the same camera: pose_camera = (pose - mean) @ R^T
        pose = out @ rot + mean_rows(result.pose)
        return replace(result, pose=np.ascontiguousarray(pose), pose_camera=np.ascontiguousarray(out))
