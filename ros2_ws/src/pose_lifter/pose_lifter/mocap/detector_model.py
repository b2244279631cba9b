"""A realistic 2D detector: the faults of a real keypoint detector, together, on filmed tracks.

:func:`detect` turns the exact projections of a track (T, 12, 2 pixels, frames at 30 Hz) into what
a detector such as YOLO-pose, RTMPose or OpenPose gives of them, with every fault at once:

* **per-joint noise scaled like the COCO keypoint sigmas** (:data:`COCO_SIGMAS`: hips and ankles
  worse than shoulders and wrists), ``noise`` the mean standard deviation per axis in right
  lower-leg lengths of the person in the image (the detector's error grows with the person's size
  in pixels, as a top-down detector's heatmap resolution does);
* **errors correlated over frames**: each joint's error is a first-order autoregressive process
  with correlation ``correlation`` between consecutive frames (a detector sees nearly the same
  image on the next frame, so it errs nearly the same way; averaging frames removes less than
  white noise suggests);
* **a confidence that falls with the error**: ``exp(-(e / (CONFIDENCE_WIDTH s_j))^2 / 2)`` of the
  joint's error ``e`` against its own spread ``s_j``, times CONFIDENCE_PEAK, plus N(0,
  CONFIDENCE_JITTER), clipped to [CONFIDENCE_MIN, 1];
* **confident outliers**: ``outliers`` of the joints displaced by 1-3 leg lengths with a
  confidence drawn from [0.5, 1] (a detector latching onto another person or a background edge);
* **misses**: ``missing`` of the joints lost (confidence below CONFIDENCE_LOST, coordinates left
  wherever the detector put them: near the joint, with 0.5 leg lengths of error);
* **whole limbs dropped**: an arm (elbow and wrist) or a leg (knee and ankle) lost for a burst of
  DROP_FRAMES frames, ``limb_drop`` of the frames starting one (occlusion by the body or an object);
* **left/right swaps**: on ``swap`` of the frames the arms' labels, and independently the legs',
  exchanged, each with its confidence kept;
* **the image border**: a joint outside the image (``image_size``) is lost (confidence below
  CONFIDENCE_LOST, coordinates clamped to the border); ``lower_cut`` of the frames, in bursts of
  DROP_FRAMES, the lower edge of the view rises above the knees (a person close to the camera or
  behind a desk): knees and ankles are lost.

Deterministic for a generator's state. The conditions ``detector3m`` / ``detector6m`` of
:mod:`pose_lifter.mocap.evaluation` film tracks through :data:`REALISTIC`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.model.skeleton import JOINTS_LEFT, JOINTS_RIGHT, LIMB_NAMES, LIMBS, N_JOINTS

__all__ = ["COCO_SIGMAS", "LOWER_LEG_JOINTS", "REALISTIC", "DetectorModel", "autoregressive", "detect",
           "joint_spreads", "swap_labels"]

#: The COCO keypoint sigmas (Ronchi & Perona 2017, the OKS constants) of the 12 model joints:
#: shoulders 0.079, elbows 0.072, wrists 0.062, hips 0.107, knees 0.087, ankles 0.089.
COCO_SIGMAS: NDArray[np.float64] = np.array(
    [0.079, 0.072, 0.062, 0.079, 0.072, 0.062, 0.107, 0.087, 0.089, 0.107, 0.087, 0.089])
#: Confidence of a joint with error ``e`` and spread ``s``:
#: ``CONFIDENCE_PEAK * exp(-(e / (CONFIDENCE_WIDTH s))^2 / 2) + N(0, CONFIDENCE_JITTER)``.
CONFIDENCE_PEAK = 0.95
CONFIDENCE_WIDTH = 3.0
CONFIDENCE_JITTER = 0.05
CONFIDENCE_MIN = 0.15
#: A lost joint's confidence is drawn from [0, CONFIDENCE_LOST) (below the lifter's default
#: ``confidence_threshold`` of 0.1).
CONFIDENCE_LOST = 0.05
#: Frames a dropped limb or a raised lower edge lasts (uniform, inclusive).
DROP_FRAMES = (3, 15)
#: The joints a dropped limb takes: elbow and wrist, or knee and ankle (the forearms' and shins'
#: joints, :data:`pose_lifter.core.model.skeleton.LIMBS`).
_DROPPED = tuple(LIMBS[i] for i, name in enumerate(LIMB_NAMES) if name.endswith("lower_arm")
                 or name.endswith("lower_leg"))
#: Knees and ankles (the shins' joints): what a lower image edge above the knees hides.
LOWER_LEG_JOINTS: NDArray[np.int64] = np.array(
    [j for i, name in enumerate(LIMB_NAMES) if name.endswith("lower_leg") for j in LIMBS[i]])


@dataclass(frozen=True)
class DetectorModel:
    """The faults of :func:`detect` (module docstring); fractions are per joint or per frame."""

    #: mean standard deviation per axis of a joint's error (right lower-leg lengths)
    noise: float = 0.05
    #: correlation of a joint's error between consecutive frames (0: independent frames)
    correlation: float = 0.7
    outliers: float = 0.02
    missing: float = 0.03
    limb_drop: float = 0.01
    swap: float = 0.03
    lower_cut: float = 0.01

    def __post_init__(self) -> None:
        for name in ("noise", "outliers", "missing", "limb_drop", "swap", "lower_cut"):
            if not 0.0 <= getattr(self, name) < (np.inf if name == "noise" else 1.0):
                raise ValueError(f"DetectorModel.{name} = {getattr(self, name)} out of range")
        if not 0.0 <= self.correlation < 1.0:
            raise ValueError(f"DetectorModel.correlation = {self.correlation} not in [0, 1)")


#: The realistic detector of the accuracy tables: 0.05 leg lengths of noise per axis on average
#: (2-3 px for a person 6 m from a 600 px camera), correlated 0.7 frame to frame, 2 % confident
#: outliers, 3 % misses, a limb dropped on ~1 % of frames for 3-15 frames, 3 % swapped frames, the
#: lower body cut on ~1 % of frames for 3-15 frames, and the image border.
REALISTIC = DetectorModel()


def joint_spreads(noise: float) -> NDArray[np.float64]:
    """Per joint (12,) the standard deviation per axis of its error (leg lengths): the COCO sigmas
    scaled to a mean of ``noise``."""
    return np.asarray(noise * COCO_SIGMAS / COCO_SIGMAS.mean(), dtype=np.float64)


def autoregressive(white: NDArray[np.float64], correlation: float, axis: int) -> NDArray[np.float64]:
    """A stationary first-order autoregressive process along ``axis`` of ``white`` (independent
    standard normal draws, any shape): ``e_0 = w_0``, ``e_t = r e_t-1 + sqrt(1 - r^2) w_t``, so
    every step keeps unit variance and consecutive steps correlate by ``r``."""
    w = np.moveaxis(np.asarray(white, dtype=np.float64), axis, 0)
    out = np.empty_like(w)
    out[0] = w[0]
    innovation = np.sqrt(1.0 - correlation * correlation)
    for t in range(1, len(w)):
        out[t] = correlation * out[t - 1] + innovation * w[t]
    return np.moveaxis(out, 0, axis)


def swap_labels(points: NDArray[np.float64], confidence: NDArray[np.float64], rate: float,
                rng: np.random.Generator) -> None:
    """A detector's left/right label swaps, in place: on ``rate`` of the frames (T, 12, ...) the
    arms' labels are exchanged, and independently on ``rate`` of them the legs', each joint's
    confidence going with its coordinates."""
    n = points.shape[0]
    for left, right in ((JOINTS_LEFT[:3], JOINTS_RIGHT[:3]), (JOINTS_LEFT[3:], JOINTS_RIGHT[3:])):
        sw = np.flatnonzero(rng.random(n) < rate)
        ab, ba = np.array(left + right), np.array(right + left)
        points[np.ix_(sw, ab)] = points[np.ix_(sw, ba)]
        confidence[np.ix_(sw, ab)] = confidence[np.ix_(sw, ba)]


def _bursts(n: int, rate: float, rng: np.random.Generator) -> NDArray[np.bool_]:
    """(n,) frames covered by bursts of DROP_FRAMES frames, starting on ``rate`` of the frames."""
    on = np.zeros(n, dtype=bool)
    if rate <= 0:
        return on
    for s in np.flatnonzero(rng.random(n) < rate):
        on[s:s + int(rng.integers(DROP_FRAMES[0], DROP_FRAMES[1] + 1))] = True
    return on


def detect(clean: NDArray[np.float64], leg_px: NDArray[np.float64], model: DetectorModel,
           rng: np.random.Generator, image_size: tuple[float, float] | None = None
           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What a detector gives of a filmed track (module docstring).

    Parameters
    ----------
    clean : ndarray, shape (T, 12, 2)
        The exact projections of one person's frames (pixels), consecutive frames at 30 Hz.
    leg_px : ndarray, shape (T,)
        The right lower leg's length in pixels on each frame (the unit of ``model.noise``).
    model : DetectorModel
    rng : numpy Generator
    image_size : (width, height), optional
        Pixels; joints outside are lost (None: no border).

    Returns
    -------
    points : ndarray, shape (T, 12, 2)
        Pixels, finite everywhere (a lost joint keeps the detector's guess).
    confidence : ndarray, shape (T, 12)
        In [0, 1]; below CONFIDENCE_LOST where lost.
    """
    clean = np.asarray(clean, dtype=np.float64)
    n = clean.shape[0]
    if clean.shape != (n, N_JOINTS, 2):
        raise ValueError(f"clean must be (T, {N_JOINTS}, 2), got {clean.shape}")
    leg = np.asarray(leg_px, dtype=np.float64).reshape(n)
    spread = joint_spreads(model.noise)  # (12,) leg lengths
    rho = model.correlation
    err = autoregressive(rng.standard_normal((n, N_JOINTS, 2)), rho, axis=0) * spread[None, :, None]
    pts = clean + err * leg[:, None, None]
    e = np.linalg.norm(err, axis=-1) / np.maximum(spread, 1e-12)[None, :]  # in units of s_j
    conf = CONFIDENCE_PEAK * np.exp(-0.5 * (e / CONFIDENCE_WIDTH) ** 2)
    conf = np.clip(conf + rng.normal(0.0, CONFIDENCE_JITTER, conf.shape), CONFIDENCE_MIN, 1.0)
    # confident outliers
    hit = rng.random((n, N_JOINTS)) < model.outliers
    angle = rng.uniform(0.0, 2.0 * np.pi, (n, N_JOINTS))
    mag = rng.uniform(1.0, 3.0, (n, N_JOINTS)) * leg[:, None]
    disp = np.stack([np.cos(angle), np.sin(angle)], axis=-1) * mag[..., None]
    pts = np.where(hit[..., None], clean + disp, pts)
    conf = np.where(hit, rng.uniform(0.5, 1.0, (n, N_JOINTS)), conf)
    swap_labels(pts, conf, model.swap, rng)
    # lost joints: misses, dropped limbs, the raised lower edge, the image border
    lost = rng.random((n, N_JOINTS)) < model.missing
    for limb in _DROPPED:
        lost[np.ix_(_bursts(n, model.limb_drop / len(_DROPPED), rng), np.array(limb))] = True
    lost[np.ix_(_bursts(n, model.lower_cut, rng), LOWER_LEG_JOINTS)] = True
    guess = clean + rng.normal(0.0, 0.5, (n, N_JOINTS, 2)) * leg[:, None, None]
    pts = np.where((lost & ~hit)[..., None], guess, pts)
    if image_size is not None:
        w, h = float(image_size[0]), float(image_size[1])
        outside = (clean[..., 0] < 0) | (clean[..., 0] > w) | (clean[..., 1] < 0) | (clean[..., 1] > h)
        lost |= outside
        pts = np.stack([np.clip(pts[..., 0], 0.0, w), np.clip(pts[..., 1], 0.0, h)], axis=-1)
    conf = np.where(lost, rng.uniform(0.0, CONFIDENCE_LOST, (n, N_JOINTS)), conf)
    return pts, conf
