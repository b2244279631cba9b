"""A robust depth reading per joint: a patch of a registered depth image around each keypoint.

A depth camera sees the body's surface, not its joints: the reading at a wrist's pixel is the
front of the forearm, a hole, the wall behind the person (the keypoint a few pixels off the
limb), a pixel mixed from both at the silhouette, or the other arm in front of it.
:func:`read_patches` takes the pixels within a radius of each keypoint (sized to the limb's image
width), drops those outside a depth band around the person (background and far foreground),
takes the median of the rest and trims the pixels that stray from it (mixed pixels, a second
surface in the patch), and gives the reading a variance (the sensor's noise at that depth, and
the spread of the trimmed pixels). The joint centre lies behind the surface it shows by the
limb's radius and the body around the joint: :data:`SURFACE_OFFSET_M` (``make depth-calibration``
measures it on the training split). Which readings belong to the joint (and not to a limb in front
of it) the fusion decides against the placed body (:mod:`pose_lifter.core.depth.fuse`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.depth.kernels import read_kernel, read_people_kernel

__all__ = ["LIMB_RADIUS_M", "SURFACE_OFFSET_M", "DepthArray", "DepthOptions", "PatchReadings",
           "joint_radius_px", "read_patches", "read_people", "sensor_std"]

#: Depth of each joint's centre behind the surface the camera sees at its pixel, metres (order of
#: :data:`pose_lifter.core.model.skeleton.JOINT_NAMES`: shoulders, elbows, wrists, hips, knees,
#: ankles; left then right): the limb's radius and the flesh around the joint (a shoulder sits
#: inside the deltoid and the chest, a hip inside the pelvis), measured on the training split's
#: held-out trials (``make depth-calibration``, :mod:`pose_lifter.mocap.depth_calibration`).
SURFACE_OFFSET_M: Final[NDArray[np.float64]] = np.array(
    [0.050, 0.049, 0.036, 0.050, 0.049, 0.036, 0.100, 0.084, 0.055, 0.100, 0.084, 0.055])
#: Radius of the body at each joint, metres: the patch stays inside the limb's image
#: (:attr:`DepthOptions.patch_scale`).
LIMB_RADIUS_M: Final[NDArray[np.float64]] = np.array(
    [0.06, 0.045, 0.035, 0.06, 0.045, 0.035, 0.08, 0.06, 0.05, 0.08, 0.06, 0.05])


#: A depth image: float32 metres along the optical axis, NaN where there is no reading (the
#: package's depth image); or uint16 millimetres, 0 where there is none, as a 16UC1 camera sends it
#: (:func:`pose_lifter.messages.depth.read_depth` with ``millimetres=True``), each pixel read as
#: the float32 metres ``mm / 1000``: the fusion reads a few patches, so the whole image is never
#: converted. Pixel (u, v) is ``depth[v, u]``.
DepthArray = NDArray[np.float32] | NDArray[np.uint16]


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
    noise_window_px : int
        Side of the square over which the sensor's noise is correlated, pixels: samples within one
        window count as one draw in a reading's variance (raise it for a camera whose error spreads
        over larger areas).
    offset_std_m : float
        Standard deviation of a joint's surface offset about :data:`SURFACE_OFFSET_M`, metres (the
        limb's orientation and the body's build; ``make depth-calibration``).
    confidence_threshold : float
        Joints whose 2D weight is below this are not read (their pixel is not known).
    gate : float
        A reading farther from the placed body than ``gate`` standard deviations (the reading's and
        the body's together) is not this joint's (dropped, as a 2D outlier is).
    outlier_share : float
        The share of kept readings taken to be another surface's (an arm in front, the clothing
        between the legs): a reading counts for its joint with its probability of being the
        joint's under this mixture (:func:`pose_lifter.core.depth.fuse.fuse_readings`).
    occlusion_margin_m : float
        A body part whose surface lies this much in front of a joint's surface on its pixel hides
        the joint.
    tilt_std : float
        Standard deviation of the depth field's tilt (metres of depth per metre across the image):
        the prior that keeps a body read at few joints as the lift leans it.
    max_iter : int
        Iteration cap of the robust depth fit.
    tol : float
        Stopping rule of the robust depth fit: the largest change of a parameter (relative, or
        absolute below 1).
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
    noise_window_px: int = 3
    offset_std_m: float = 0.028
    confidence_threshold: float = 0.1
    gate: float = 3.0
    outlier_share: float = 0.15
    occlusion_margin_m: float = 0.08
    tilt_std: float = 0.3
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


def read_patches(depth: DepthArray, pixels: NDArray[np.float64], radius_px: NDArray[np.float64],
                 expected: NDArray[np.float64], options: DepthOptions) -> PatchReadings:
    """Robust surface depths of ``m`` keypoints of one depth image.

    Parameters
    ----------
    depth : ndarray of float32 or uint16, shape (H, W)
        Metres along the optical axis, NaN where there is no reading; or uint16 millimetres, 0
        where there is none (:data:`DepthArray`).
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
        The median of the in-band pixels of each patch (every ``stride``-th pixel of a large patch,
        :data:`~pose_lifter.core.depth.kernels.STRIDE_RADIUS`) after trimming, its variance
        ``pi/2 max(sigma_z^2, spread^2) / n_eff`` (a median's; ``n_eff`` the independent draws
        among the samples, :attr:`DepthOptions.noise_window_px`); NaN where fewer than
        ``min_pixels`` pixels (or less than ``min_fraction`` of the patch) are in band, or the
        keypoint is outside the image.
    """
    img, millimetres = _image(depth)
    px = np.ascontiguousarray(pixels, dtype=np.float64).reshape(-1, 2)
    m = len(px)
    radius = np.clip(np.asarray(radius_px, dtype=np.float64).reshape(m), options.min_patch_px,
                     float(options.max_patch_px))
    surface = np.empty(m)
    var = np.empty(m)
    n_used = np.empty(m, dtype=np.int64)
    read_kernel(img, millimetres, px, radius, np.ascontiguousarray(expected, dtype=np.float64).reshape(m),
                _settings(options), surface, var, n_used)
    return PatchReadings(surface, var, n_used)


def read_people(depth: DepthArray, pixels: NDArray[np.float64], radius_px: NDArray[np.float64],
                z0: NDArray[np.float64], observed: NDArray[np.bool_], options: DepthOptions
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The readings (:func:`read_patches`) of the keypoints of ``n`` people, each person's depth
    band centred on its depth as the image shows it: the median of its observed keypoints'
    patches read without a band (most lie on the body; the placed depth may be far off).

    Parameters
    ----------
    depth : ndarray of float32 or uint16, shape (H, W)
        As :func:`read_patches`.
    pixels : ndarray, shape (n, 12, 2)
        The keypoints, pixels.
    radius_px : ndarray, shape (n, 12)
        Patch radii, pixels (clipped as :func:`read_patches` clips them).
    z0 : ndarray, shape (n, 12)
        The joints' placed depths, metres: the centres of the bands of the first patches.
    observed : ndarray of bool, shape (n, 12)
        The keypoints whose first patches give the person's depth.
    options : DepthOptions

    Returns
    -------
    surface, var : ndarray, shape (n, 12)
        As :func:`read_patches`'s (NaN where no reading).
    """
    img, millimetres = _image(depth)
    z = np.ascontiguousarray(z0, dtype=np.float64)
    radius = np.clip(np.asarray(radius_px, dtype=np.float64).reshape(z.shape), options.min_patch_px,
                     float(options.max_patch_px))
    surface, var = np.empty(z.shape), np.empty(z.shape)
    read_people_kernel(img, millimetres, np.ascontiguousarray(pixels, dtype=np.float64).reshape(*z.shape, 2),
                       radius, z, np.ascontiguousarray(observed, dtype=bool), _settings(options), surface,
                       var)
    return surface, var


def _image(depth: DepthArray) -> tuple[DepthArray, bool]:
    """``depth`` as the kernels read it (C-ordered float32 metres or uint16 millimetres), and
    whether it holds millimetres."""
    millimetres = bool(np.asarray(depth).dtype == np.uint16)
    img: DepthArray = (np.ascontiguousarray(depth, dtype=np.uint16) if millimetres
                       else np.ascontiguousarray(depth, dtype=np.float32))
    return img, millimetres


def _settings(options: DepthOptions) -> NDArray[np.float64]:
    """The reading's settings (8,) as :func:`read_kernel` takes them (the order of
    :data:`~pose_lifter.core.depth.kernels.READ_SETTINGS`; the counts whole numbers)."""
    return np.array([options.band_m, options.band_fraction, int(options.min_pixels), options.min_fraction,
                     options.trim, options.sensor_noise, max(1, int(options.noise_window_px)),
                     int(options.max_patch_px)], dtype=np.float64)


def joint_radius_px(scale_px_per_m: NDArray[np.float64], options: DepthOptions) -> NDArray[np.float64]:
    """Patch radius (n, 12; pixels) of each joint of ``n`` people whose image scale is
    ``scale_px_per_m`` (n,; pixels per metre at the person's depth, ``f / Z``)."""
    per_m = np.asarray(scale_px_per_m, dtype=np.float64)[:, None]
    return options.patch_scale * LIMB_RADIUS_M[None, :] * per_m

