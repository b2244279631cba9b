"""The learned prior (core.model.prior): its file, features and training code."""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
import tolerances as tol
from filmed import filmed_views
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.core.errors import InvalidInputError, PriorFileError
from pose_lifter.core.lift.batch import PriorCall, prior_calls
from pose_lifter.core.model.prior import (
    DEFAULT_PRIOR_PATH,
    DEFAULT_TEMPORAL_PRIOR_PATH,
    PosePrior,
    prior_features,
)
from pose_lifter.core.model.synthetic import synthetic_poses
from pose_lifter.core.numeric.jit import HAVE_NUMBA
from pose_lifter.core.results import Failure, LiftStatus
from pose_lifter.mocap.views import scale_limbs

#: Tolerances of this file, stated once.
FLOAT32_TOL = tol.PRIOR_FLOAT32_REL  # a saved prior (float32 weights) vs the in-memory one, relative


@pytest.fixture(scope="module")
def prior() -> PosePrior:
    return PosePrior.load()


def test_packaged_prior_loads_without_pickle_and_has_its_provenance(prior: PosePrior) -> None:
    with np.load(DEFAULT_PRIOR_PATH, allow_pickle=False) as z:  # raises if anything needs pickle
        assert all(z[k].dtype != object for k in z.files)
    assert prior.window >= 1
    assert "training_trials" in prior.metadata and "command" in prior.metadata
    assert not {"02", "07", "08"} & {t.split("_")[0] for t in prior.metadata["training_trials"]}
    assert "09_12" not in prior.metadata["training_trials"]


def _write(path: Path, **arrays: object) -> Path:
    np.savez(path, **arrays)  # type: ignore[arg-type]
    return path


@pytest.mark.parametrize("defect", ["missing", "shape", "nan", "object", "version", "not_zip", "big"])
def test_a_bad_prior_file_is_refused_with_a_clear_error(prior: PosePrior, tmp_path: Path,
                                                         defect: str) -> None:
    good = tmp_path / "good.npz"
    prior.save(good)
    with np.load(good, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    path = tmp_path / f"{defect}.npz"
    if defect == "missing":
        del arrays["w1"]
    elif defect == "shape":
        arrays["w0"] = arrays["w0"][:-1]
    elif defect == "nan":
        arrays["b0"] = arrays["b0"].copy()
        arrays["b0"][3] = np.nan
    elif defect == "version":
        arrays["format_version"] = np.int64(99)
    if defect == "object":
        arrays["metadata"] = np.array([{"a": 1}], dtype=object)
        np.savez(path, **arrays)
    elif defect == "not_zip":
        path.write_bytes(b"not a zip file")
    elif defect == "big":  # a zip whose members claim more than the cap uncompressed
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("w0.npy", b"\0" * (65 * 1024 * 1024))
    else:
        np.savez(path, **arrays)
    with pytest.raises(PriorFileError) as err:
        PosePrior.load(path)
    assert str(path) in str(err.value)
    with pytest.raises(PriorFileError):
        Lifter(options=LifterOptions(mode="hybrid", prior_file=str(path)))


def test_save_load_round_trip_keeps_the_outputs(prior: PosePrior, tmp_path: Path) -> None:
    x, _ = filmed_views(5)
    vis = np.ones((5, 12), dtype=bool)
    p = tmp_path / "p.npz"
    prior.save(p)
    again = PosePrior.load(p)
    a, b = prior.predict(x, vis), again.predict(x, vis)
    assert np.allclose(a, b, rtol=FLOAT32_TOL, atol=FLOAT32_TOL * float(np.abs(a).max()))
    assert again.metadata == prior.metadata


def test_output_shape_and_finiteness_on_degenerate_input(prior: PosePrior) -> None:
    x, _ = filmed_views(4)
    # batched, single and windowed shapes
    assert prior.predict(x, np.ones((4, 12), dtype=bool)).shape == (4, 12, 3)
    assert prior.predict(x[0], np.ones(12, dtype=bool)).shape == (12, 3)
    # all but two joints missing (NaN coordinates count as missing): every joint still predicted
    sparse = x[0].copy()
    sparse[2:] = np.nan
    out = prior.predict(sparse, np.ones(12, dtype=bool))
    assert out.shape == (12, 3) and np.all(np.isfinite(out))
    # missing joints' coordinates do not matter
    vis = np.ones(12, dtype=bool)
    vis[5] = False
    moved = x[0].copy()
    moved[5] += 1e6
    assert np.array_equal(prior.predict(x[0], vis), prior.predict(moved, vis))
    # the prediction follows the input's position and scale (normalised input)
    shifted = prior.predict(2.0 * x[0] + 50.0, np.ones(12, dtype=bool))
    base = prior.predict(x[0], np.ones(12, dtype=bool))
    assert np.allclose(shifted[:, :2], 2.0 * base[:, :2] + 50.0, atol=1e-6)
    assert np.allclose(shifted[:, 2], 2.0 * base[:, 2], atol=1e-6)
    with pytest.raises(InvalidInputError):  # one visible joint
        prior.predict(x[0], np.eye(12, dtype=bool)[0])
    with pytest.raises(InvalidInputError):  # all at one point
        prior.predict(np.ones((12, 2)), np.ones(12, dtype=bool))
    feats, _, _ = prior_features(np.stack([x[:3]]), np.ones((1, 3, 12), dtype=bool), window=3)
    assert feats.shape == (1, 108)


def test_training_code_fits_a_tiny_prior_that_beats_the_flat_floor(tmp_path: Path) -> None:
    from pose_lifter.mocap.prior_training import Augmentation, make_batch, train_prior

    seqs = [synthetic_poses(300, seed=s, n_actions=2) for s in range(3)]
    aug = Augmentation(p_outliers=0.0, p_missing=0.0, p_noise=0.0, limb_spread=0.0, elevation=(0.0, 0.0),
                       roll_std=0.0)
    kw = {"hidden": (64,), "samples_per_epoch": 3000, "seed": 1, "aug": aug, "log": None, "lr": 3e-3,
          "lr_final": 1e-3}
    pr = train_prior(seqs[:2], seqs[2:], epochs=20, **kw)  # type: ignore[arg-type]
    again = train_prior(seqs[:2], seqs[2:], epochs=20, **kw)  # type: ignore[arg-type]
    assert all(np.array_equal(a, b) for a, b in zip(pr.weights, again.weights, strict=True))  # seeded
    test = make_batch(seqs[2:], 500, np.random.default_rng(9), aug)
    depth = test.targets.reshape(-1, 12, 3)[..., 2]
    flat_err = np.abs(depth).mean()  # zero depth
    # measured 0.86 of the flat floor after 20 epochs (1.02 after 1): the training code learns depth
    assert np.abs(pr.forward(test.features)[..., 2] - depth).mean() < 0.92 * flat_err
    pr.save(tmp_path / "tiny.npz")
    assert PosePrior.load(tmp_path / "tiny.npz").weights[0].shape == (36, 64)


def test_scale_limbs_changes_each_limb_by_its_factor() -> None:
    from pose_lifter.core.model.skeleton import limb_lengths

    poses = synthetic_poses(3, seed=2)
    f = np.linspace(0.8, 1.2, 8)
    out = scale_limbs(poses, f)
    assert np.allclose(limb_lengths(out), limb_lengths(poses) * f)
    assert np.allclose(out[:, [0, 3, 6, 9]], poses[:, [0, 3, 6, 9]])  # roots stay


def test_the_single_frame_path_equals_the_batched_one(prior: PosePrior) -> None:
    """The node's per-frame features (a fast path) and a batch of one give the same pose."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        x = rng.normal(size=(12, 2)) * 50.0 + 300.0
        vis = rng.random(12) > 0.3
        vis[:2] = True
        x[~vis] = np.nan if rng.random() < 0.5 else 0.0
        one, batch = prior_features(x, vis), prior_features(x[None, None], vis[None, None])
        for a, b in zip(one, batch, strict=True):
            np.testing.assert_allclose(a, np.reshape(b, np.shape(a)), rtol=0, atol=tol.ROUND_OFF)
        # float32 layers: a matrix-vector and a matrix-matrix product round differently
        np.testing.assert_allclose(prior.predict(x, vis), prior.predict(x[None, None], vis[None, None])[0],
                                   rtol=FLOAT32_TOL, atol=FLOAT32_TOL)
        # ... and a tracked person's window (W, 12, 2), its last frame the current one
        xw = np.concatenate([rng.normal(size=(3, 12, 2)) * 50.0 + 300.0, x[None]])
        vw = np.concatenate([rng.random((3, 12)) > 0.3, vis[None]])
        one, batch = prior_features(xw, vw, 4), prior_features(xw[None], vw[None], 4)
        for a, b in zip(one, batch, strict=True):
            np.testing.assert_allclose(a, np.reshape(b, np.shape(a)), rtol=0, atol=tol.ROUND_OFF)
        # ... and an offline prior's window, normalised on a frame inside it
        centred = np.concatenate([xw[1:], xw[:1]]), np.concatenate([vw[1:], vw[:1]])
        one, batch = prior_features(*centred, 4, 2), prior_features(centred[0][None], centred[1][None], 4, 2)
        for a, b in zip(one, batch, strict=True):
            np.testing.assert_allclose(a, np.reshape(b, np.shape(a)), rtol=0, atol=tol.ROUND_OFF)


def test_the_compiled_features_are_the_numpy_ones() -> None:
    """The per-frame path's compiled features (prior._features_kernel) and their numpy reference
    (prior._window_features, _frame_features) agree, errors included, normalised on any frame of
    the window, to round-off (the kernel sums in its own order): a changed operation still fails
    it."""
    from pose_lifter.core.model import prior as prior_module

    rng = np.random.default_rng(4)
    for trial in range(300):
        w = int(rng.integers(1, 6))
        anchor = int(rng.integers(0, w))
        x = rng.normal(size=(w, 12, 2)) * 10.0 ** rng.uniform(-2, 3) + rng.uniform(-1e3, 1e3)
        vis = rng.random((w, 12)) > rng.uniform(0.0, 0.9)
        x[rng.random((w, 12, 2)) < 0.05] = np.nan
        if trial % 50 == 0:
            x[anchor] = 7.0  # all at one point
        ref_vis = vis & np.isfinite(x).all(axis=-1)
        try:
            ref = (prior_module._frame_features(x[0], ref_vis[0]) if w == 1
                   else prior_module._window_features(x, ref_vis, anchor))
        except InvalidInputError as exc:
            with pytest.raises(InvalidInputError, match=re.escape(str(exc))):
                prior_features(x[0] if w == 1 else x, vis[0] if w == 1 else vis, w, anchor)
            continue
        got = prior_features(x[0] if w == 1 else x, vis[0] if w == 1 else vis, w, anchor)
        for a, b in zip(got, ref, strict=True):
            assert np.shape(a) == np.shape(b), trial
            assert np.allclose(a, b, rtol=tol.ROUND_OFF_LONG, atol=tol.ROUND_OFF), trial


def test_the_compiled_layer_pass_of_a_few_rows_is_the_matrix_product(
        prior: PosePrior, monkeypatch: pytest.MonkeyPatch) -> None:
    """PosePrior.forward of up to SMALL_BATCH rows (the compiled pass) against the same network
    through numpy's matrix products (float32 both: equal up to the summation order's rounding)."""
    from pose_lifter.core.model import prior as prior_module

    rng = np.random.default_rng(6)
    d = prior._layers32[0][0].shape[0]
    for rows in (1, 2, prior_module.SMALL_BATCH):
        x = rng.normal(size=(rows, d))
        got = prior.forward(x)
        with monkeypatch.context() as mp:
            mp.setattr(prior_module, "HAVE_NUMBA", False)
            ref = prior.forward(x)
        scale = np.abs(ref).max()
        assert got.shape == ref.shape == (rows, 12, 3)
        assert np.abs(got - ref).max() <= tol.PRIOR_FLOAT32_REL * scale, rows
        assert np.abs(prior.forward(x[0]) - ref[0]).max() <= tol.PRIOR_FLOAT32_REL * scale
    relu_off = prior_module._affine_rows(np.array([[1.0, -2.0]], np.float32),
                                         np.array([[1.0, 0.0], [1.0, 1.0]], np.float32),
                                         np.array([0.5, 0.0], np.float32), False)
    assert np.allclose(relu_off, [[-0.5, -2.0]])  # h @ w + b, negatives kept without the ReLU
    assert np.allclose(prior_module._affine_rows(np.array([[1.0, -2.0]], np.float32),
                                                 np.array([[1.0, 0.0], [1.0, 1.0]], np.float32),
                                                 np.array([0.5, 0.0], np.float32), True), [[0.0, 0.0]])



def test_the_compiled_layer_pass_adds_the_products_one_at_a_time_in_order() -> None:
    """_affine_rows: each output is the bias plus the products added in the order of the inputs,
    each product and sum rounded to float32 (numpy's element-wise float32 arithmetic, one input at
    a time, is the same sum bit for bit), whatever the rows around it; input widths with and
    without a remainder of the pass's blocks of eight, a ReLU's zeros among the inputs."""
    from pose_lifter.core.model import prior as prior_module

    rng = np.random.default_rng(11)
    for d, m, n in ((36, 512, 1), (252, 40, 3), (512, 36, 40), (5, 7, 2)):
        h = np.maximum(rng.normal(size=(n, d)), 0.0).astype(np.float32)
        w = rng.normal(size=(d, m)).astype(np.float32)
        b = rng.normal(size=m).astype(np.float32)
        ref = np.repeat(b[None], n, axis=0)
        for i in range(d):
            ref = ref + h[:, i:i + 1] * w[i]
        for relu in (False, True):
            got = prior_module._affine_rows(h, w, b, relu)
            np.testing.assert_array_equal(got, np.maximum(ref, 0.0) if relu else ref)
        np.testing.assert_array_equal(prior_module._affine_rows(h[-1:], w, b, False), ref[-1:])

def _counting_passes(mp: pytest.MonkeyPatch) -> list[int]:
    """``PosePrior._forward_small`` patched (inside ``mp``) to record each compiled pass's row
    count in the returned list."""
    passes: list[int] = []
    forward = PosePrior._forward_small

    def counted(self: PosePrior, rows: np.ndarray) -> np.ndarray:
        passes.append(len(rows))
        return forward(self, rows)

    mp.setattr(PosePrior, "_forward_small", counted)
    return passes


def test_the_rows_split_over_threads_are_each_rows_own_bit_for_bit(
        prior: PosePrior, monkeypatch: pytest.MonkeyPatch) -> None:
    """PosePrior.forward_rows: the rows split into contiguous parts run by threads give what
    one pass gives, bit for bit, in order; a part has at least _ROWS_PER_THREAD rows."""
    from pose_lifter.core.model import prior as prior_module

    rng = np.random.default_rng(12)
    d = prior._layers32[0][0].shape[0]
    x = np.maximum(rng.normal(size=(37, d)), 0.0).astype(np.float32)
    one = prior._forward_small(x)
    with monkeypatch.context() as mp:
        passes = _counting_passes(mp)
        for threads, parts in ((1, 1), (2, 2), (3, 3), (8, 37 // prior_module._ROWS_PER_THREAD)):
            passes.clear()
            np.testing.assert_array_equal(prior.forward_rows(x, threads), one)
            assert len(passes) == parts and sum(passes) == 37, threads
        passes.clear()
        few = x[:2 * prior_module._ROWS_PER_THREAD - 1]
        np.testing.assert_array_equal(prior.forward_rows(few, 4), one[:len(few)])
        assert passes == [len(few)]  # too few rows to split


def test_prior_calls_are_each_poses_own_bit_for_bit(prior: PosePrior,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """prior_calls: the poses of many people, of two priors and both flip settings, are one by
    one those of each pose computed alone (the rows of the compiled pass do not mix), each
    prior's network in one pass over its weights; an input the prior refuses gets its failure in
    its place and costs nobody else."""
    temporal = PosePrior.load(DEFAULT_TEMPORAL_PRIOR_PATH)
    other = PosePrior(tuple(w * 1.01 for w in prior.weights), prior.biases, prior.out_mean,
                      prior.out_scale, prior.abs_error, prior.window, prior.metadata, prior.blocks)
    rng = np.random.default_rng(11)
    people = [(rng.uniform(100.0, 500.0, (12, 2)), rng.random(12) > 0.15) for _ in range(9)]
    windows = [(rng.uniform(100.0, 500.0, (temporal.window, 12, 2)), rng.random((temporal.window, 12)) > 0.1)
               for _ in range(5)]
    refused = (np.zeros((12, 2)), np.zeros(12, dtype=bool))  # no visible joint
    calls = ([PriorCall(prior, x, v, True) for x, v in people[:4]] + [PriorCall(prior, *refused, True)]
             + [PriorCall(temporal, x, v, True) for x, v in windows] + [PriorCall(prior, x, v, False)
                                                                        for x, v in people[4:]]
             + [PriorCall(other, *people[0], True)])
    with monkeypatch.context() as mp:
        passes = _counting_passes(mp)
        out = prior_calls(calls)
    assert len(out) == len(calls)
    for c, pose in zip(calls, out, strict=True):
        if c.points is refused[0]:
            assert isinstance(pose, Failure) and pose.status == LiftStatus.INVALID_INPUT
            continue
        assert isinstance(pose, np.ndarray)
        np.testing.assert_array_equal(pose, c.prior.predict(c.points, c.visible, c.flip))
    # the same input through other weights is not the first prior's pose
    assert not np.array_equal(out[-1], out[0])
    if HAVE_NUMBA:  # one pass per (prior, flip): 4 + 5 mirrored pairs, 5 single rows, 1 pair
        assert sorted(passes) == [2, 5, 8, 10]
