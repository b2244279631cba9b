"""The depth fusion's loops, compiled (:func:`pose_lifter.core.numeric.jit.njit`): the patch
readings, the occlusion test and the robust scale fit, one person or joint at a time over small
arrays, where numpy's per-call overhead would cost more than the arithmetic. Their meaning is
documented where they are called (:mod:`.reading`, :mod:`.fuse`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.numeric.jit import njit

__all__ = ["depth_fit_kernel", "hidden_kernel", "read_kernel"]

#: Tukey's biweight constant (95 % efficiency under Gaussian noise).
TUKEY = 4.685
#: A patch samples every ``int(radius / STRIDE_RADIUS)``-th pixel along rows and columns: at most
#: about ``pi STRIDE_RADIUS^2`` pixels however large the person (the sensor's noise is correlated
#: over neighbouring pixels, so more would add little).
STRIDE_RADIUS = 5.0


@njit
def read_kernel(img: NDArray[np.float32], pixels: NDArray[np.float64], radius: NDArray[np.float64],
                expected: NDArray[np.float64], band_m: float, band_fraction: float, min_pixels: int,
                min_fraction: float, trim: float, sensor_noise: float, noise_window: int, r_max: int,
                surface: NDArray[np.float64], var: NDArray[np.float64], n_used: NDArray[np.int64]) -> None:
    """Fill ``surface``, ``var`` and ``n_used`` (m,) with the readings of
    :func:`pose_lifter.core.depth.reading.read_patches` (its docstring: the same arguments)."""
    h, w = img.shape
    buf = np.empty((2 * r_max + 1) ** 2)
    dev = np.empty_like(buf)
    for i in range(len(pixels)):
        surface[i] = np.nan
        var[i] = np.nan
        n_used[i] = 0
        u, v = pixels[i, 0], pixels[i, 1]
        if not (math.isfinite(u) and math.isfinite(v)):
            continue
        cu, cv = int(np.rint(u)), int(np.rint(v))
        r2 = radius[i] * radius[i]
        stride = max(1, int(radius[i] / STRIDE_RADIUS))
        reach = int(radius[i])
        band = band_m + band_fraction * expected[i]
        n_patch = 0
        n = 0
        for dv in range(-reach, reach + 1, stride):
            for du in range(-reach, reach + 1, stride):
                if du * du + dv * dv > r2:
                    continue
                n_patch += 1
                row, col = cv + dv, cu + du
                if row < 0 or row >= h or col < 0 or col >= w:
                    continue
                z = float(img[row, col])
                if math.isfinite(z) and abs(z - expected[i]) <= band:
                    buf[n] = z
                    n += 1
        if n < min_pixels or n < min_fraction * n_patch:
            continue
        med = np.median(buf[:n])
        for k in range(n):
            dev[k] = abs(buf[k] - med)
        spread = 1.4826 * np.median(dev[:n])
        limit = trim * max(spread, max(sensor_noise * med * med, 1e-3))
        nk = 0
        for k in range(n):
            if dev[k] <= limit:
                buf[nk] = buf[k]
                nk += 1
        med2 = np.median(buf[:nk])
        s2 = 0.0
        for k in range(nk):
            s2 += (buf[k] - med2) ** 2
        s2 /= max(nk - 1, 1)
        sd = max(sensor_noise * med2 * med2, 1e-3)
        # independent draws among the samples: a stride shorter than the noise's correlation window
        # samples each window's one draw several times
        n_eff = max(1.0, nk * min(1.0, (stride / noise_window) ** 2))
        surface[i] = med2
        var[i] = 0.5 * math.pi * max(sd * sd, s2) / n_eff  # the median's variance
        n_used[i] = nk


@njit
def _trunk_entry(ru: float, rv: float, centre: NDArray[np.float64], axes: NDArray[np.float64],
                 extent: NDArray[np.float64], half_width: float, half_depth: float) -> float:
    """The z-depth where the ray ``t (ru, rv, 1)`` enters an elliptic cylinder (``axes`` (3, 3)
    rows: its width, spine and depth directions; ``centre`` (3,) its origin in those axes;
    ``extent`` (2,) its ends along the spine from it; half axes ``half_width`` x ``half_depth``),
    caps included; inf if it misses."""
    rr = np.empty(3)  # the ray in the cylinder's axes
    for i in range(3):
        rr[i] = axes[i, 0] * ru + axes[i, 1] * rv + axes[i, 2]
    iw, id2 = 1.0 / (half_width * half_width), 1.0 / (half_depth * half_depth)
    best = math.inf
    a = rr[0] * rr[0] * iw + rr[2] * rr[2] * id2
    b = -2.0 * (rr[0] * centre[0] * iw + rr[2] * centre[2] * id2)
    c = centre[0] * centre[0] * iw + centre[2] * centre[2] * id2 - 1.0
    disc = b * b - 4.0 * a * c
    if a > 1e-12 and disc > 0.0:
        t = (-b - math.sqrt(disc)) / (2.0 * a)
        s = t * rr[1] - centre[1]
        if t > 0.0 and extent[0] <= s <= extent[1]:
            best = t
    if abs(rr[1]) > 1e-12:  # the caps
        for e in range(2):
            t = (extent[e] + centre[1]) / rr[1]
            pw, pd = t * rr[0] - centre[0], t * rr[2] - centre[2]
            if 0.0 < t < best and pw * pw * iw + pd * pd * id2 <= 1.0:
                best = t
    return best


@njit
def hidden_kernel(proj: NDArray[np.float64], z: NDArray[np.float64], candidates: NDArray[np.bool_],
                  pixels: NDArray[np.float64], surface: NDArray[np.float64], limbs: NDArray[np.int64],
                  limb_radius: NDArray[np.float64], trunk_centre: NDArray[np.float64],
                  trunk_axes: NDArray[np.float64], trunk_extent: NDArray[np.float64], half_width: float,
                  half_depth: float, intrinsics: NDArray[np.float64], margin: float,
                  hidden: NDArray[np.bool_]) -> None:
    """Fill ``hidden`` (n, 12) for the occlusion test of :func:`pose_lifter.core.depth.fuse._hidden`:
    ``proj`` (n, 12, 2) the bodies' joints in the image, ``z`` (n, 12) their depths, ``pixels``
    (n, 12, 2) the keypoints, ``surface`` (n, 12) each joint's surface depth, ``limbs`` (8, 2),
    ``limb_radius`` (8,), each body's trunk (``trunk_centre`` (n, 3), ``trunk_axes`` (n, 3, 3),
    ``trunk_extent`` (n, 2), see :func:`_trunk_entry`), ``intrinsics`` (fx, fy, cx, cy)."""
    n = proj.shape[0]
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    focal = 0.5 * (fx + fy)
    for p in range(n):
        for j in range(proj.shape[1]):
            if not candidates[p, j]:
                continue
            qu, qv = pixels[p, j, 0], pixels[p, j, 1]
            limit = surface[p, j] - margin
            found = False
            for o in range(n):
                for li in range(limbs.shape[0]):
                    a, b = limbs[li, 0], limbs[li, 1]
                    if o == p and (a == j or b == j):
                        continue
                    au, av = proj[o, a, 0], proj[o, a, 1]
                    eu, ev = proj[o, b, 0] - au, proj[o, b, 1] - av
                    du, dv = qu - au, qv - av
                    tau = min(max((du * eu + dv * ev) / max(eu * eu + ev * ev, 1e-9), 0.0), 1.0)
                    dist = math.hypot(du - tau * eu, dv - tau * ev)
                    zs = z[o, a] + tau * (z[o, b] - z[o, a])
                    rad = limb_radius[li]
                    if dist < rad * focal / max(zs, 1e-3) and zs - rad < limit:
                        found = True
                        break
                if found:
                    break
                # the trunk, every body's own too: seen from the side it hides the far shoulder,
                # hip and an arm behind it
                if _trunk_entry((qu - cx) / fx, (qv - cy) / fy, trunk_centre[o], trunk_axes[o],
                                trunk_extent[o], half_width, half_depth) < limit:
                    found = True
                    break
            hidden[p, j] = found


@njit
def _normal_equations(d: NDArray[np.float64], v: NDArray[np.float64], g: NDArray[np.float64],
                      have: NDArray[np.bool_], shape_z: NDArray[np.float64], precision: NDArray[np.float64],
                      mean: NDArray[np.float64], theta: NDArray[np.float64]
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """One person's IRLS normal equations at ``theta`` (3,): ``A = sum w g g^T / sigma^2 + P`` and
    ``b = sum w d g / sigma^2 + P mean`` (Tukey's weights ``w`` of the residuals
    ``(d_j - g_j . theta) / sigma_j``, ``P`` the prior's diagonal ``precision``), and
    ``sum rho`` over its readings ``have`` (12,)."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for i in range(3):
        a[i, i] = precision[i]
        b[i] = precision[i] * mean[i]
    loss = 0.0
    for j in range(len(d)):
        if not have[j]:
            continue
        sig2 = v[j] + (theta[0] * shape_z[j]) ** 2
        m = g[j, 0] * theta[0] + g[j, 1] * theta[1] + g[j, 2] * theta[2]
        r = (d[j] - m) / math.sqrt(sig2)
        u = min((r / TUKEY) ** 2, 1.0)
        wt = (1.0 - u) ** 2 / sig2
        for i in range(3):
            b[i] += wt * d[j] * g[j, i]
            for k in range(3):
                a[i, k] += wt * g[j, i] * g[j, k]
        loss += TUKEY * TUKEY / 6.0 * (1.0 - (1.0 - u) ** 3)
    return a, b, loss


@njit
def depth_fit_kernel(d: NDArray[np.float64], v: NDArray[np.float64], g: NDArray[np.float64],
                     have: NDArray[np.bool_], shape_z: NDArray[np.float64], precision: NDArray[np.float64],
                     mean: NDArray[np.float64], theta0: NDArray[np.float64], max_iter: int, tol: float,
                     theta: NDArray[np.float64], cov: NDArray[np.float64], objective: NDArray[np.float64],
                     n_iter: NDArray[np.int64], converged: NDArray[np.bool_]) -> None:
    """The robust fit of each of ``n`` people's depth field (:func:`.fuse.fuse_readings`):
    readings ``d`` (n, 12) with variances ``v``, ``have`` the readings to fit, each joint's
    regressors ``g`` (n, 12, 3) (its placed depth and its offsets across the image), ``shape_z``
    (12,) the shape's depth error, a Gaussian prior (``mean`` (3,), each person's diagonal
    ``precision`` (n, 3)), from ``theta0`` (n, 3). Minimises
    ``sum_j rho((d_j - g_j . theta) / sigma_j) + (theta - mean)^T P (theta - mean) / 2`` (Tukey's rho,
    ``sigma_j^2 = v_j + (theta_0 shape_z_j)^2``) by iteratively reweighted least squares until no
    parameter moves by more than ``tol`` (relative, at least absolute) or ``max_iter``; fills
    ``theta``, its covariance ``cov`` (n, 3, 3; the inverse of the final normal matrix),
    ``objective``, ``n_iter`` and ``converged``."""
    for p in range(len(d)):
        th = theta0[p].copy()
        converged[p] = not have[p].any()
        it = 0
        while not converged[p] and it < max_iter:
            it += 1
            a, b, _ = _normal_equations(d[p], v[p], g[p], have[p], shape_z, precision[p], mean, th)
            new = np.linalg.solve(a, b)
            step = 0.0
            for i in range(3):
                step = max(step, abs(new[i] - th[i]) / max(1.0, abs(th[i])))
            converged[p] = step <= tol
            th = new
        n_iter[p] = it
        a, _, loss = _normal_equations(d[p], v[p], g[p], have[p], shape_z, precision[p], mean, th)
        theta[p] = th
        cov[p] = np.linalg.inv(a)
        prior = 0.0
        for i in range(3):
            prior += 0.5 * precision[p, i] * (th[i] - mean[i]) ** 2
        objective[p] = loss + prior
