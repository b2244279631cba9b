"""The depth fusion's constants, measured on training-split tracks (``make depth-calibration``).

The constants of :mod:`pose_lifter.core.depth` that describe the world rather than the method are
measured here, on the training split's trials the packaged prior was not fitted on
(:func:`pose_lifter.mocap.evaluation.evaluation_tracks` ``"val"``), filmed as the RGB-D evaluation
films (:func:`pose_lifter.mocap.rgbd_evaluation.film_rgbd`: the realistic detector, the depth
model's body surface and sensor) at each distance, and lifted as the node lifts:

* :data:`~pose_lifter.core.depth.reading.SURFACE_OFFSET_M`: per joint (left and right together),
  the median of the true joint's depth minus the surface reading at its keypoint (readings within
  0.25 m of the joint: the joint's own surface, not an occluder or the background);
* :attr:`~pose_lifter.core.depth.reading.DepthOptions.offset_std_m`: the spread of those about
  their joint's offset (the 68th percentile of the absolute deviations: a Gaussian's sigma);
* :data:`~pose_lifter.core.depth.uncertainty.MONOCULAR_SCALE_STD`: per bin of
  :data:`~pose_lifter.core.depth.uncertainty.OBSERVED_BINS` (how many joints the 2D shows), the
  68th percentile of ``|k - 1|``, ``k`` the scale about the camera centre that best puts the
  monocular placement's depths on the true ones (least squares);
* :data:`~pose_lifter.core.depth.uncertainty.SHAPE_STD_M`: per joint, the 68th percentiles of the
  scaled placement's errors across the image (x and y together) and along the depth, of the joints
  of wholly shown bodies; :data:`~pose_lifter.core.depth.uncertainty.SHAPE_FACTOR` per bin the same
  of the shown joints over the whole bodies', and
  :data:`~pose_lifter.core.depth.uncertainty.UNOBSERVED_FACTOR` of the joints not shown over the
  shown ones of the same bodies (medians over joints and axes).

The 68th percentile of an error's absolute value is its standard deviation when it is Gaussian,
and the coverage the RGB-D evaluation reports is that of these quantiles: it says how far the
errors are from Gaussian on unseen people.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.reading import DepthOptions, read_patches
from pose_lifter.core.depth.uncertainty import OBSERVED_BINS, observed_bin
from pose_lifter.core.model.skeleton import COUNTERPART, N_JOINTS, RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.placement import DEFAULT_DISTANCE_M, DEFAULT_LEG_LENGTH_M, place_results
from pose_lifter.messages.frame import labelled_2d
from pose_lifter.mocap import depth_model
from pose_lifter.mocap import evaluation as ev
from pose_lifter.mocap.rgbd_evaluation import IMAGE_SIZE, INTRINSICS, film_rgbd

__all__ = ["Calibration", "calibrate", "format_calibration"]

#: A reading farther than this from its joint's true depth minus a typical offset
#: (:data:`_TYPICAL_OFFSET_M`) is not the joint's surface (an occluder, the background): metres.
_OWN_SURFACE_M = 0.25
_TYPICAL_OFFSET_M = 0.06
#: The patch radius of the offsets' readings, pixels: small, on the joint.
_PATCH_PX = 4.0


@dataclass(frozen=True)
class Calibration:
    """The measured constants (module docstring) and the sample sizes behind them."""

    surface_offset_m: NDArray[np.float64]  #: (12,)
    offset_std_m: float
    monocular_scale_std: NDArray[np.float64]  #: per observed-count bin
    shape_std_m: NDArray[np.float64]  #: (12, 2): across, along the depth
    shape_factor: NDArray[np.float64]  #: per observed-count bin
    unobserved_factor: float
    n_frames: int
    n_readings: int


def _q68(x: NDArray[np.float64]) -> float:
    return float(np.quantile(np.abs(x), 0.6827)) if len(x) else float("nan")


def _pooled(per_joint: list[list[float]]) -> list[NDArray[np.float64]]:
    """Each joint's samples with its counterpart's (left and right together)."""
    return [np.array(per_joint[j] + per_joint[COUNTERPART[j]], dtype=np.float64) for j in range(N_JOINTS)]


def calibrate(tracks: Sequence[ev.Track], distances: Sequence[float], settings: dict[str, Any] | None = None,
              sensor: depth_model.DepthSensor | None = None) -> Calibration:
    """The constants (module docstring) measured on ``tracks`` filmed at each of ``distances``."""
    lifts = ev.Evaluator(("hybrid",), settings or {}, ev.Setup(intrinsics=True))
    opt = DepthOptions()
    bins = len(OBSERVED_BINS)
    offsets: list[list[float]] = [[] for _ in range(N_JOINTS)]
    scale_err: list[list[float]] = [[] for _ in range(bins)]
    # the scaled placements' errors per bin, axis (across, along) and joint: of shown and hidden joints
    shown: list[list[list[list[float]]]] = [[[[] for _ in range(N_JOINTS)] for _ in range(2)]
                                            for _ in range(bins)]
    hidden: list[list[list[list[float]]]] = [[[[] for _ in range(N_JOINTS)] for _ in range(2)]
                                             for _ in range(bins)]
    n_frames = 0
    for track in tracks:
        for distance in distances:
            det_seed, depth_seed = np.random.SeedSequence([track.seed, round(1000 * distance), 7]).spawn(2)
            px, conf, truth = film_rgbd(track, distance, np.random.default_rng(det_seed))
            rng = np.random.default_rng(depth_seed)
            leg_m = limb_lengths(track.world)[:, RIGHT_LOWER_LEG]
            _, live = lifts.lifts("hybrid", px, conf, leg_m, distance)
            for i, t in enumerate(live):
                if t is None:
                    continue
                n_frames += 1
                res = t.result
                x0 = place_results(res.pose_camera[None], [res], DEFAULT_LEG_LENGTH_M, INTRINSICS,
                                   DEFAULT_DISTANCE_M)[0]
                k = float(x0[:, 2] @ truth[i, :, 2] / (x0[:, 2] @ x0[:, 2]))
                observed = res.weights > 0
                b = int(observed_bin(observed[None])[0])
                scale_err[b].append(k - 1.0)
                err = k * x0 - truth[i]
                for j in range(N_JOINTS):
                    into = shown[b] if observed[j] else hidden[b]
                    into[0][j].extend(err[j, :2].tolist())
                    into[1][j].append(float(err[j, 2]))
                rendered = depth_model.render_depth(truth[i][None], INTRINSICS, IMAGE_SIZE)
                depth = depth_model.sense(rendered, sensor or depth_model.REALISTIC, rng)
                points = labelled_2d(px[i], conf[i], t.swapped)[0]
                read = read_patches(depth, points, np.full(N_JOINTS, _PATCH_PX), truth[i, :, 2], opt)
                gap = truth[i, :, 2] - read.surface
                own = observed & np.isfinite(gap) & (np.abs(gap - _TYPICAL_OFFSET_M) < _OWN_SURFACE_M)
                for q in np.flatnonzero(own):
                    offsets[q].append(float(gap[q]))
    pooled = _pooled(offsets)
    surface = np.array([float(np.median(p)) if len(p) else float("nan") for p in pooled])
    spread = np.concatenate([p - surface[j] for j, p in enumerate(pooled)])
    q_shown = np.array([[[_q68(p) for p in _pooled(shown[b][a])] for a in (0, 1)] for b in range(bins)])
    q_hidden = np.array([[[_q68(p) for p in _pooled(hidden[b][a])] for a in (0, 1)] for b in range(bins)])
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.array([float(np.nanmedian(q_shown[b] / q_shown[0])) for b in range(bins)])
        unobserved = float(np.nanmedian(q_hidden / q_shown))
    return Calibration(surface, _q68(spread), np.array([_q68(np.array(e)) for e in scale_err]),
                       q_shown[0].T, factor, unobserved, n_frames, sum(len(o) for o in offsets))


def format_calibration(c: Calibration) -> str:
    """The constants as the lines of :mod:`pose_lifter.core.depth` that hold them."""
    def row(a: NDArray[np.float64]) -> str:
        return ", ".join(f"{x:.3f}" for x in a)

    return "\n".join([
        f"# {c.n_frames} frames, {c.n_readings} surface readings",
        f"SURFACE_OFFSET_M = [{row(c.surface_offset_m)}]",
        f"offset_std_m = {c.offset_std_m:.3f}",
        f"MONOCULAR_SCALE_STD = [{row(c.monocular_scale_std)}]  # per bin of OBSERVED_BINS",
        "SHAPE_STD_M = [" + ", ".join(f"[{a:.3f}, {b:.3f}]" for a, b in c.shape_std_m) + "]",
        f"SHAPE_FACTOR = [{row(c.shape_factor)}]",
        f"UNOBSERVED_FACTOR = {c.unobserved_factor:.2f}",
    ])
