"""The depth fusion's compiled kernels (pose_lifter.core.depth.kernels) against numpy versions of
the same arithmetic, written as the fusion's module docstring states it (whole-array operations
over the ``n`` people of a frame)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from pose_lifter.core.depth.fuse import _MIN_INLIER, _UNREAD_VAR, fuse_depth
from pose_lifter.core.depth.kernels import STRIDE_RADIUS, field_kernel, fuse_kernel, masked_median
from pose_lifter.core.depth.reading import DepthOptions, read_patches, read_people
from pose_lifter.core.depth.uncertainty import SHAPE_CORR_Z, SHAPE_STD_M, shape_std
from tolerances import ROUND_OFF

N = 12


def _inlier(residual: NDArray[np.float64], var: NDArray[np.float64], kept: NDArray[np.bool_],
            band: NDArray[np.float64], share: float) -> NDArray[np.float64]:
    dens = np.exp(-0.5 * residual**2 / var) / np.sqrt(2.0 * np.pi * var)
    return np.where(kept, (1.0 - share) * dens / ((1.0 - share) * dens + share / band), 0.0)


def _conditioned(prior: NDArray[np.float64], residual: NDArray[np.float64], v: NDArray[np.float64],
                 kept: NDArray[np.bool_]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                   NDArray[np.float64], NDArray[np.float64]]:
    """The leave-one-out residuals and variances, and the conditional shifts and deviations, of
    ``N(0, prior)`` given the ``kept`` residuals of variances ``v`` (n, 12)."""
    noise = np.where(kept, v, _UNREAD_VAR)
    system = prior + noise[:, :, None] * np.eye(N)[None]
    inv = np.linalg.inv(system)
    diag = np.diagonal(inv, axis1=1, axis2=2)
    res = np.where(kept, residual, 0.0)
    a = np.einsum("njk,nk->nj", inv, res)
    prior_diag = np.diagonal(prior, axis1=1, axis2=2)
    loo_var = np.maximum(1.0 / diag - noise, 1e-3 * prior_diag)
    gain = prior @ inv
    post = np.diagonal(prior - gain @ prior, axis1=1, axis2=2)
    return a / diag, loo_var, np.einsum("njk,nk->nj", gain, res), np.sqrt(np.maximum(post, 1e-3 * prior_diag))


def _fuse_numpy(x0: NDArray[np.float64], g: NDArray[np.float64], d: NDArray[np.float64],
                v: NDArray[np.float64], have: NDArray[np.bool_], theta: NDArray[np.float64],
                cov: NDArray[np.float64], observed: NDArray[np.bool_], mono_scale: NDArray[np.float64],
                opt: DepthOptions) -> tuple[NDArray[np.float64], ...]:
    """Steps 4c-5 of the fusion in numpy (:func:`~pose_lifter.core.depth.kernels.fuse_kernel`'s
    arguments): joints, std, kept, placeable."""
    shape_z = SHAPE_STD_M[:, 1]
    model_z = np.einsum("njc,nc->nj", g, theta)
    r = (d - model_z) / np.sqrt(v + (theta[:, :1] * shape_z[None]) ** 2)
    kept = have & (np.abs(r) <= opt.gate)
    placeable = np.isfinite(model_z).all(axis=1) & (model_z > 0).all(axis=1) & kept.any(axis=1)
    kept &= placeable[:, None]
    mono = ~placeable
    model_z[mono] = x0[mono, :, 2]
    body = x0 * (model_z / x0[..., 2])[..., None]
    shape = shape_std(observed)
    along_sd = np.sqrt(np.einsum("njc,ncd,njd->nj", g, cov, g)) / model_z
    along_sd[mono] = mono_scale[mono, None]
    root = along_sd[..., None] * np.abs(body)
    band = 2.0 * (opt.band_m + opt.band_fraction * model_z)
    p_in = _inlier(d - model_z, shape[..., 2] ** 2 + root[..., 2] ** 2 + v, kept, band, opt.outlier_share)
    field = np.einsum("njc,ncd,nkd->njk", g, cov, g)
    place = root[..., 2][:, :, None] * root[..., 2][:, None, :]
    prior = (shape[..., 2][:, :, None] * SHAPE_CORR_Z[None] * shape[..., 2][:, None, :]
             + np.where(mono[:, None, None], place, field))
    loo, loo_var, _, _ = _conditioned(prior, d - model_z, v / np.maximum(p_in, _MIN_INLIER), kept)
    p_in = _inlier(loo, loo_var + v, kept, band, opt.outlier_share)
    kept &= p_in >= 0.5
    _, _, shift, z_std = _conditioned(prior, d - model_z, v / np.maximum(p_in, 0.5), kept)
    z = model_z + shift
    z_std = np.where(kept, z_std, np.sqrt(np.diagonal(prior, axis1=1, axis2=2)))
    joints = body * (z / model_z)[..., None]
    along = np.abs(joints) * (z_std / z)[..., None]
    std = np.where(kept[..., None], np.sqrt(shape**2 + along**2), np.sqrt(shape**2 + root**2))
    std[..., 2] = z_std
    return joints, std, kept, placeable


def _frame(seed: int) -> tuple[NDArray[np.float64], ...]:
    """Four people's fusion inputs: one read whole with a few stray readings, one read at three
    joints, one without readings, and one whose field puts it behind the camera."""
    rng = np.random.default_rng(seed)
    n = 4
    x0 = rng.normal(0.0, 0.3, (n, N, 3)) + np.array([0.0, 0.0, 1.0]) * rng.uniform(2.0, 6.0, (n, 1, 1))
    lateral = x0[..., :2] - x0[..., :2].mean(axis=1, keepdims=True)
    g = np.ascontiguousarray(np.concatenate([x0[..., 2:], lateral[..., ::-1]], axis=-1))
    theta = np.column_stack([rng.uniform(0.9, 1.1, n), rng.normal(0.0, 0.05, (n, 2))])
    theta[3, 0] = -1.0
    d = np.einsum("njc,nc->nj", g, theta) + rng.normal(0.0, 0.02, (n, N))
    d[0, rng.choice(N, 3, replace=False)] -= rng.uniform(0.1, 0.4, 3)  # stray surfaces
    v = rng.uniform(1e-4, 1e-3, (n, N))
    have = np.ones((n, N), dtype=bool)
    have[1] = False
    have[1, [0, 4, 7]] = True
    have[2] = False
    d, v = np.where(have, d, 0.0), np.where(have, v, 1.0)
    a = rng.normal(0.0, 0.01, (n, 3, 3))
    cov = a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(3)
    observed = rng.random((n, N)) < 0.9
    return x0, g, d, v, have, theta, cov, observed


@pytest.mark.parametrize("seed", range(5))
def test_the_fusion_kernel_is_the_numpy_fusion(seed: int) -> None:
    """:func:`fuse_kernel` against :func:`_fuse_numpy` (the same steps on whole arrays): the same
    readings kept and bodies placed, the same joints and deviations up to round-off."""
    x0, g, d, v, have, theta, cov, observed = _frame(seed)
    opt = DepthOptions()
    mono_scale = np.array([0.055, 0.06, 0.378, 0.43])
    n = len(x0)
    joints, std = np.empty((n, N, 3)), np.empty((n, N, 3))
    kept, placeable = np.empty((n, N), dtype=bool), np.empty(n, dtype=bool)
    settings = np.array([opt.gate, opt.band_m, opt.band_fraction, opt.outlier_share, _MIN_INLIER,
                         _UNREAD_VAR])
    model = np.column_stack([SHAPE_CORR_Z, SHAPE_STD_M[:, 1]])
    fuse_kernel(x0, g, d, v, have, theta, cov, shape_std(observed), model, mono_scale, settings, joints, std,
                kept, placeable)
    want = _fuse_numpy(x0, g, d, v, have, theta, cov, observed, mono_scale, opt)
    assert placeable.tolist() == [True, True, False, False] == want[3].tolist()
    assert np.array_equal(kept, want[2]) and not kept[0].all() and kept[0].sum() > 6
    assert np.abs(joints - want[0]).max() < ROUND_OFF
    assert np.abs(std - want[1]).max() < ROUND_OFF
    assert np.array_equal(joints[2:], x0[2:])  # not placed: the monocular placement


def test_millimetres_are_read_as_their_float32_metres() -> None:
    """A uint16 millimetre image (0: no reading) gives the patch readings and the fusion of the
    float32 metres it converts to (``mm / 1000`` correctly rounded, NaN for 0), bit for bit."""
    rng = np.random.default_rng(9)
    mm = rng.integers(2900, 3100, (120, 160)).astype(np.uint16)
    mm[rng.random(mm.shape) < 0.2] = 0
    mm[:, :30] = 6000  # a wall behind
    metres = np.where(mm > 0, mm.astype(np.float32) / np.float32(1000.0), np.float32(np.nan))
    pixels = np.column_stack([rng.uniform(-5.0, 165.0, 60), rng.uniform(-5.0, 125.0, 60)])
    radius, expected = rng.uniform(1.0, 12.0, 60), rng.uniform(2.8, 3.2, 60)
    for opt in (DepthOptions(), DepthOptions(band_m=np.inf)):
        a = read_patches(mm, pixels, radius, expected, opt)
        b = read_patches(metres, pixels, radius, expected, opt)
        assert np.isfinite(a.surface).sum() > 30
        for x, y in ((a.surface, b.surface), (a.var, b.var), (a.n_pixels, b.n_pixels)):
            np.testing.assert_array_equal(x, y)
    grid = np.linspace(-0.5, 0.5, N)
    pose = np.stack([grid, grid[::-1], 0.2 * grid], axis=-1)[None]
    args = (((100.0, 100.0), (80.0, 60.0)), 80.0 + 20.0 * pose[..., :2], np.ones((1, N)), pose,
            np.array([14.0]), np.array([[80.0, 60.0]]))
    x, y = fuse_depth(mm, *args), fuse_depth(metres, *args)
    assert x.from_depth.any()
    np.testing.assert_array_equal(x.joints_m, y.joints_m)
    np.testing.assert_array_equal(x.std_m, y.std_m)


def test_masked_median_is_numpys_median_of_the_masked_values() -> None:
    """:func:`masked_median` of each row against ``np.median`` of its masked values (odd and even
    counts, ties, a row without any: ``empty``)."""
    rng = np.random.default_rng(10)
    values = rng.normal(3.0, 0.5, (200, N))
    values[::7, :4] = 2.5  # ties
    mask = rng.random((200, N)) < rng.random((200, 1))
    mask[0] = False
    out = np.empty(200)
    masked_median(values, mask, -1.0, out)
    want = np.array([np.median(v[m]) if m.any() else -1.0 for v, m in zip(values, mask, strict=True)])
    np.testing.assert_array_equal(out, want)
    assert len({int(c) for c in mask.sum(axis=1) % 2}) == 2


def _read_numpy(img: NDArray[np.float32], u: float, v: float, radius: float, expected: float,
                opt: DepthOptions) -> tuple[float, float, int]:
    """One patch reading of :func:`read_patches` in numpy: the in-band pixels of the strided disk,
    their median, the pixels within ``trim`` robust (or sensor) deviations of it, their median and
    its variance (the spread about the median, or the sensor's)."""
    r = float(np.clip(radius, opt.min_patch_px, opt.max_patch_px))
    stride, reach = max(1, int(r / STRIDE_RADIUS)), int(r)
    dv, du = np.meshgrid(np.arange(-reach, reach + 1, stride), np.arange(-reach, reach + 1, stride),
                         indexing="ij")
    disk = (du**2 + dv**2 <= r * r).ravel()
    rows, cols = (int(np.rint(v)) + dv).ravel()[disk], (int(np.rint(u)) + du).ravel()[disk]
    inside = (rows >= 0) & (rows < img.shape[0]) & (cols >= 0) & (cols < img.shape[1])
    z = img[rows[inside], cols[inside]].astype(np.float64)
    z = z[np.isfinite(z) & (np.abs(z - expected) <= opt.band_m + opt.band_fraction * expected)]
    if len(z) < opt.min_pixels or len(z) < opt.min_fraction * disk.sum():
        return np.nan, np.nan, 0
    med = np.median(z)
    spread = 1.4826 * np.median(np.abs(z - med))
    z = z[np.abs(z - med) <= opt.trim * max(spread, opt.sensor_noise * med**2, 1e-3)]
    med = np.median(z)
    sd = max(opt.sensor_noise * med**2, 1e-3)
    n_eff = max(1.0, len(z) * min(1.0, (stride / opt.noise_window_px) ** 2))
    s2 = np.sum((z - med) ** 2) / max(len(z) - 1, 1)  # the spread about the median
    return med, 0.5 * np.pi * max(sd * sd, s2) / n_eff, len(z)


def test_the_patch_reading_is_the_numpy_reading() -> None:
    """:func:`read_patches` against :func:`_read_numpy` on a body-like surface with a wall behind,
    holes, mixed pixels at its edges and patches of every size: the same readings (the kernel
    skips the spread and the second median where no pixel can be trimmed)."""
    rng = np.random.default_rng(11)
    img = np.full((120, 160), 5.0, dtype=np.float32)
    img[20:100, 40:120] = (3.0 + 0.01 * rng.standard_normal((80, 80))).astype(np.float32)
    img[rng.random(img.shape) < 0.1] = np.nan
    img[20:100, 40:42] = 4.0  # mixed pixels
    pixels = np.column_stack([rng.uniform(30.0, 130.0, 80), rng.uniform(10.0, 110.0, 80)])
    radius = rng.uniform(1.0, 14.0, 80)
    for opt in (DepthOptions(), DepthOptions(band_m=np.inf), DepthOptions(sensor_noise=0.0)):
        got = read_patches(img, pixels, radius, np.full(80, 3.0), opt)
        want = np.array([_read_numpy(img, u, v, r, 3.0, opt)
                         for (u, v), r in zip(pixels, radius, strict=True)])
        np.testing.assert_array_equal(got.surface, want[:, 0])
        np.testing.assert_array_equal(got.n_pixels, want[:, 2])
        finite = np.isfinite(want[:, 1])
        assert np.array_equal(np.isfinite(got.var), finite) and finite.sum() > 40
        np.testing.assert_allclose(got.var[finite], want[finite, 1], rtol=ROUND_OFF)


def test_people_are_read_about_their_depth_in_the_image() -> None:
    """:func:`read_people` against its two steps with :func:`read_patches`: the patches read
    without a band about the placed depths, each person's band centred on the median of its
    observed keypoints' readings (0 without any), the patches read again (float32 and uint16
    images alike)."""
    rng = np.random.default_rng(12)
    mm = rng.integers(2950, 3050, (120, 160)).astype(np.uint16)
    mm[:, 100:] = rng.integers(4450, 4550, (120, 60))  # a second person behind
    mm[rng.random(mm.shape) < 0.15] = 0
    metres = np.where(mm > 0, mm.astype(np.float32) / np.float32(1000.0), np.float32(np.nan))
    pixels = np.stack([np.column_stack([rng.uniform(10, 90, N), rng.uniform(10, 110, N)]),
                       np.column_stack([rng.uniform(110, 150, N), rng.uniform(10, 110, N)]),
                       np.column_stack([rng.uniform(10, 150, N), rng.uniform(10, 110, N)])])
    radius = rng.uniform(2.0, 9.0, (3, N))
    z0 = np.stack([np.full(N, 2.0), np.full(N, 5.5), np.full(N, 3.0)])  # placed far off
    observed = rng.random((3, N)) < 0.8
    observed[2] = False  # no keypoint to place the band: centred on 0, nothing read
    opt = DepthOptions()
    for img in (mm, metres):
        surface, var = read_people(img, pixels, radius, z0, observed, opt)
        raw = read_patches(img, pixels.reshape(-1, 2), radius.ravel(), z0.ravel(),
                           DepthOptions(band_m=np.inf)).surface.reshape(3, N)
        centre = [np.median(r[o & np.isfinite(r)]) if (o & np.isfinite(r)).any() else 0.0
                  for r, o in zip(raw, observed, strict=True)]
        want = read_patches(img, pixels.reshape(-1, 2), radius.ravel(), np.repeat(centre, N), opt)
        np.testing.assert_array_equal(surface.ravel(), want.surface)
        np.testing.assert_array_equal(var.ravel(), want.var)
        assert np.isfinite(surface[:2]).sum() > 15 and not np.isfinite(surface[2]).any()
        assert abs(np.nanmedian(surface[1]) - 4.5) < 0.05


def test_the_field_data_are_the_numpy_ones() -> None:
    """:func:`field_kernel` against numpy: the readings fitted (finite, observed, placed in front
    of the camera), their values and variances (0 and 1 elsewhere), the regressors (placed depth,
    then the offsets across the image, y and x, from the centroid) and the first scale (the median
    of ``d_j / z0_j``, 1 without readings)."""
    x0, _, d, v, have, _, _, observed = _frame(13)
    x0[0, 3, 2] = -0.5  # behind the camera
    depth_m, var = np.where(have, d, np.nan), np.where(have, v, np.nan)
    n = len(x0)
    got = (np.empty((n, N), dtype=bool), np.empty((n, N)), np.empty((n, N)), np.empty((n, N, 3)),
           np.empty((n, 3)))
    field_kernel(x0, observed, depth_m, var, *got)
    z0 = x0[..., 2]
    want_have = np.isfinite(depth_m) & observed & (z0 > 0)
    want_d = np.where(want_have, depth_m, 0.0)
    lateral = x0[..., :2] - x0[..., :2].mean(axis=1, keepdims=True)
    k0 = [np.median((want_d / np.where(z0 > 0, z0, 1.0))[p][want_have[p]]) if want_have[p].any() else 1.0
          for p in range(n)]
    assert np.array_equal(got[0], want_have) and not got[0][0, 3]
    np.testing.assert_array_equal(got[1], want_d)
    np.testing.assert_array_equal(got[2], np.where(want_have, var, 1.0))
    np.testing.assert_allclose(got[3], np.concatenate([z0[..., None], lateral[..., ::-1]], axis=-1),
                               rtol=0.0, atol=ROUND_OFF)
    np.testing.assert_array_equal(got[4], np.column_stack([k0, np.zeros((n, 2))]))
