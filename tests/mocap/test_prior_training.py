"""The prior's training data and models: pose augmentations keep bone lengths and chirality, the
residual prior's numpy inference and file checks."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from pose_lifter.core.errors import PriorFileError
from pose_lifter.core.model.prior import PosePrior
from pose_lifter.core.model.skeleton import JOINTS_LEFT, JOINTS_RIGHT, LIMBS, body_frame, limb_lengths
from pose_lifter.core.model.synthetic import synthetic_poses
from pose_lifter.mocap.pose_augment import CHAINS, mirror_poses, random_turns, transplant_limbs, turn_limbs
from pose_lifter.mocap.prior_training import GENERALISE, Augmentation, augment_poses, make_batch

EXACT = 1e-12  # metres: rotations and re-scaled unit vectors, round-off only


def _handedness(p: np.ndarray) -> np.ndarray:
    """A pseudo-scalar of a person: det[left hip - right hip, spine, hips -> knees]; a mirror
    image flips its sign, a rotation or a relabelling of the same person does not."""
    across = p[:, 6] - p[:, 9]
    spine = 0.5 * (p[:, 0] + p[:, 3]) - 0.5 * (p[:, 6] + p[:, 9])
    knees = 0.5 * (p[:, 7] + p[:, 10]) - 0.5 * (p[:, 6] + p[:, 9])
    return np.linalg.det(np.stack([across, spine, knees], axis=-1))


@pytest.fixture(scope="module")
def poses() -> np.ndarray:
    return synthetic_poses(40, seed=3)


def test_mirroring_swaps_sides_keeps_handedness_and_is_an_involution(poses: np.ndarray) -> None:
    m = mirror_poses(poses)
    np.testing.assert_array_equal(mirror_poses(m), poses)
    # the mirrored person's left joints are the original's right ones, x negated
    np.testing.assert_array_equal(m[:, list(JOINTS_LEFT), 0], -poses[:, list(JOINTS_RIGHT), 0])
    np.testing.assert_array_equal(m[:, list(JOINTS_LEFT), 1:], poses[:, list(JOINTS_RIGHT), 1:])
    # its left limbs have the original's right limbs' lengths
    lengths, mirrored = limb_lengths(poses), limb_lengths(m)
    np.testing.assert_allclose(mirrored[:, [0, 1, 4, 5]], lengths[:, [2, 3, 6, 7]], rtol=0, atol=EXACT)
    # a person again, not a mirror-image body: the handedness is kept, while a plain reflection
    # (or a left/right relabelling alone) flips it
    h = _handedness(poses)
    assert np.all(np.abs(h) > 1e-6)
    np.testing.assert_allclose(_handedness(m), h, rtol=1e-9, atol=0)
    reflected = poses * np.array([-1.0, 1.0, 1.0])
    assert np.all(np.sign(_handedness(reflected)) == -np.sign(h))
    assert np.all(np.linalg.det(body_frame(m)) > 0.999)


def test_a_transplanted_limb_keeps_the_receivers_bones_and_the_donors_torso_relative_shape(
        poses: np.ndarray) -> None:
    donors = synthetic_poses(40, seed=11)
    rng = np.random.default_rng(0)
    sel = rng.random((40, 4)) < 0.5
    out = transplant_limbs(poses, donors, sel)
    np.testing.assert_allclose(limb_lengths(out), limb_lengths(poses), rtol=0, atol=EXACT)
    roots = [c[0] for c in CHAINS]
    np.testing.assert_array_equal(out[:, roots], poses[:, roots])  # the torso stays
    rec_frame, don_frame = body_frame(out), body_frame(donors)
    for k, (r, m, e) in enumerate(CHAINS):
        for a, b in ((r, m), (m, e)):
            got = np.einsum("nab,nb->na", rec_frame, out[:, b] - out[:, a])
            want = np.einsum("nab,nb->na", don_frame, donors[:, b] - donors[:, a])
            got /= np.linalg.norm(got, axis=-1, keepdims=True)
            want /= np.linalg.norm(want, axis=-1, keepdims=True)
            np.testing.assert_allclose(got[sel[:, k]], want[sel[:, k]], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(out[~sel[:, k]][:, [m, e]], poses[~sel[:, k]][:, [m, e]])
    assert not np.allclose(out[sel[:, 0], 2], poses[sel[:, 0], 2])  # something moved


def test_turned_limbs_keep_bone_lengths_and_turn_by_the_given_angle(poses: np.ndarray) -> None:
    rng = np.random.default_rng(1)
    root, end = random_turns(40, 40.0, 30.0, 1.0, rng)
    out = turn_limbs(poses, root, end)
    np.testing.assert_allclose(limb_lengths(out), limb_lengths(poses), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(out[:, [0, 3, 6, 9]], poses[:, [0, 3, 6, 9]])
    assert np.all(np.linalg.norm(root, axis=-1) <= np.radians(40.0) + 1e-12)
    assert np.all(np.linalg.norm(end, axis=-1) <= np.radians(30.0) + 1e-12)
    np.testing.assert_allclose(turn_limbs(poses, 0 * root, 0 * end), poses, rtol=0, atol=EXACT)
    # a turn about an axis perpendicular to the upper bone moves it by exactly that angle
    r, m = CHAINS[2][0], CHAINS[2][1]
    bone = poses[:, m] - poses[:, r]
    axis = np.cross(bone, np.array([0.3, 0.5, 0.8]))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    turns = np.zeros((40, 4, 3))
    turns[:, 2] = axis * np.radians(25.0)
    moved = turn_limbs(poses, turns, np.zeros_like(turns))
    new = moved[:, m] - moved[:, r]
    cos = np.sum(new * bone, axis=-1) / np.sum(bone * bone, axis=-1)
    np.testing.assert_allclose(np.degrees(np.arccos(np.clip(cos, -1, 1))), 25.0, atol=1e-6)


def test_pose_augmentation_is_seeded_shared_by_a_window_and_off_by_default(poses: np.ndarray) -> None:
    seqs = [synthetic_poses(200, seed=s) for s in range(3)]
    prob = np.array([len(s) for s in seqs], dtype=np.float64)
    wins = np.stack([s[10:14] for s in seqs] * 4)  # (12, 4, 12, 3)
    rng = np.random.default_rng(5)
    same = augment_poses(wins, seqs, prob, rng, Augmentation())
    assert same is wins and rng.random() == np.random.default_rng(5).random()  # no draws at p = 0
    a = augment_poses(wins, seqs, prob, np.random.default_rng(7), GENERALISE)
    b = augment_poses(wins, seqs, prob, np.random.default_rng(7), GENERALISE)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, wins)
    # every frame of a window keeps its bone lengths up to the mirror's left/right exchange
    la, lw = limb_lengths(a.reshape(-1, 12, 3)), limb_lengths(wins.reshape(-1, 12, 3))
    np.testing.assert_allclose(np.sort(la, axis=1), np.sort(lw, axis=1), rtol=0, atol=EXACT)
    # a window's frames share their changes: mirrored whole or not at all
    mir = augment_poses(wins, seqs, prob, np.random.default_rng(3), Augmentation(p_mirror=0.5))
    whole = np.array([np.array_equal(w, o) for w, o in zip(mir, wins, strict=True)])
    flipped = np.array([np.array_equal(w, mirror_poses(o)) for w, o in zip(mir, wins, strict=True)])
    assert np.all(whole ^ flipped) and whole.any() and flipped.any()
    batch = make_batch(seqs, 64, np.random.default_rng(2), GENERALISE, window=4)
    assert np.all(np.isfinite(batch.features)) and batch.features.shape == (64, 144)


def _residual(rng: np.random.Generator, width: int = 16, blocks: int = 2, window: int = 1) -> PosePrior:
    dims = [36 * window] + [width] * (2 * blocks + 1) + [36]
    ws = tuple(rng.normal(size=(a, b)) / np.sqrt(a) for a, b in itertools.pairwise(dims))
    bs = tuple(rng.normal(size=b) * 0.1 for b in dims[1:])
    return PosePrior(ws, bs, rng.normal(size=36), np.ones(36) * 0.5, np.ones((12, 3)), window, {}, blocks)


def test_the_residual_prior_adds_each_blocks_output_to_its_input(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    net = _residual(rng)
    x = rng.normal(size=(5, 36))
    relu = lambda v: np.maximum(v, 0.0)  # noqa: E731
    w, b = net.weights, net.biases
    h = relu(x @ w[0] + b[0])
    for k in range(2):
        h = h + relu(relu(h @ w[1 + 2 * k] + b[1 + 2 * k]) @ w[2 + 2 * k] + b[2 + 2 * k])
    want = ((h @ w[5] + b[5]) * net.out_scale + net.out_mean).reshape(5, 12, 3)
    np.testing.assert_allclose(net.forward(x), want, rtol=1e-4, atol=1e-4)  # float32 layers
    plain = PosePrior(net.weights, net.biases, net.out_mean, net.out_scale, net.abs_error)
    assert np.abs(plain.forward(x) - want).max() > 1e-2  # the skips matter
    net.save(tmp_path / "r.npz")
    again = PosePrior.load(tmp_path / "r.npz")
    assert again.blocks == 2
    np.testing.assert_allclose(again.forward(x), net.forward(x), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("defect", ["no_blocks", "blocks_float", "blocks_count", "not_square", "too_many"])
def test_a_damaged_residual_prior_file_is_refused(tmp_path: Path, defect: str) -> None:
    good = tmp_path / "good.npz"
    _residual(np.random.default_rng(1)).save(good)
    with np.load(good, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    if defect == "no_blocks":
        del arrays["blocks"]
    elif defect == "blocks_float":
        arrays["blocks"] = np.float64(2.0)
    elif defect == "blocks_count":
        arrays["blocks"] = np.int64(1)
    elif defect == "not_square":
        arrays["w1"] = arrays["w1"][:, :-1]
        arrays["b1"] = arrays["b1"][:-1]
        arrays["w2"] = arrays["w2"][:-1]
    elif defect == "too_many":
        arrays["blocks"] = np.int64(9)
    path = tmp_path / f"{defect}.npz"
    np.savez(path, **arrays)  # type: ignore[arg-type]
    with pytest.raises(PriorFileError) as err:
        PosePrior.load(path)
    assert str(path) in str(err.value)


#: torch's outputs of a small trained prior (tests/fixtures/make_prior_torch.py, torch 2.13 on CPU).
TORCH_FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "prior_torch.npz"


def test_the_numpy_prior_equals_torch_s_outputs_of_a_committed_network() -> None:
    """Without torch: the committed network's Linear -> BatchNorm layers folded by
    fold_linear_bn into a PosePrior give torch's own evaluation-mode outputs (float32 in torch:
    the tolerance of the test below)."""
    from pose_lifter.mocap.prior_training import fold_linear_bn

    f = np.load(TORCH_FIXTURE, allow_pickle=False)

    def fold(name: str) -> tuple[np.ndarray, np.ndarray]:
        return fold_linear_bn(*(f[f"{name}_{k}"] for k in ("weight", "bias", "gamma", "beta", "mean", "var")),
                              float(f[f"{name}_eps"]))

    n_blocks = int(f["n_blocks"])
    layers = [fold("stem")]
    for i in range(n_blocks):
        layers += [fold(f"block{i}_a"), fold(f"block{i}_b")]
    layers.append((f["head_weight"].T, f["head_bias"]))
    prior = PosePrior(tuple(np.ascontiguousarray(w) for w, _ in layers),
                      tuple(np.ascontiguousarray(b) for _, b in layers),
                      f["out_mean"], f["out_scale"], np.ones((12, 3)), 1, {}, n_blocks)
    want = (f["y_torch"] * f["out_scale"] + f["out_mean"]).reshape(-1, 12, 3)
    np.testing.assert_allclose(prior.forward(f["x"]), want, rtol=1e-4, atol=1e-4 * float(np.abs(want).max()))
    # the tolerance is far below what a wrong layer costs: a shifted bias is caught
    w, b = layers[0]
    layers[0] = (w, b + 0.1)
    broken = PosePrior(tuple(w for w, _ in layers), tuple(b for _, b in layers), f["out_mean"],
                       f["out_scale"], np.ones((12, 3)), 1, {}, n_blocks)
    assert np.abs(broken.forward(f["x"]) - want).max() > 1e-3 * float(np.abs(want).max())


def test_the_trained_residual_prior_runs_in_numpy_as_in_torch() -> None:
    """Batch normalisation folded into the linear layers: the numpy prior equals the torch
    network in evaluation mode; seeded training repeats exactly. Needs the training extra (torch,
    ``make train-deps``); CI checks the same equivalence on a committed network above."""
    torch = pytest.importorskip("torch", reason="torch is the training extra (make train-deps)")
    from pose_lifter.mocap import prior_training as pt

    seqs = [synthetic_poses(200, seed=s, n_actions=2) for s in range(3)]
    captured: dict[str, object] = {}
    orig = pt._fold_residual

    def spy(stem, body, head, *rest):  # type: ignore[no-untyped-def]
        captured.update(stem=stem, body=body, head=head)
        return orig(stem, body, head, *rest)

    kw = {"width": 32, "blocks": 1, "epochs": 2, "samples_per_epoch": 1024, "batch_size": 128, "seed": 4,
          "log": None}
    pt._fold_residual = spy
    try:
        pr = pt.train_prior_residual(seqs[:2], seqs[2:], **kw)  # type: ignore[arg-type]
    finally:
        pt._fold_residual = orig
    again = pt.train_prior_residual(seqs[:2], seqs[2:], **kw)  # type: ignore[arg-type]
    assert all(np.array_equal(a, b) for a, b in zip(pr.weights, again.weights, strict=True))
    stem, body, head = captured["stem"], captured["body"], captured["head"]
    for m in (stem, *body, head):  # type: ignore[attr-defined]
        m.eval()
    x = make_batch(seqs[2:], 50, np.random.default_rng(3)).features
    with torch.no_grad():
        h = stem(torch.from_numpy(x.astype(np.float32)))  # type: ignore[operator]
        for blk in body:  # type: ignore[attr-defined]
            h = h + blk(h)
        y = head(h).double().numpy()  # type: ignore[operator]
    want = (y * pr.out_scale + pr.out_mean).reshape(-1, 12, 3)
    np.testing.assert_allclose(pr.forward(x), want, rtol=1e-4, atol=1e-4 * float(np.abs(want).max()))
    assert pr.blocks == 1 and len(LIMBS) == 8


def test_train_prior_overrides_one_augmentation_field_and_refuses_unknown_ones() -> None:
    from tool_modules import load_tool

    tp = load_tool("train_prior")
    aug = tp.augmentation("generalise", ["p_transplant=0", "turn_root_deg = 20"])
    assert aug.p_transplant == 0.0 and aug.turn_root_deg == 20.0
    assert aug.p_mirror == GENERALISE.p_mirror and aug.p_lower_cut == GENERALISE.p_lower_cut
    assert tp.augmentation("views", []) == Augmentation()
    for bad in (["p_nothing=1"], ["p_mirror=x"]):
        with pytest.raises(ValueError):
            tp.augmentation("generalise", bad)


def test_a_detectors_training_noise_is_per_joint_and_correlated_over_a_window() -> None:
    """The training's detector noise (Augmentation.p_detector): each joint's spread is the detector
    model's, a window's frames err alike by the correlation drawn, and an augmentation without
    it draws the same samples as before it existed."""
    from dataclasses import replace

    from pose_lifter.mocap.detector_model import joint_spreads
    from pose_lifter.mocap.prior_training import detector_noise

    e = detector_noise((20_000, 4), 0.05, 0.8, np.random.default_rng(0))
    np.testing.assert_allclose(e.std(axis=(0, 1, 3)), joint_spreads(0.05), rtol=0.03)
    lag1 = np.mean([np.corrcoef(e[:, t, :, 0].ravel(), e[:, t + 1, :, 0].ravel())[0, 1] for t in range(3)])
    assert lag1 == pytest.approx(0.8, abs=0.02)
    seqs = [synthetic_poses(40, seed=s) for s in range(3)]
    off = make_batch(seqs, 64, np.random.default_rng(2), replace(GENERALISE, p_detector=0.0), window=4)
    base = make_batch(seqs, 64, np.random.default_rng(2), GENERALISE, window=4)
    assert np.array_equal(off.features, base.features)
    on = make_batch(seqs, 64, np.random.default_rng(2), replace(GENERALISE, p_detector=1.0), window=4)
    assert np.isfinite(on.features).all() and not np.array_equal(on.features, base.features)


def test_an_offline_priors_target_is_the_frame_future_frames_before_the_windows_last(tmp_path: Path) -> None:
    """``make_batch(..., future=f)``: the target is the pose of the window's frame
    ``window - 1 - f``, and the window is normalised on that frame; only a lifter that reads
    ahead takes such a prior."""
    from dataclasses import replace

    from pose_lifter.core.model.loading import LifterData
    from pose_lifter.core.model.metrics import p_mpjpe

    window = 5
    seq = synthetic_poses(window, seed=7)  # one sequence of one window: it starts at frame 0
    aug = Augmentation(limb_spread=0.0, p_noise=0.0, p_missing=0.0, p_outliers=0.0)
    batches = {f: make_batch([seq], 16, np.random.default_rng(4), aug, window=window, future=f)
               for f in (0, 2)}
    for f, batch in batches.items():
        errs = [p_mpjpe(batch.camera_pose, np.broadcast_to(seq[k], batch.camera_pose.shape)).max()
                for k in range(window)]
        assert errs[window - 1 - f] < EXACT  # that frame, seen from the sample's camera
        assert min(e for k, e in enumerate(errs) if k != window - 1 - f) > 1e-3
        # every joint visible: the normalised frame's coordinates are centred with RMS radius 1
        frames = batch.features.reshape(16, window, 36)[..., :24].reshape(16, window, 12, 2)
        for k in range(window):
            centred = np.abs(frames[:, k].mean(axis=1)).max() < EXACT
            unit = np.abs(np.sqrt((frames[:, k] ** 2).sum(axis=-1).mean(axis=-1)) - 1.0).max() < EXACT
            assert (centred and unit) == (k == window - 1 - f)
    with pytest.raises(ValueError, match="future"):
        make_batch([seq], 4, np.random.default_rng(4), aug, window=window, future=window)
    net = _residual(np.random.default_rng(0), window=window)
    replace(net, metadata={"future_frames": 2}).save(tmp_path / "offline.npz")
    with pytest.raises(PriorFileError, match="offline lift"):
        LifterData.packaged("hybrid").temporal_prior(str(tmp_path / "offline.npz"))
    assert LifterData.packaged("hybrid").temporal_prior(str(tmp_path / "offline.npz"), reads_ahead=True
                                                        ).future_frames == 2
    with pytest.raises(PriorFileError, match="future_frames"):
        replace(net, metadata={"future_frames": window})


def test_a_crop_cuts_a_window_at_two_image_rows_and_is_off_by_default() -> None:
    """The training's image borders (Augmentation.p_crop): the joints of every frame of a window
    above one image row and below another are missing, the rows within ``crop_max`` of the target
    frame's height from its top and bottom; only the samples drawn are cut, and an augmentation
    without it draws the same samples as before it existed."""
    from dataclasses import replace

    from pose_lifter.mocap.prior_training import _cropped

    rng = np.random.default_rng(3)
    pts = rng.normal(size=(500, 5, 12, 2))
    crop = rng.random(500) < 0.5
    out = _cropped(pts, 2, crop, 0.3, np.random.default_rng(4))
    assert not out[~crop].any() and out[crop].any()
    y = pts[..., 1]
    lo, hi = y[:, 2].min(axis=1), y[:, 2].max(axis=1)
    for i in np.flatnonzero(crop):  # every frame cut at the same two rows
        kept, cut = y[i][~out[i]], y[i][out[i]]
        top, bottom = lo[i] + 0.3 * (hi[i] - lo[i]), hi[i] - 0.3 * (hi[i] - lo[i])
        above = (cut < kept.min()) & (cut < top)
        below = (cut > kept.max()) & (cut > bottom)
        assert (above | below).all()
    seqs = [synthetic_poses(40, seed=s) for s in range(3)]
    base = make_batch(seqs, 64, np.random.default_rng(2), GENERALISE, window=4)
    off = make_batch(seqs, 64, np.random.default_rng(2), replace(GENERALISE, p_crop=0.0), window=4)
    assert np.array_equal(off.features, base.features)
    on = make_batch(seqs, 64, np.random.default_rng(2), replace(GENERALISE, p_crop=1.0), window=4)
    assert not np.array_equal(on.features, base.features)
