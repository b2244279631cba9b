"""A robust depth reading per joint: a patch of a registered depth image around each keypoint.

A depth camera sees the body's surface, not its joints: the reading at a wrist's pixel is the
front of the forearm, a hole, the wall behind the person (the keypoint a few pixels off the
limb), a pixel mixed from both at the silhouette, or the other arm in front of it.
:func:`read_patches` takes the pixels within a radius of each keypoint (sized to the limb's image
width), drops those outside a depth band around the person (background and far foreground),
takes the median of the rest and trims the pixels that stray from it (mixed pixels, a second
surface in the patch), and gives the reading a variance (the sensor's noise at that depth, and
the spread of the trimmed pixels). The joint centre lies behind the surface it shows by the
limb's radius and the body around the joint: :data:`SURFACE_OFFSET_M` (``tools/depth_calibration.py``
measures it on the training split). Which readings belong to the joint (and not to a limb in front
of it) the fusion decides against the placed body (:mod:`pose_lifter.core.depth.fuse`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["LIMB_RADIUS_M", "SURFACE_OFFSET_M", "DepthOptions", "PatchReadings", "joint_radius_px",
           "read_patches", "sensor_std"]

#: Depth of each joint's centre behind the surface the camera sees at its pixel, metres (order of
#: :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`: shoulders, elbows, wrists, hips, knees,
#: ankles; left then right): the limb's radius and the flesh around the joint (a shoulder sits
#: inside the deltoid and the chest, a hip inside the pelvis).
SURFACE_OFFSET_M: Final[NDArray[np.float64]] = np.array(
    [0.10, 0.07, 0.05, 0.10, 0.07, 0.05, 0.11, 0.07, 0.06, 0.11, 0.07, 0.06])
#: Radius of the body at each joint, metres: the patch stays inside the limb's image
#: (:attr:`DepthOptions.patch_scale`).
LIMB_RADIUS_M: Final[NDArray[np.float64]] = np.array(
    [0.06, 0.045, 0.035, 0.06, 0.045, 0.035, 0.08, 0.06, 0.05, 0.08, 0.06, 0.05])


@dataclass(frozen=True)
class DepthOptions:
    """How depth readings are taken and fused (:func:`read_patches`,
    :func:`pose_lifter.core.depth.fuse.fuse_depth`).

    Attributes
    ----------
    patch_scale : float
        Patch radius as a fraction of the limb's radius in the image (:data:`LIMB_RADIUS_M` at the
        person's placed depth): the patch stays on the limb when the keypoint is on it.
    min_patch_px, max_patch_px : float, int
        Bounds of the patch radius, pixels.
    band_m, band_fraction : float
        Pixels farther than ``band_m + band_fraction * Z`` from the person's placed depth ``Z`` in
        front or behind are not the person (background, a near object).
    min_pixels : int
        Fewest in-band pixels a reading needs.
    min_fraction : float
        Least fraction of the patch's pixels in band (a patch mostly on the background is a miss).
    trim : float
        Pixels farther than ``trim`` robust standard deviations (or sensor standard deviations,
        whichever is larger) from the patch's median are dropped before the reading.
    sensor_noise : float
        The sensor's depth noise ``c`` of ``sigma_z = c z^2`` (per metre): active stereo cameras
        (RealSense D4xx: about 2 % RMS at 4 m).
    offset_std_m : float
        Standard deviation of a joint's surface offset about :data:`SURFACE_OFFSET_M`, metres (the
        limb's orientation and the body's build).
    confidence_threshold : float
        Joints whose 2D weight is below this are not read (their pixel is not known).
    gate : float
        A reading farther from the placed body than ``gate`` standard deviations (the reading's and
        the body's together) is not this joint's (dropped, as a 2D outlier is).
    occlusion_margin_m : float
        A body part whose surface lies this much in front of a joint's surface on its pixel hides
        the joint.
    prior_std : float
        Standard deviation of the person's depth scale about the monocular placement's (relative):
        the prior on the leg length that keeps a person with few readings near it.
    max_iter : int
        Iteration cap of the robust scale fit.
    tol : float
        Stopping rule of the robust scale fit: relative change of the scale.
    """

    patch_scale: float = 0.6
    min_patch_px: float = 1.5
    max_patch_px: int = 10
    band_m: float = 0.6
    band_fraction: float = 0.15
    min_pixels: int = 3
    min_fraction: float = 0.25
    trim: float = 3.0
    sensor_noise: float = 0.0025
    offset_std_m: float = 0.025
    confidence_threshold: float = 0.1
    gate: float = 3.0
    occlusion_margin_m: float = 0.08
    prior_std: float = 0.15
    max_iter: int = 50
    tol: float = 1e-7


def sensor_std(z: NDArray[np.float64], options: DepthOptions) -> NDArray[np.float64]:
    """The sensor's depth standard deviation at depths ``z`` (any shape, metres): ``c z^2``, at
    least 1 mm (the 16-bit image's quantisation)."""
    return np.maximum(options.sensor_noise * np.asarray(z, dtype=np.float64) ** 2, 1e-3)


@dataclass(frozen=True)
class PatchReadings:
    """The depth readings of ``m`` keypoints.

    Attributes
    ----------
    surface : ndarray, shape (m,)
        Depth of the surface at each keypoint, metres (NaN: no reading).
    var : ndarray, shape (m,)
        Variance of ``surface``, m^2 (NaN where no reading).
    n_pixels : ndarray of int, shape (m,)
        Pixels the reading used.
    """

    surface: NDArray[np.float64]
    var: NDArray[np.float64]
    n_pixels: NDArray[np.int64]


def read_patches(depth: NDArray[np.float32], pixels: NDArray[np.float64], radius_px: NDArray[np.float64],
                 expected: NDArray[np.float64], options: DepthOptions) -> PatchReadings:
    """Robust surface depths of ``m`` keypoints of one depth image.

    Parameters
    ----------
    depth : ndarray of float32, shape (H, W)
        Metres along the optical axis, NaN where there is no reading.
    pixels : ndarray, shape (m, 2)
        The keypoints (u column, v row), pixels.
    radius_px : ndarray, shape (m,)
        Patch radius per keypoint, pixels (clipped to ``[min_patch_px, max_patch_px]``).
    expected : ndarray, shape (m,)
        The person's placed depth per keypoint, metres: the centre of the depth band.
    options : DepthOptions

    Returns
    -------
    PatchReadings
        The median of the in-band pixels of each patch after trimming, its variance
        ``sigma_z^2 + spread^2 / n`` (the sensor's noise is correlated over a patch, so it is not
        divided by the pixel count); NaN where fewer than ``min_pixels`` pixels (or less than
        ``min_fraction`` of the patch) are in band, or the keypoint is outside the image.
    """
    img = np.asarray(depth)
    h, w = img.shape
    m = len(pixels)
    r_max = int(options.max_patch_px)
    radius = np.clip(np.asarray(radius_px, dtype=np.float64), options.min_patch_px, float(r_max))
    grid = np.arange(-r_max, r_max + 1)
    dv, du = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    dist2 = (du * du + dv * dv).astype(np.float64)
    px = np.asarray(pixels, dtype=np.float64)
    finite = np.asarray(np.isfinite(px).all(axis=1), dtype=bool)
    centre = np.where(finite[:, None], np.rint(px), -10 * (r_max + 1)).astype(np.int64)
    rows = centre[:, 1:2] + dv[None, :]
    cols = centre[:, 0:1] + du[None, :]
    in_patch = dist2[None, :] <= (radius * radius)[:, None]
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w) & in_patch
    vals = np.full((m, len(dv)), np.nan)
    vals[inside] = img[rows[inside], cols[inside]]
    exp = np.asarray(expected, dtype=np.float64)
    band = options.band_m + options.band_fraction * exp
    vals[~(np.abs(vals - exp[:, None]) <= band[:, None])] = np.nan  # NaN, background and foreground
    n_in = np.isfinite(vals).sum(axis=1)
    n_patch = in_patch.sum(axis=1)
    ok = finite & (n_in >= options.min_pixels) & (n_in >= options.min_fraction * n_patch)
    surface = np.full(m, np.nan)
    var = np.full(m, np.nan)
    n_used = np.zeros(m, dtype=np.int64)
    if ok.any():
        v = vals[ok]
        med = _row_medians(v)
        dev = np.abs(v - med[:, None])
        spread = 1.4826 * _row_medians(dev)
        keep = dev <= options.trim * np.maximum(spread, sensor_std(med, options))[:, None]
        n_k = keep.sum(axis=1)
        med2 = _row_medians(np.where(keep, v, np.nan))
        resid = np.where(keep, v - med2[:, None], 0.0)
        s2 = (resid * resid).sum(axis=1) / np.maximum(n_k - 1, 1)
        surface[ok] = med2
        var[ok] = sensor_std(med2, options) ** 2 + s2 / n_k
        n_used[ok] = n_k
    return PatchReadings(surface, var, n_used)


def _row_medians(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """The median of each row's finite values (m, P) -> (m,); every row has at least one (NaN
    sorts last, so the finite values are the first ``n`` of the sorted row)."""
    srt = np.sort(values, axis=1)
    n = np.isfinite(values).sum(axis=1)
    rows = np.arange(len(values))
    return np.asarray(0.5 * (srt[rows, (n - 1) // 2] + srt[rows, n // 2]))


def joint_radius_px(scale_px_per_m: NDArray[np.float64], options: DepthOptions) -> NDArray[np.float64]:
    """Patch radius (n, 12; pixels) of each joint of ``n`` people whose image scale is
    ``scale_px_per_m`` (n,; pixels per metre at the person's depth, ``f / Z``)."""
    per_m = np.asarray(scale_px_per_m, dtype=np.float64)[:, None]
    return options.patch_scale * LIMB_RADIUS_M[None, :] * per_m

