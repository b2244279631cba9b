"""A depth camera filming mocap people: the body surface of :mod:`pose_lifter.mocap.body_surface`
rendered to an ideal depth image (:func:`render_depth`, re-exported here), seen through an
active-stereo sensor (RealSense D435-like) with its faults (:func:`sense`).

**The sensor** (:class:`DepthSensor`, :func:`sense`), in this order on the ideal image:

1. *mixed (flying) pixels*: a pixel on a silhouette (a 4-neighbour differs in depth by more
   than ``edge_jump_m``), with probability ``mixed_rate``, reads a depth uniformly between the
   nearest and the farthest depth of its 3x3 neighbourhood (a stereo window straddling the edge);
2. *noise*: Gaussian, standard deviation ``noise_c z^2`` (the stereo depth RMS error
   ``z^2 subpixel / (f B)`` of Grunnet-Jepsen, Sweetser & Woodfill, "Best-known-methods for
   tuning Intel RealSense D400 depth cameras for best performance", Intel, 2018: subpixel 0.08,
   f = 0.5 * 1280 / tan(87 deg / 2) = 675 px at 1280x720, B = 50 mm give 0.0024 per metre); each
   pixel's draw is the mean of a ``noise_window_px`` square block of independent draws, rescaled
   to unit variance, so neighbours within a block-matching window err alike;
3. *quantisation* to ``quantisation_m`` (1 mm: a 16UC1 image in millimetres);
4. *edge shadows*: the stereo occlusion of an active-stereo pair whose second imager sits
   ``baseline_m`` to the right of the depth reference (the D435's left imager): a pixel is lost
   when, in the right imager, a nearer surface to its right covers it, i.e. when
   ``u - d(u) >= min over u' > u of (u' - d(u'))`` with ``d = fx B / z`` the disparity. This
   removes a band ``fx B (1/z_near - 1/z_far)`` pixels wide on the far side, to the left of each
   near object (6 px for a person at 3 m before a wall at 5.5 m);
5. *holes*: random dropouts in square blobs of ``hole_size_px`` pixels (a grid of cells at a
   random offset, each lost with probability ``hole_rate``), as low texture and specular spots
   give;
6. *range*: no reading nearer than ``min_range_m`` or farther than ``max_range_m``.

Deterministic for a generator's state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pose_lifter.mocap.body_surface import Background, RenderedDepth, render_depth, scene_backgrounds

__all__ = [
    "REALISTIC",
    "Background",
    "DepthSensor",
    "RenderedDepth",
    "render_depth",
    "scene_backgrounds",
    "sense",
    "silhouette",
    "stereo_shadow",
]


@dataclass(frozen=True)
class DepthSensor:
    """The faults of :func:`sense` (module docstring); lengths in metres, rates per pixel."""

    #: sigma_z = noise_c z^2 (per metre)
    noise_c: float = 0.0024
    #: side of the square window over which the noise is correlated (pixels; 1: independent pixels)
    noise_window_px: int = 3
    quantisation_m: float = 0.001
    #: fraction of a silhouette's pixels that read a depth between the near and far surfaces
    mixed_rate: float = 0.3
    #: a depth step larger than this between 4-neighbours is a silhouette
    edge_jump_m: float = 0.05
    #: stereo baseline: the edge shadows' width (0: no shadows)
    baseline_m: float = 0.05
    hole_rate: float = 0.02
    hole_size_px: int = 4
    min_range_m: float = 0.3
    max_range_m: float = 6.0

    def __post_init__(self) -> None:
        for name in ("noise_c", "quantisation_m", "edge_jump_m", "baseline_m", "min_range_m"):
            if not 0.0 <= getattr(self, name) < np.inf:
                raise ValueError(f"DepthSensor.{name} = {getattr(self, name)} must be finite and >= 0")
        for name in ("mixed_rate", "hole_rate"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"DepthSensor.{name} = {getattr(self, name)} not in [0, 1]")
        if self.noise_window_px < 1 or self.hole_size_px < 1:
            raise ValueError("DepthSensor.noise_window_px and hole_size_px must be >= 1")
        if not self.min_range_m < self.max_range_m:
            raise ValueError(f"DepthSensor range [{self.min_range_m}, {self.max_range_m}] is empty")


#: An active-stereo camera like the RealSense D435 (module docstring): noise 0.0024 z^2 (10 mm at
#: 2 m, 38 mm at 4 m) correlated over 3x3 pixels, 1 mm steps, 30 % of silhouette pixels mixed,
#: 50 mm baseline shadows, 2 % holes in 4x4 px blobs, readings from 0.3 to 6 m.
REALISTIC = DepthSensor()


def silhouette(depth: NDArray[np.floating], jump: float) -> NDArray[np.bool_]:
    """(H, W) pixels with a 4-neighbour whose depth differs by more than ``jump`` (an infinite
    depth, nothing, differs from every finite one)."""
    edge = np.zeros(depth.shape, dtype=bool)
    finite = np.isfinite(depth)
    with np.errstate(invalid="ignore"):
        for a, b in (((slice(1, None), slice(None)), (slice(None, -1), slice(None))),
                     ((slice(None), slice(1, None)), (slice(None), slice(None, -1)))):
            big = (np.abs(depth[a] - depth[b]) > jump) | (finite[a] != finite[b])
            edge[a] |= big
            edge[b] |= big
    return edge


def _mix(z: NDArray[np.float32], ideal: NDArray[np.float32], rate: float, jump: float,
         rng: np.random.Generator) -> None:
    """Mixed pixels, in place (module docstring, step 1): ``rate`` of the silhouette's pixels get
    a depth uniform between the nearest and farthest finite depths of their 3x3 neighbourhood."""
    rows, cols = np.nonzero(silhouette(ideal, jump))
    pick = rng.random(len(rows)) < rate
    rows, cols = rows[pick], cols[pick]
    padded = np.pad(ideal, 1, constant_values=np.inf)
    around = np.stack([padded[rows + dv, cols + du] for dv in range(3) for du in range(3)])  # (9, n)
    finite = np.isfinite(around)
    lo = np.where(finite, around, np.inf).min(axis=0)
    hi = np.where(finite, around, -np.inf).max(axis=0)
    ok = hi > lo
    rows, cols, lo, hi = rows[ok], cols[ok], lo[ok], hi[ok]
    z[rows, cols] = lo + rng.random(len(rows), dtype=np.float32) * (hi - lo)


def stereo_shadow(depth: NDArray[np.floating], fx: float, baseline: float) -> NDArray[np.bool_]:
    """(H, W) pixels hidden from the right imager of a stereo pair (module docstring, step 4):
    ``u - d(u) >= min over u' > u of (u' - d(u'))``, ``d = fx baseline / z`` (0 where inf)."""
    w = depth.shape[1]
    with np.errstate(divide="ignore"):
        disparity = (fx * baseline) / depth  # 0 where inf
    m = np.arange(w, dtype=depth.dtype)[None, :] - disparity
    after = np.full_like(m, np.inf)
    # the minimum over the columns to the right of each pixel
    after[:, :-1] = np.minimum.accumulate(m[:, :0:-1], axis=1)[:, ::-1]
    return np.asarray(m >= after)


def _correlated_normal(shape: tuple[int, int], window: int, rng: np.random.Generator) -> NDArray[np.float32]:
    """(H, W) standard normal field (unit variance per pixel), each pixel the mean of a
    ``window`` x ``window`` block of independent draws (so neighbours within it correlate)."""
    h, w = shape
    white = rng.standard_normal((h + window - 1, w + window - 1), dtype=np.float32)
    if window == 1:
        return white
    rows = white[:h].copy()
    for k in range(1, window):
        rows += white[k:k + h]
    out = rows[:, :w].copy()
    for k in range(1, window):
        out += rows[:, k:k + w]
    out /= np.float32(window)
    return out


def _holes(shape: tuple[int, int], rate: float, size: int, rng: np.random.Generator) -> NDArray[np.bool_]:
    """(H, W) pixels lost in square blobs: cells of ``size`` pixels at a random offset, each lost
    with probability ``rate``."""
    h, w = shape
    oy, ox = (int(o) for o in rng.integers(0, size, 2))
    cells = rng.random(((h + oy) // size + 1, (w + ox) // size + 1)) < rate
    grid = np.repeat(np.repeat(cells, size, axis=0), size, axis=1)
    return np.asarray(grid[oy:oy + h, ox:ox + w])


def sense(rendered: RenderedDepth, sensor: DepthSensor, rng: np.random.Generator) -> NDArray[np.float32]:
    """What the depth sensor reads of an ideal depth image (module docstring, steps 1-6).

    Parameters
    ----------
    rendered : RenderedDepth
    sensor : DepthSensor
    rng : numpy Generator

    Returns
    -------
    ndarray, shape (H, W), float32
        z-depth in metres, NaN where there is no reading.
    """
    ideal = rendered.depth.astype(np.float32)
    shape = (ideal.shape[0], ideal.shape[1])
    z = ideal.copy()
    if sensor.mixed_rate > 0:
        _mix(z, ideal, sensor.mixed_rate, sensor.edge_jump_m, rng)
    if sensor.noise_c > 0:
        z += np.float32(sensor.noise_c) * z * z * _correlated_normal(shape, sensor.noise_window_px, rng)
    if sensor.quantisation_m > 0:
        q = np.float32(sensor.quantisation_m)
        z = np.round(z / q) * q
    with np.errstate(invalid="ignore"):
        lost = ~((z >= sensor.min_range_m) & (z <= sensor.max_range_m))  # also NaN, inf
    if sensor.baseline_m > 0:
        lost |= stereo_shadow(ideal, rendered.intrinsics[0][0], sensor.baseline_m)
    if sensor.hole_rate > 0:
        lost |= _holes(shape, sensor.hole_rate, sensor.hole_size_px, rng)
    z[lost] = np.nan
    return z
