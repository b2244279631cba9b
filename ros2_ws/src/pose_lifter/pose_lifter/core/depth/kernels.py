"""The depth fusion's loops, compiled (:func:`pose_lifter.core.numeric.jit.njit`): the patch
readings, the occlusion test, the robust scale fit and the fusion of the readings with the body,
one person or joint at a time over small arrays, where numpy's per-call overhead would cost more
than the arithmetic. Their meaning is documented where they are called (:mod:`.reading`,
:mod:`.fuse`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.numeric.jit import njit

__all__ = ["condition", "depth_fit_kernel", "field_kernel", "fuse_kernel", "hidden_kernel", "inlier",
           "leave_one_out", "masked_median", "read_kernel", "read_people_kernel"]

#: Tukey's biweight constant (95 % efficiency under Gaussian noise).
TUKEY = 4.685
#: The order of :func:`read_kernel`'s ``settings``: the band's half width and its fraction of the
#: depth, the least pixels and share of the patch, the trim, the sensor's noise, its correlation
#: window (pixels) and the largest patch radius (pixels)
#: (:class:`~pose_lifter.core.depth.reading.DepthOptions`).
READ_SETTINGS = ("band_m", "band_fraction", "min_pixels", "min_fraction", "trim", "sensor_noise",
                 "noise_window_px", "max_patch_px")
#: A patch samples every ``int(radius / STRIDE_RADIUS)``-th pixel along rows and columns: at most
#: about ``pi STRIDE_RADIUS^2`` pixels however large the person (the sensor's noise is correlated
#: over neighbouring pixels, so more would add little).
STRIDE_RADIUS = 5.0


@njit
def read_kernel(img: NDArray[np.float32] | NDArray[np.uint16], millimetres: bool,
                pixels: NDArray[np.float64], radius: NDArray[np.float64], expected: NDArray[np.float64],
                settings: NDArray[np.float64], surface: NDArray[np.float64], var: NDArray[np.float64],
                n_used: NDArray[np.int64]) -> None:
    """Fill ``surface``, ``var`` and ``n_used`` (m,) with the readings of
    :func:`pose_lifter.core.depth.reading.read_patches` (its docstring: the same arguments;
    ``settings`` (8,) its options in the order of :data:`READ_SETTINGS`);
    ``millimetres``: ``img`` holds uint16 millimetres (0: no reading), each pixel read as the
    float32 metres ``mm / 1000`` (correctly rounded), else float32 metres."""
    band_m, band_fraction, min_fraction, trim, sensor_noise = (settings[0], settings[1], settings[3],
                                                                 settings[4], settings[5])
    min_pixels, noise_window, r_max = int(settings[2]), int(settings[6]), int(settings[7])
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
                pixel = img[row, col]
                if millimetres:
                    z = float(np.float32(pixel) / np.float32(1000.0)) if pixel != 0 else math.nan
                else:
                    z = float(pixel)
                if math.isfinite(z) and abs(z - expected[i]) <= band:
                    buf[n] = z
                    n += 1
        if n < min_pixels or n < min_fraction * n_patch:
            continue
        med = np.median(buf[:n])
        widest = 0.0
        for k in range(n):
            dev[k] = abs(buf[k] - med)
            widest = max(widest, dev[k])
        floor = trim * max(sensor_noise * med * med, 1e-3)
        nk = n
        med2 = med
        if widest > floor:  # else no pixel is trimmed, whatever the spread: the median stands
            spread = 1.4826 * np.median(dev[:n])
            limit = trim * max(spread, max(sensor_noise * med * med, 1e-3))
            nk = 0
            for k in range(n):
                if dev[k] <= limit:
                    buf[nk] = buf[k]
                    nk += 1
            if nk < n:
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
def read_people_kernel(img: NDArray[np.float32] | NDArray[np.uint16], millimetres: bool,
                       pixels: NDArray[np.float64], radius: NDArray[np.float64], z0: NDArray[np.float64],
                       observed: NDArray[np.bool_], settings: NDArray[np.float64],
                       surface: NDArray[np.float64], var: NDArray[np.float64]) -> None:
    """Fill ``surface`` and ``var`` (n, 12) with the patch readings (:func:`read_kernel`) of the
    keypoints ``pixels`` (n, 12, 2) of ``n`` people (patch radii ``radius`` (n, 12), already
    clipped), each person's depth band centred on its depth as the image shows it: the median of
    the readings of its ``observed`` (n, 12) keypoints' patches without a band about its placed
    depths ``z0`` (n, 12) (0 for a person without any)."""
    n, m = z0.shape
    seen = np.empty((n, m))
    seen_var = np.empty(n * m)
    used = np.empty(n * m, dtype=np.int64)
    unbanded = settings.copy()
    unbanded[0] = np.inf
    read_kernel(img, millimetres, pixels.reshape(n * m, 2), radius.reshape(n * m), z0.reshape(n * m),
                unbanded, seen.reshape(n * m), seen_var, used)
    centre = np.empty(n)
    masked_median(seen, observed & np.isfinite(seen), 0.0, centre)
    expected = np.empty((n, m))
    for p in range(n):
        expected[p] = centre[p]
    read_kernel(img, millimetres, pixels.reshape(n * m, 2), radius.reshape(n * m), expected.reshape(n * m),
                settings, surface.reshape(n * m), var.reshape(n * m), used)


@njit
def masked_median(values: NDArray[np.float64], mask: NDArray[np.bool_], empty: float,
                  out: NDArray[np.float64]) -> None:
    """Fill ``out`` (n,) with each row's median of ``values`` (n, m) where ``mask`` (the mean of
    the middle two of an even count), ``empty`` for a row without any."""
    buf = np.empty(values.shape[1])
    for i in range(values.shape[0]):
        c = 0
        for j in range(values.shape[1]):
            if mask[i, j]:
                buf[c] = values[i, j]
                c += 1
        if c == 0:
            out[i] = empty
            continue
        head = buf[:c]
        head.sort()
        out[i] = 0.5 * (head[(c - 1) // 2] + head[c // 2])


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
    ``proj`` (n, m, 2) the bodies' occluder points in the image (the 12 joints first), ``z`` (n, m)
    their depths, ``pixels`` (n, 12, 2) the keypoints, ``surface`` (n, 12) each joint's surface
    depth, ``limbs`` (k, 2) segments between the points, ``limb_radius`` (k,), each body's trunk
    (``trunk_centre`` (n, 3), ``trunk_axes`` (n, 3, 3), ``trunk_extent`` (n, 2), see
    :func:`_trunk_entry`), ``intrinsics`` (fx, fy, cx, cy)."""
    n = proj.shape[0]
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    focal = 0.5 * (fx + fy)
    for p in range(n):
        for j in range(candidates.shape[1]):
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
def field_kernel(x0: NDArray[np.float64], observed: NDArray[np.bool_], depth_m: NDArray[np.float64],
                 var: NDArray[np.float64], have: NDArray[np.bool_], d: NDArray[np.float64],
                 v: NDArray[np.float64], g: NDArray[np.float64], theta0: NDArray[np.float64]) -> None:
    """The depth field's data of ``n`` people (:func:`depth_fit_kernel`'s), from their placed joints
    ``x0`` (n, 12, 3), ``observed`` (n, 12) keypoints and depth readings ``depth_m`` (n, 12) of
    variances ``var`` (NaN where none): fill ``have`` (n, 12) (a reading of an observed joint
    placed in front of the camera), ``d`` and ``v`` (its readings and variances; 0 and 1
    elsewhere), ``g`` (n, 12, 3) (each joint's placed depth and its offsets across the image from
    the body's centroid, y then x) and ``theta0`` (n, 3) (the median of ``d_j / z0_j``, 1 for a
    body without readings, and no tilt)."""
    n, m = d.shape
    ratio = np.empty((n, m))
    for p in range(n):
        mean_x, mean_y = 0.0, 0.0
        for j in range(m):
            mean_x += x0[p, j, 0]
            mean_y += x0[p, j, 1]
        mean_x /= m
        mean_y /= m
        for j in range(m):
            z0 = x0[p, j, 2]
            have[p, j] = math.isfinite(depth_m[p, j]) and observed[p, j] and z0 > 0
            d[p, j] = depth_m[p, j] if have[p, j] else 0.0
            v[p, j] = var[p, j] if have[p, j] else 1.0
            ratio[p, j] = d[p, j] / (z0 if z0 > 0 else 1.0)
            g[p, j, 0] = z0
            g[p, j, 1] = x0[p, j, 1] - mean_y
            g[p, j, 2] = x0[p, j, 0] - mean_x
        theta0[p, 1] = 0.0
        theta0[p, 2] = 0.0
    k0 = np.empty(n)
    masked_median(ratio, have, 1.0, k0)
    for p in range(n):
        theta0[p, 0] = k0[p]


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



@njit
def inlier(residual: float, var: float, band: float, share: float) -> float:
    """The probability that a reading is its joint's, from its ``residual`` of variance ``var`` if
    it is (Gaussian), against a stray surface (probability ``share``) uniform over the depth
    ``band``."""
    dens = math.exp(-0.5 * residual * residual / var) / math.sqrt(2.0 * math.pi * var)
    return (1.0 - share) * dens / ((1.0 - share) * dens + share / band)


@njit
def leave_one_out(prior: NDArray[np.float64], residual: NDArray[np.float64], noise: NDArray[np.float64],
                  loo: NDArray[np.float64], loo_var: NDArray[np.float64]) -> None:
    """Fill ``loo`` (m,) with each reading's residual from its joint's depth as the Gaussian
    ``N(0, prior)`` (``prior`` (m, m)) conditioned on the other readings (``residual`` (m,) about
    the prior's mean, 0 where there is none; variances ``noise`` (m,), a large one where there is
    none) predicts it, and ``loo_var`` (m,) with that prediction's variance (the reading's own noise
    not included, at least ``1e-3`` of the prior's): ``a_j / C_jj`` and ``1 / C_jj - noise_j``,
    ``C = (prior + diag(noise))^-1``, ``a = C residual`` (the closed form of leaving one
    observation out of a Gaussian conditioning)."""
    m = len(residual)
    system = prior.copy()
    for j in range(m):
        system[j, j] += noise[j]
    inv = np.linalg.solve(system, np.eye(m))
    for j in range(m):
        a = 0.0
        for k in range(m):
            a += inv[j, k] * residual[k]
        loo[j] = a / inv[j, j]
        loo_var[j] = max(1.0 / inv[j, j] - noise[j], 1e-3 * prior[j, j])


@njit
def condition(prior: NDArray[np.float64], residual: NDArray[np.float64], noise: NDArray[np.float64],
              shift: NDArray[np.float64], sd: NDArray[np.float64]) -> None:
    """The Gaussian ``N(mean, prior)`` (``prior`` (m, m)) conditioned on readings ``d_j = z_j + e_j``,
    ``e_j ~ N(0, noise_j)`` (``residual`` (m,) = ``d - mean``, 0 where there is none; ``noise``
    (m,), a large variance where there is none): fill ``shift`` (m,) with the conditional mean
    minus ``mean`` (``prior (prior + diag(noise))^-1 residual``) and ``sd`` (m,) with the
    conditional standard deviations (at least ``sqrt(1e-3)`` of the prior's)."""
    m = len(residual)
    system = prior.copy()
    for j in range(m):
        system[j, j] += noise[j]
    x = np.linalg.solve(system, prior)  # its transpose is prior @ system^-1, the gain
    for j in range(m):
        z = 0.0
        post = prior[j, j]
        for k in range(m):
            z += x[k, j] * residual[k]
            post -= x[k, j] * prior[k, j]
        shift[j] = z
        sd[j] = math.sqrt(max(post, 1e-3 * prior[j, j]))


@njit
def fuse_kernel(x0: NDArray[np.float64], g: NDArray[np.float64], d: NDArray[np.float64],
                v: NDArray[np.float64], have: NDArray[np.bool_], theta: NDArray[np.float64],
                cov: NDArray[np.float64], shape: NDArray[np.float64], shape_model: NDArray[np.float64],
                mono_scale: NDArray[np.float64], settings: NDArray[np.float64],
                joints: NDArray[np.float64], std: NDArray[np.float64], kept: NDArray[np.bool_],
                placeable: NDArray[np.bool_]) -> None:
    """Steps 4c-5 of :func:`pose_lifter.core.depth.fuse.fuse_readings` (the module docstring of
    :mod:`.fuse`) for ``n`` people, after the depth field's fit: their placed joints ``x0``
    (n, 12, 3), the fit's regressors ``g`` (n, 12, 3), readings ``d`` (n, 12) of variances ``v``
    (``have`` the readings fitted; 0 and 1 elsewhere), the field ``theta`` (n, 3) and its
    covariance ``cov`` (n, 3, 3), the shape's standard deviations ``shape`` (n, 12, 3), its depth
    correlations and the fit's shape depth errors ``shape_model`` (12, 13: the correlations (12,
    12), then the errors as the last column), the monocular scale errors ``mono_scale`` (n,), and
    the options ``settings`` (6,): ``gate``, ``band_m``, ``band_fraction``, ``share`` the outlier
    share, ``min_inlier`` the least inlier probability in the leave-one-out predictions,
    ``unread_var`` the variance of a joint without a reading. Fills ``joints`` and ``std`` (n, 12,
    3), the readings ``kept`` (n, 12) and the bodies the field
    places (``placeable`` (n,)); a body it does not place keeps its monocular placement and its
    uncertainty."""
    gate, band_m, band_fraction, share, min_inlier, unread_var = (settings[0], settings[1], settings[2],
                                                                  settings[3], settings[4], settings[5])
    shape_corr, shape_z = shape_model[:, :-1], shape_model[:, -1]
    n, m = d.shape
    model_z = np.empty(m)
    body = np.empty((m, 3))
    root = np.empty((m, 3))
    band = np.empty(m)
    p_in = np.empty(m)
    res = np.empty(m)
    noise = np.empty(m)
    prior = np.empty((m, m))
    loo = np.empty(m)
    loo_var = np.empty(m)
    shift = np.empty(m)
    z_sd = np.empty(m)
    for p in range(n):
        # readings beyond the gate of the field dropped; a field of a non-positive depth places nothing
        ok = False
        fin = True
        for j in range(m):
            model_z[j] = g[p, j, 0] * theta[p, 0] + g[p, j, 1] * theta[p, 1] + g[p, j, 2] * theta[p, 2]
            r = (d[p, j] - model_z[j]) / math.sqrt(v[p, j] + (theta[p, 0] * shape_z[j]) ** 2)
            kept[p, j] = have[p, j] and abs(r) <= gate
            ok = ok or kept[p, j]
            fin = fin and math.isfinite(model_z[j]) and model_z[j] > 0
        placeable[p] = ok and fin
        mono = not placeable[p]
        # the body along its rays at the field's depths; each joint's error along its ray
        for j in range(m):
            kept[p, j] = kept[p, j] and placeable[p]
            if mono:
                model_z[j] = x0[p, j, 2]
                sd = mono_scale[p]
            else:
                q = 0.0
                for c in range(3):
                    for e in range(3):
                        q += g[p, j, c] * cov[p, c, e] * g[p, j, e]
                sd = math.sqrt(q) / model_z[j]
            f = model_z[j] / x0[p, j, 2]
            for c in range(3):
                body[j, c] = x0[p, j, c] * f
                root[j, c] = sd * abs(body[j, c])
            band[j] = 2.0 * (band_m + band_fraction * model_z[j])
            res[j] = d[p, j] - model_z[j] if kept[p, j] else 0.0
            var_body = shape[p, j, 2] ** 2 + root[j, 2] ** 2
            p_in[j] = inlier(res[j], var_body + v[p, j], band[j], share) if kept[p, j] else 0.0
        # the true depths' covariance about the field's: the shape's plus the field's (or the
        # monocular placement's scale error, fully correlated)
        for j in range(m):
            for k in range(m):
                if mono:
                    field = root[j, 2] * root[k, 2]
                else:
                    field = 0.0
                    for c in range(3):
                        for e in range(3):
                            field += g[p, j, c] * cov[p, c, e] * g[p, k, e]
                prior[j, k] = shape[p, j, 2] * shape_corr[j, k] * shape[p, k, 2] + field
            noise[j] = v[p, j] / max(p_in[j], min_inlier) if kept[p, j] else unread_var
        # each reading against what the others predict of its joint; then the conditioning
        leave_one_out(prior, res, noise, loo, loo_var)
        for j in range(m):
            p_in[j] = inlier(loo[j], loo_var[j] + v[p, j], band[j], share) if kept[p, j] else 0.0
            kept[p, j] = kept[p, j] and p_in[j] >= 0.5
            noise[j] = v[p, j] / max(p_in[j], 0.5) if kept[p, j] else unread_var
            res[j] = d[p, j] - model_z[j] if kept[p, j] else 0.0
        condition(prior, res, noise, shift, z_sd)
        for j in range(m):
            z = model_z[j] + shift[j]
            # a joint without its own reading keeps its marginal deviation (fuse_readings)
            sd_j = z_sd[j] if kept[p, j] else math.sqrt(prior[j, j])
            for c in range(3):
                joints[p, j, c] = body[j, c] * (z / model_z[j])
                other = abs(joints[p, j, c]) * (sd_j / z) if kept[p, j] else root[j, c]
                std[p, j, c] = math.sqrt(shape[p, j, c] ** 2 + other ** 2)
            std[p, j, 2] = sd_j
