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
  of the shown joints' errors over their joint's spread (every joint and axis together), and
  :data:`~pose_lifter.core.depth.uncertainty.UNOBSERVED_FACTOR` per bin and per axis the same of
  the joints not shown over the bin's shown ones (a joint outside the image is placed by the lift's
  guess across the image too, not by the 2D: most along the image's vertical, where an upright
  body leaves the image);
* :data:`~pose_lifter.core.depth.uncertainty.RESIDUAL_SHAPE_LINE` and
  :data:`~pose_lifter.core.depth.uncertainty.RESIDUAL_SCALE_LINE` (:func:`residual_line`): per
  decile of the fits' 2D residual (:func:`~pose_lifter.core.depth.uncertainty.fit_residual`), the
  68th percentile of the scaled placement's errors over their shape's deviations (every joint and
  axis), and of ``|k - 1|`` over the bin's scale deviation; a least-squares line through each
  against the deciles' median residual, scaled so that the 68th percentile of the errors over the
  deviations it scales is 1;
* :data:`~pose_lifter.core.depth.uncertainty.LEAN_SCALE_LINE` (:func:`residual_line` against the
  placed body's :func:`~pose_lifter.core.depth.uncertainty.spine_lean` instead of the residual): the
  same of ``|k - 1|`` over the scale's deviation scaled by the residual's line just measured;
* :data:`~pose_lifter.core.depth.uncertainty.SHAPE_CORR_Z`: the correlation between the joints of
  the scaled placement's errors along the depth, of wholly shown bodies (:func:`shape_correlation`:
  left and right pooled, so the matrix is the same seen in a mirror);
* :data:`~pose_lifter.core.depth.uncertainty.SMOOTHED_STD_FACTOR` and
  :data:`~pose_lifter.core.depth.uncertainty.LAGGED_STD_FACTOR` (:func:`smoothed_std_factors`):
  the 68th percentile of the offline lift's (the lagged node's) fused errors over their standard
  deviations, every coordinate of the joints the scale is for (read from depth, or of a body the
  2D shows whole: :func:`~pose_lifter.core.depth.smooth.window_std_factor`), after the window over
  the fused joints (the deviations averaged as the joints) over the same of each frame's own
  fusion: the scale that gives the smoothed joints the frames' coverage.

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
from pose_lifter.core.depth.uncertainty import (
    OBSERVED_BINS,
    fit_residual,
    monocular_scale_std,
    observed_bin,
    residual_factor,
    shape_std,
    spine_lean,
)
from pose_lifter.core.model.skeleton import COUNTERPART, N_JOINTS, RIGHT_LOWER_LEG, limb_lengths
from pose_lifter.core.track.placement import DEFAULT_DISTANCE_M, DEFAULT_LEG_LENGTH_M, place_results
from pose_lifter.messages.frame import labelled_2d
from pose_lifter.mocap import depth_model
from pose_lifter.mocap import evaluation as ev
from pose_lifter.mocap.rgbd_evaluation import IMAGE_SIZE, INTRINSICS, STD_FACTORS, RgbdEvaluator, film_rgbd

__all__ = ["Calibration", "calibrate", "format_calibration", "residual_line", "shape_correlation",
           "smoothed_std_factors", "spread_factors"]

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
    unobserved_factor: NDArray[np.float64]  #: per observed-count bin (rows): x, y, z
    shape_corr_z: NDArray[np.float64]  #: (12, 12)
    shape_line: tuple[float, float]  #: (a, b) of RESIDUAL_SHAPE_LINE
    scale_line: tuple[float, float]  #: (a, b) of RESIDUAL_SCALE_LINE
    lean_line: tuple[float, float]  #: (a, b) of LEAN_SCALE_LINE
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
    # the scaled placements' errors per bin, axis (x, y, z) and joint: of shown and hidden joints
    shown: list[list[list[list[float]]]] = [[[[] for _ in range(N_JOINTS)] for _ in range(3)]
                                            for _ in range(bins)]
    hidden: list[list[list[list[float]]]] = [[[[] for _ in range(N_JOINTS)] for _ in range(3)]
                                             for _ in range(bins)]
    whole_z: list[NDArray[np.float64]] = []  # the depth errors (12,) of wholly shown bodies
    residuals: list[float] = []  # each frame's fit's 2D residual
    shape_z: list[NDArray[np.float64]] = []  # and its scaled placement's errors / the shape's deviations
    scale_z: list[float] = []  # and |k - 1| / the scale's deviation
    leans: list[float] = []  # and the placed body's spine's lean out of the image plane
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
                residuals.append(float(fit_residual([res])[0]))
                shape_z.append(err / shape_std(observed[None])[0])
                scale_z.append(float((k - 1.0) / monocular_scale_std(observed[None])[0]))
                leans.append(float(spine_lean(x0[None])[0]))
                if observed.all():
                    whole_z.append(err[:, 2])
                for j in range(N_JOINTS):
                    into = shown[b] if observed[j] else hidden[b]
                    for axis in range(3):
                        into[axis][j].append(float(err[j, axis]))
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
    shape, factor, unobserved = spread_factors(shown, hidden)
    r = np.array(residuals)
    scale_line = residual_line(r, np.array(scale_z))
    lean_line = residual_line(np.array(leans), np.array(scale_z) / residual_factor(r, scale_line))
    return Calibration(surface, _q68(spread), np.array([_q68(np.array(e)) for e in scale_err]),
                       shape, factor, unobserved, shape_correlation(np.array(whole_z)),
                       residual_line(r, np.array(shape_z)), scale_line, lean_line, n_frames,
                       sum(len(o) for o in offsets))


def residual_line(residuals: NDArray[np.float64], errors: NDArray[np.float64]) -> tuple[float, float]:
    """``(a, b)`` of a line of :mod:`~pose_lifter.core.depth.uncertainty` (``RESIDUAL_SHAPE_LINE``,
    ``RESIDUAL_SCALE_LINE``; ``LEAN_SCALE_LINE`` with the bodies' leans in place of the residuals)
    from ``n`` frames' fits' 2D residuals (n,) and their errors over their
    deviations without the line (n, ...): per decile of the residual, the 68th percentile of the
    errors' absolute values (a frame's values together) against the decile's median residual;
    the least-squares line through the ten, scaled so that the errors over their deviations scaled
    by it have a 68th percentile of 1 (module docstring)."""
    ok = np.isfinite(residuals)
    r, z = residuals[ok], np.abs(errors[ok]).reshape(int(ok.sum()), -1)
    edges = np.quantile(r, np.linspace(0.0, 1.0, 11))
    decile = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, 9)
    x = np.array([np.median(r[decile == d]) for d in range(10)])
    y = np.array([_q68(z[decile == d].ravel()) for d in range(10)])
    b, a = np.polyfit(x, y, 1)
    level = _q68((z / np.maximum(a + b * r, 1e-9)[:, None]).ravel())  # the line's scale over all frames
    return float(a * level), float(b * level)


def shape_correlation(errors: NDArray[np.float64]) -> NDArray[np.float64]:
    """The correlation matrix (12, 12) of ``errors`` (m, 12), m samples of the 12 joints, with
    each body's mirror image as a sample too (left and right joints swapped)."""
    e = np.asarray(errors, dtype=np.float64)
    both = np.concatenate([e, e[:, list(COUNTERPART)]])
    return np.asarray(np.corrcoef(both, rowvar=False))


def spread_factors(shown: Sequence[Sequence[Sequence[Sequence[float]]]],
                   hidden: Sequence[Sequence[Sequence[Sequence[float]]]]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The shape's spread and its factors from the errors of scaled placements.

    Parameters
    ----------
    shown, hidden : nested sequences [bin][axis][joint] of float
        Per bin of :data:`~pose_lifter.core.depth.uncertainty.OBSERVED_BINS` (bin 0: whole bodies),
        axis (x, y, z) and joint, the errors (metres) of the joints the 2D showed and did not show.

    Returns
    -------
    shape : ndarray, shape (12, 2)
        Per joint (left and right pooled), the 68th percentile of the whole bodies' shown joints'
        absolute errors across the image (x and y together) and along the depth.
    factor : ndarray, shape (bins,)
        Per bin, the same of the shown joints' errors over their joint's ``shape`` (every axis).
    unobserved : ndarray, shape (bins, 3)
        Per bin and axis, the same of the hidden joints' errors over their joint's ``shape`` times
        the bin's ``factor`` (1 in bin 0, which hides no joint; NaN where a bin has no sample).
    """
    def as_lists(errors: Sequence[Sequence[float]]) -> list[list[float]]:
        return [list(e) for e in errors]

    across = [list(x) + list(y) for x, y in zip(shown[0][0], shown[0][1], strict=True)]
    shape = np.array([[_q68(p) for p in _pooled(errors)] for errors in (across, as_lists(shown[0][2]))])

    def normalised(errors: Sequence[Sequence[Sequence[float]]]) -> list[NDArray[np.float64]]:
        """Per axis (x, y, z), one bin's errors over their joint's spread (x, y: across; z: along)."""
        return [np.concatenate([p / shape[a // 2, j] for j, p in enumerate(_pooled(as_lists(errors[a])))])
                for a in range(3)]

    bins = len(shown)
    factor = np.array([_q68(np.concatenate(normalised(shown[b]))) for b in range(bins)])
    unobserved = np.array([[_q68(e) / factor[b] for e in normalised(hidden[b])] for b in range(bins)])
    unobserved[0] = 1.0  # a whole body has no joint hidden
    return shape.T, factor, unobserved


def smoothed_std_factors(tracks: Sequence[ev.Track], distances: Sequence[float],
                         settings: dict[str, Any] | None = None, workers: int = 1
                         ) -> dict[str, tuple[float, int]]:
    """Per smoothed method of the RGB-D evaluation (``fused-offline``: SMOOTHED_STD_FACTOR,
    ``fused-lag``: LAGGED_STD_FACTOR), its factor measured on ``tracks`` at each of ``distances``
    (module docstring) and the coordinates behind it."""
    jobs = [(t, d) for t in tracks for d in distances]
    methods = tuple(STD_FACTORS)
    records = ev.run_jobs(jobs, RgbdEvaluator,
                          (methods, settings or {}, None, None, dict.fromkeys(methods, 1.0), True), workers)
    out: dict[str, tuple[float, int]] = {}
    for m in methods:
        frames = np.concatenate([np.asarray(r["normalised_errors"][m]["frames"]) for r in records])
        smoothed = np.concatenate([np.asarray(r["normalised_errors"][m]["smoothed"]) for r in records])
        out[m] = (_q68(smoothed) / _q68(frames), len(frames))
    return out


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
        "UNOBSERVED_FACTOR = [" + ", ".join("[" + ", ".join(f"{x:.2f}" for x in r) + "]"
                                            for r in c.unobserved_factor) + "]",
        f"RESIDUAL_SHAPE_LINE = ({c.shape_line[0]:.3f}, {c.shape_line[1]:.2f})",
        f"RESIDUAL_SCALE_LINE = ({c.scale_line[0]:.3f}, {c.scale_line[1]:.2f})",
        f"LEAN_SCALE_LINE = ({c.lean_line[0]:.3f}, {c.lean_line[1]:.3f})",
        "SHAPE_CORR_Z = [\n" + "\n".join("    [" + ", ".join(f"{x:.2f}" for x in r) + "],"
                                         for r in c.shape_corr_z) + "\n]",
    ])
