"""The learned prior (core.prior), its training code and the hybrid mode's fusion (core.lifter)."""

from __future__ import annotations

import re
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core import Lifter, LifterOptions, LiftResult, PoseBases, p_mpjpe
from pose_lifter.core.bases import default_bases_path
from pose_lifter.core.errors import InvalidInputError, OptionsError, PriorFileError
from pose_lifter.core.lifter import TrackContext
from pose_lifter.core.prior import DEFAULT_PRIOR_PATH, PosePrior, prior_features
from pose_lifter.core.synthetic import synthetic_poses
from pose_lifter.core.tracking import OutOfOrderFrameError, TrackPolicy
from pose_lifter.mocap.views import film, scale_limbs, view_rotation

#: Tolerances of this file, stated once.
LIMB_TOL = tol.LIFT_LIMB_VIOLATION  # limb-length violation of a fused (hybrid) result, right-lower-leg units
FLOAT32_TOL = tol.PRIOR_FLOAT32_REL  # a saved prior (float32 weights) vs the in-memory one, relative


@pytest.fixture(scope="module")
def prior() -> PosePrior:
    return PosePrior.load()


@pytest.fixture(scope="module")
def bases() -> PoseBases:
    return PoseBases.load()


REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def real_frames() -> tuple[np.ndarray, np.ndarray]:
    """Real people (the committed bags' ground truth: CMU trials of the evaluation split, camera
    frame, metres), 4 frames of each of 3 bags, seen weak-perspective: (pixels (12, 12, 2),
    centred camera-frame truth (12, 12, 3))."""
    from pose_lifter.messages import convert as messages
    from pose_lifter.mocap.scenes import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import read_messages

    truth = []
    for name in ("walk_clean", "punch_clean", "run_orbit"):
        msgs = [x.msg for x in read_messages(REPO / "bags" / f"{name}.mcap", [TOPIC_GROUND_TRUTH])]
        truth += [messages.skeleton3d_to_joints(m.skeletons[0]) for m in msgs[5:45:10]]
    cam = np.array(truth)
    cam -= cam.mean(axis=1, keepdims=True)
    return 160.0 * cam[..., :2] + 320.0, cam


def _views(n: int, seed: int = 0, azimuth: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic people filmed weak-perspective: (pixels (n, 12, 2), camera-frame truth (n, 12, 3))."""
    poses = synthetic_poses(n, seed=seed)
    rots = np.repeat(view_rotation(azimuth, 10.0)[None], n, axis=0)
    pts, cam, _ = film(poses, rots, np.full(n, 4.0), np.zeros(n, dtype=bool))
    return 800.0 * pts + 320.0, cam - cam.mean(axis=1, keepdims=True)


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
    x, _ = _views(5)
    vis = np.ones((5, 12), dtype=bool)
    p = tmp_path / "p.npz"
    prior.save(p)
    again = PosePrior.load(p)
    a, b = prior.predict(x, vis), again.predict(x, vis)
    assert np.allclose(a, b, rtol=FLOAT32_TOL, atol=FLOAT32_TOL * float(np.abs(a).max()))
    assert again.metadata == prior.metadata


def test_output_shape_and_finiteness_on_degenerate_input(prior: PosePrior) -> None:
    x, _ = _views(4)
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
    from pose_lifter.core.skeleton import limb_lengths

    poses = synthetic_poses(3, seed=2)
    f = np.linspace(0.8, 1.2, 8)
    out = scale_limbs(poses, f)
    assert np.allclose(limb_lengths(out), limb_lengths(poses) * f)
    assert np.allclose(out[:, [0, 3, 6, 9]], poses[:, [0, 3, 6, 9]])  # roots stay


# --------------------------------------------------------------------------- fusion


def test_modes_are_selectable_and_validated(bases: PoseBases) -> None:
    for mode in ("paper", "learned", "hybrid"):
        assert Lifter(bases, LifterOptions(mode=mode)).options.mode == mode
    with pytest.raises(OptionsError):
        LifterOptions(mode="magic")
    with pytest.raises(OptionsError):
        Lifter(bases, LifterOptions(mode="hybrid", alpha_solver="admm"))


def test_hybrid_meets_the_limb_constraints_and_beats_both_parts(
        bases: PoseBases, real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = real_frames
    errs: dict[str, list[float]] = {"paper": [], "learned": [], "hybrid": []}
    for mode in errs:
        lifter = Lifter(bases, LifterOptions(mode=mode, n_starts=10))
        for xi, ti in zip(x, truth, strict=True):
            r = lifter.lift(xi)
            errs[mode].append(float(p_mpjpe(r.pose_camera, ti)))
            if mode != "learned":
                assert r.limb_violation < LIMB_TOL
            assert np.all(np.isfinite(r.pose_camera))
    mean = {k: float(np.mean(v)) for k, v in errs.items()}
    assert mean["hybrid"] < mean["paper"], mean
    assert mean["hybrid"] < 1.1 * mean["learned"], mean


def test_a_confident_outlier_is_dropped_and_does_not_drag_the_depth(bases: PoseBases) -> None:
    x, truth = _views(8, seed=7)
    lifter = Lifter(bases, LifterOptions(mode="hybrid"))
    plain = Lifter(bases, LifterOptions(mode="hybrid", outlier_threshold=0.0))
    leg = float(np.linalg.norm(x[0, 10] - x[0, 11]))
    dropped, err_on, err_off = 0, [], []
    for xi, ti in zip(x, truth, strict=True):
        bad = xi.copy()
        bad[2] += np.array([2.5, -1.5]) * max(leg, 40.0)  # the left wrist, confidence kept at 1
        r = lifter.lift(bad)
        dropped += int(r.weights[2] == 0.0)
        assert r.limb_violation < LIMB_TOL
        err_on.append(float(p_mpjpe(r.pose_camera, ti)))
        err_off.append(float(p_mpjpe(plain.lift(bad).pose_camera, ti)))
    assert dropped >= 6, dropped
    assert np.mean(err_on) < np.mean(err_off)


def test_the_tracker_leaves_a_wrong_depth_basin(
        bases: PoseBases, real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """A track forced into the depth-mirrored basin (its warm start is the mirrored solution)
    comes back to the image's basin: the prior's pose starts every frame."""
    x, truth = real_frames  # frames 0-3: one walker, 1/3 s apart
    lifter = Lifter(bases, LifterOptions(mode="hybrid", warm_flip=False))
    first = lifter.lift(x[0])
    mirrored = lifter.runs.start_alpha(first.pose_camera * np.array([1.0, 1.0, -1.0]))
    policy = TrackPolicy(lifter)
    wrong = replace(first.warm_start(), alpha=mirrored)
    policy.restore(0, wrong, 0)  # the track's state: the wrong basin
    r = policy.lift(0, 33_000_000, x[1]).result
    trapped = Lifter(bases, LifterOptions(mode="paper", warm_flip=False)).lift(x[1], warm=wrong)
    assert p_mpjpe(r.pose_camera, truth[1]) < p_mpjpe(trapped.pose_camera, truth[1])
    assert r.start_index == -3  # the prior's start won
    with pytest.raises(OutOfOrderFrameError):
        policy.lift(0, 10_000_000, x[2])


@pytest.fixture(scope="module")
def walk_track() -> tuple[np.ndarray, np.ndarray]:
    """One real walker (bags/walk_clean.mcap's ground truth), 30 consecutive frames at 30 Hz,
    weak perspective: (pixels (30, 12, 2), centred camera-frame truth (30, 12, 3))."""
    from pose_lifter.messages import convert as messages
    from pose_lifter.mocap.scenes import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import read_messages

    msgs = [x.msg for x in read_messages(REPO / "bags" / "walk_clean.mcap", [TOPIC_GROUND_TRUTH])]
    cam = np.array([messages.skeleton3d_to_joints(m.skeletons[0]) for m in msgs[5:35]])
    cam -= cam.mean(axis=1, keepdims=True)
    return 160.0 * cam[..., :2] + 320.0, cam


def _track(lifter: Lifter, x: np.ndarray, conf: np.ndarray | None = None) -> list[LiftResult]:
    policy = TrackPolicy(lifter)
    return [policy.lift(0, i * 33_333_333, x[i], None if conf is None else conf[i]).result
            for i in range(len(x))]


def test_the_temporal_gate_drops_a_jumping_detection_before_the_prior_sees_it(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walk_track
    leg = float(np.median(np.linalg.norm(x[:, 10] - x[:, 11], axis=1)))
    hit = [10, 15, 20, 25]
    bad = x.copy()
    bad[hit, 2] += np.array([1.2, -0.8]) * leg  # the left wrist jumps ~1.4 legs, confidence 1
    # the lifter's own outlier pass off: the gate alone
    gated = _track(Lifter(bases, LifterOptions(outlier_threshold=0.0)), bad)
    plain = _track(Lifter(bases, LifterOptions(outlier_threshold=0.0, outlier_gate=0.0)), bad)
    assert all(gated[i].weights[2] == 0.0 for i in hit)
    clean = [i for i in range(len(x)) if i not in hit]
    assert sum(int(np.count_nonzero(gated[i].weights == 0.0)) for i in clean) <= 1  # no false alarms
    err = [np.mean([p_mpjpe(r[i].pose_camera, truth[i]) for i in hit]) for r in (gated, plain)]
    assert err[0] < 0.97 * err[1], err


def test_a_missing_joint_is_carried_over_by_the_track(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    x, truth = walk_track
    conf = np.ones(x.shape[:2])
    conf[10:25, [2, 8]] = 0.0  # the left wrist and left ankle lost for half a second
    frames = range(10, 25)
    errs = []
    for w in (3.0, 0.0):
        # the single-frame prior: the carry-over alone (the temporal prior sees the past frames
        # too, and the flip-averaged prior guesses this walker's lost joints within 1.3 % of it;
        # the output's measurement update holds a lost joint where the track had it as well)
        res = _track(Lifter(bases, LifterOptions(missing_temporal_weight=w, temporal_prior=False,
                                                 fill_missing_frames=0, prior_flip=False,
                                                 measurement_update=False)), x, conf)
        errs.append(np.mean([p_mpjpe(res[i].pose_camera, truth[i]) for i in frames]))
    assert errs[0] < 0.97 * errs[1], errs


def test_a_lost_joint_is_given_to_the_prior_where_the_track_predicts_it(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray], monkeypatch: pytest.MonkeyPatch) -> None:
    x, truth = walk_track
    conf = np.ones(x.shape[:2])
    lost = [10, 11, 16, 17, 22, 23]
    conf[np.ix_(lost, [2, 8])] = 0.0  # the left wrist and ankle lost for 2 frames, 3 times
    conf[5:15, 5] = 0.0  # the right wrist lost for 10 frames: filled on its first 3 only
    seen: list[np.ndarray | None] = []
    lift = Lifter.lift

    def spy(self: Lifter, *args: object, **kwargs: object) -> LiftResult:
        track = kwargs.get("track")
        f = None if track is None else track.fill  # type: ignore[attr-defined]
        seen.append(None if f is None else np.asarray(f[1]).copy())
        return lift(self, *args, **kwargs)  # type: ignore[arg-type]

    errs = []
    for n in (3, 0):
        # the fill's effect on the fit alone: the output's measurement update holds a lost joint
        # where the track had it, which takes part of the same error off both runs (ratio with it
        # on: 0.955-0.964; off: 0.914-0.929, measured under both floating-point set-ups)
        opts = LifterOptions(fill_missing_frames=n, missing_temporal_weight=0.0, measurement_update=False)
        if n:
            monkeypatch.setattr(Lifter, "lift", spy)
        res = _track(Lifter(bases, opts), x, conf)
        monkeypatch.setattr(Lifter, "lift", lift)
        errs.append(np.mean([p_mpjpe(res[i].pose_camera, truth[i]) for i in lost]))
    assert errs[0] < 0.97 * errs[1], errs
    assert seen[0] is None  # the first frame has no track to predict from
    allowed = np.array([m is not None and bool(m[5]) for m in seen])
    assert allowed[5:8].all() and not allowed[8:15].any()  # 3 frames, then it is left missing
    assert np.all([m is not None and m[2] for i, m in enumerate(seen) if i in lost])
    with pytest.raises(InvalidInputError, match="fill"):
        Lifter(bases).lift(x[0], track=TrackContext(fill=(np.zeros((11, 2)), np.ones(12, dtype=bool))))
    # no fill while the track's fit is being lost (its last objective far above its median)
    policy = TrackPolicy(Lifter(bases))
    for i in range(5):
        policy.lift(0, i * 33_333_333, x[i])
    seen.clear()
    monkeypatch.setattr(Lifter, "lift", spy)
    policy.lift(0, 5 * 33_333_333, x[5], conf[10])
    assert seen[-1] is not None
    policy._tracks[0].objectives.append(1e6)
    policy.lift(0, 6 * 33_333_333, x[6], conf[10])
    assert seen[-1] is None
    monkeypatch.setattr(Lifter, "lift", lift)


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


def test_the_compiled_features_are_the_numpy_ones() -> None:
    """The per-frame path's compiled features (prior._features_kernel) and their numpy reference
    (prior._window_features, _frame_features) agree, errors included. The kernel repeats numpy's
    operations in numpy's order (0 difference measured on every trial here); the bound is
    round-off, so that a compiler's choices on another CPU cannot fail it and a changed operation
    still does."""
    from pose_lifter.core import prior as prior_module

    rng = np.random.default_rng(4)
    for trial in range(300):
        w = int(rng.integers(1, 6))
        x = rng.normal(size=(w, 12, 2)) * 10.0 ** rng.uniform(-2, 3) + rng.uniform(-1e3, 1e3)
        vis = rng.random((w, 12)) > rng.uniform(0.0, 0.9)
        x[rng.random((w, 12, 2)) < 0.05] = np.nan
        if trial % 50 == 0:
            x[-1] = 7.0  # all at one point
        ref_vis = vis & np.isfinite(x).all(axis=-1)
        try:
            ref = (prior_module._frame_features(x[0], ref_vis[0]) if w == 1
                   else prior_module._window_features(x, ref_vis))
        except InvalidInputError as exc:
            with pytest.raises(InvalidInputError, match=re.escape(str(exc))):
                prior_features(x[0] if w == 1 else x, vis[0] if w == 1 else vis, w)
            continue
        got = prior_features(x[0] if w == 1 else x, vis[0] if w == 1 else vis, w)
        for a, b in zip(got, ref, strict=True):
            assert np.shape(a) == np.shape(b), trial
            assert np.allclose(a, b, rtol=tol.ROUND_OFF_LONG, atol=tol.ROUND_OFF), trial


def test_the_compiled_prior_target_is_the_numpy_one() -> None:
    """hybrid._target_kernel against the numpy lines it replaced (prior_rows' target and its blend
    with the previous frame's pose), to round-off (0 measured here)."""
    from pose_lifter.core._fast import median_rows
    from pose_lifter.core.hybrid import _target_kernel

    rng = np.random.default_rng(5)
    for trial in range(300):
        pose = rng.normal(size=(12, 3)) * 80.0 + rng.uniform(-500, 500)
        centre, spread = rng.uniform(-500, 500, size=2), float(rng.uniform(1.0, 300.0))
        previous = rng.normal(size=(12, 3))
        tw = np.where(rng.random(12) < 0.5, 0.0, rng.uniform(0.0, 3.0, size=12)) * (trial % 7 != 0)
        vis = rng.random(12) > rng.uniform(0.0, 0.8)
        vis[trial % 12] = True
        target = np.empty((12, 3))
        target[:, :2] = (pose[:, :2] - centre) / spread
        target[:, 2] = pose[:, 2] / spread
        if (tw > 0).any():
            prev = previous.copy()
            prev[:, :2] += median_rows(target[vis, :2] - prev[vis, :2])
            target = (target + tw[:, None] * prev) / (1.0 + tw[:, None])
        got, status = _target_kernel(pose, centre, spread, previous, tw, vis, True)
        assert status == 0 and np.allclose(got, target, rtol=tol.ROUND_OFF_LONG, atol=tol.ROUND_OFF), trial
    pose[3, 2] = np.inf
    assert _target_kernel(pose, centre, spread, previous, tw, vis, False)[1] == 1


def test_a_temporal_prior_sees_the_tracks_past_frames(
        bases: PoseBases, real_frames: tuple[np.ndarray, np.ndarray]) -> None:
    """A window-2 prior (random weights: the plumbing, not the accuracy) gets the previous frame
    from the lift's ``past``; no past means the current frame repeated; the per-track policy
    hands over only evenly spaced frames."""
    from pose_lifter.core.track import Track

    rng = np.random.default_rng(0)
    net = PosePrior((rng.normal(size=(72, 16)) * 0.3, rng.normal(size=(16, 36)) * 0.3),
                    (np.zeros(16), np.zeros(36)), np.zeros(36), np.ones(36), np.ones((12, 3)), window=2)
    lifter = Lifter(bases, LifterOptions(mode="learned", temporal_prior=False), prior=net)
    x = real_frames[0]
    vis = np.ones(12, dtype=bool)
    now = lifter.lift(x[1]).prior_pose
    assert now is not None
    same = lifter.lift(x[1], track=TrackContext(past=(x[1][None], vis[None]))).prior_pose
    moved = lifter.lift(x[1], track=TrackContext(past=(x[0][None], vis[None]))).prior_pose
    np.testing.assert_allclose(same, now, rtol=0, atol=tol.ROUND_OFF_ACCUMULATED)
    assert moved is not None and np.abs(moved - now).max() > 1e-3
    with pytest.raises(InvalidInputError):
        lifter.lift(x[1], track=TrackContext(past=(x[0], vis)))
    track = Track(None, 0)
    for stamp in (0, 100, 133, 166):  # a gap, then 33 ms steps
        track.history.append((stamp, np.full((12, 2), float(stamp)), np.ones(12, dtype=bool)))
    past = track.past(199, 5)
    assert past is not None
    assert past[0][:, 0, 0].tolist() == [100.0, 133.0, 166.0]
    assert track.past(166, 5) is None  # not after the last frame


def test_the_packaged_temporal_prior_is_used_on_tracked_frames(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """The packaged causal temporal prior (4 frames, training split only) loads without pickle;
    a track's frames after the first are lifted with it, and on a real walker it is closer to the
    truth than the single-frame prior."""
    from pose_lifter.core.prior import DEFAULT_TEMPORAL_PRIOR_PATH

    temporal = PosePrior.load(DEFAULT_TEMPORAL_PRIOR_PATH)
    assert temporal.window == 4
    assert not set(temporal.metadata["training_trials"]) & {"02_01", "07_01", "08_01", "09_12"}
    x, truth = walk_track
    errs = []
    for on in (True, False):
        res = _track(Lifter(bases, LifterOptions(temporal_prior=on)), x)
        errs.append(np.mean([p_mpjpe(r.pose_camera, t) for r, t in zip(res[1:], truth[1:], strict=True)]))
        if on:  # the first frame has no past: the single-frame prior, the same as without
            off0 = Lifter(bases, LifterOptions(temporal_prior=False)).lift(x[0])
            np.testing.assert_allclose(res[0].pose_camera, off0.pose_camera, atol=tol.ROUND_OFF_ACCUMULATED)
    assert errs[0] < errs[1], errs


def test_the_temporal_prior_never_reads_a_future_frame(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """Causal as the node runs it (``TrackPolicy``, frame by frame): the packaged temporal prior
    is handed only the current frame and earlier frames of the track, oldest first and the
    current one last, and a frame's published pose does not change when the frames after it do."""
    from pose_lifter.core.prior import DEFAULT_TEMPORAL_PRIOR_PATH

    temporal = PosePrior.load(DEFAULT_TEMPORAL_PRIOR_PATH)
    windows: list[tuple[np.ndarray, np.ndarray]] = []

    class Spy(PosePrior):
        def predict(self, points: np.ndarray, visible: np.ndarray, flip: bool = False) -> np.ndarray:
            windows.append((np.array(points), np.array(visible)))
            return super().predict(points, visible, flip)

    spy = Spy(temporal.weights, temporal.biases, temporal.out_mean, temporal.out_scale,
              temporal.abs_error, temporal.window, temporal.metadata, temporal.blocks)
    x = walk_track[0][:12]
    k = 6
    other = np.concatenate([x[:k + 1], x[k + 1:][::-1] + 40.0])  # the same past, another future
    poses = []
    for frames in (x, other):
        policy = TrackPolicy(Lifter(bases, LifterOptions(), prior=PosePrior.load(), temporal_prior=spy))
        out = []
        for i in range(len(frames)):
            windows.clear()
            out.append(policy.lift(0, i * 33_333_333, frames[i]).result.pose_camera)
            assert (len(windows) > 0) == (i > 0)  # the first frame has no past: the single-frame prior
            for pts, vis in windows:
                assert pts.shape == (spy.window, 12, 2)
                np.testing.assert_array_equal(pts[-1][vis[-1]], frames[i][vis[-1]])
                # every earlier row is a frame of the track's past, in order
                src = [int(np.argmin([np.abs(f[v] - row[v]).max() for f in frames]))
                       for row, v in zip(pts[:-1], vis[:-1], strict=True)]
                for j, row, v in zip(src, pts[:-1], vis[:-1], strict=True):
                    np.testing.assert_array_equal(row[v], frames[j][v])
                assert src == sorted(src) and src[-1] == i - 1
        poses.append(out)
    for i in range(k + 1):
        np.testing.assert_array_equal(poses[0][i], poses[1][i])
    assert np.abs(poses[0][k + 1] - poses[1][k + 1]).max() > 1e-3


def test_a_malformed_tracked_frame_is_refused_with_the_lifters_error(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """The gate and the carry-over run before the lifter's checks: a wrong shape on a warm frame
    must still be the lifter's InvalidInputError, and the track goes on."""
    x, _ = walk_track
    policy = TrackPolicy(Lifter(bases))
    policy.lift(0, 0, x[0])
    with pytest.raises(InvalidInputError):
        policy.lift(0, 33_333_333, x[1][:11])
    with pytest.raises(InvalidInputError):
        policy.lift(0, 66_666_666, x[2], np.ones(11))
    assert policy.lift(0, 99_999_999, x[3]).result.limb_violation < LIMB_TOL


def test_the_track_learns_a_persons_limb_proportions(walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """A real walker made long-shinned and short-armed: with ``prior_limbs`` the track's estimate
    (median of the prior's limbs, calibrated) moves toward the person's proportions from the
    bases', and the fit's limbs take it. (What it gains in 3D is measured by tools/accuracy.py's
    ``proportions`` condition: on one 1 s track it is within the noise.)"""
    _, truth = walk_track
    factors = np.array([1.0, 0.85, 1.0, 0.85, 1.0, 1.2, 1.0, 1.2])  # forearms -15 %, shins +20 %
    person = scale_limbs(truth, factors)
    x = 160.0 * person[..., :2] + 320.0
    bases = PoseBases.load(default_bases_path("hybrid"))
    own = Lifter(bases, LifterOptions(mode="hybrid", prior_limbs=True))
    fixed = Lifter(bases, LifterOptions(mode="hybrid", prior_limbs=False))
    policy = TrackPolicy(own)
    got = [policy.lift(0, i * 33_333_333, x[i]) for i in range(len(x) - 1)]
    used = policy._tracks[0].limb_proportions()  # what the last frame's fit is given
    got.append(policy.lift(0, (len(x) - 1) * 33_333_333, x[-1]))
    est = policy._tracks[0].limb_proportions()
    assert est is not None and used is not None

    def shape(p: np.ndarray) -> np.ndarray:  # (8,) limbs -> 4 log-proportions, size removed
        q = np.asarray(p)
        g = np.log(0.5 * (q[[0, 1, 4, 5]] + q[[2, 3, 6, 7]]))
        return g - g.mean()

    true = shape(Lifter.limb_proportions_of(person[0]))
    assert np.linalg.norm(shape(est) - true) < 0.8 * np.linalg.norm(shape(bases.limb_proportions) - true)
    # the fit's limbs follow the estimate it was given (the constraint radii), not the bases'
    # proportions (the fit's own pose: the published one is smoothed over frames, see
    # tests/core/test_output_smoothing.py)
    last = got[-1].fit_pose_camera
    assert last is not None
    fitted = shape(Lifter.limb_proportions_of(last))
    assert np.allclose(fitted, shape(used), atol=1e-3)
    # ... and without prior_limbs they keep the bases' proportions
    other = TrackPolicy(fixed)
    plain_fit = [other.lift(0, i * 33_333_333, x[i]) for i in range(len(x))][-1].fit_pose_camera
    assert plain_fit is not None
    plain = shape(Lifter.limb_proportions_of(plain_fit))
    assert np.allclose(plain, shape(bases.limb_proportions), atol=1e-3)


def test_the_hybrid_mode_has_its_own_packaged_bases() -> None:
    """Hybrid's bases: trials the prior was trained on (training subjects only, never the
    evaluation split, never the prior's validation trials), limbs varied; the paper's mode keeps
    the paper's (subject 01 playground)."""
    paper = Lifter(options=LifterOptions(mode="paper")).bases.metadata
    hybrid = Lifter(options=LifterOptions(mode="hybrid")).bases.metadata
    assert paper.get("split", "paper") == "paper"
    assert {t.split("_")[0] for t in paper["training_trials"]} == {"01"}
    assert hybrid["split"] == "prior" and hybrid["limb_spread"] == pytest.approx(0.2)
    trained = set(hybrid["training_trials"])
    assert trained <= set(PosePrior.load().metadata["training_trials"])
    assert {t.split("_")[0] for t in trained} <= {"01", "03", "05", "06", "09"} and "09_12" not in trained
    assert not trained & set(PosePrior.load().metadata["validation_trials"])


def test_the_hybrid_pose_step_has_its_own_iteration_cap(
        bases: PoseBases, walk_track: tuple[np.ndarray, np.ndarray]) -> None:
    """``hybrid_pose_max_iter`` caps the hybrid runs' pose steps; the paper's mode keeps
    ``pose_max_iter`` (its results stay the paper's). A tolerance no step meets makes every pose
    step run to its cap (seen in ``LiftResult.history``)."""
    x, _ = walk_track
    hybrid = LifterOptions(mode="hybrid", hybrid_pose_max_iter=7, warm_flip=False, pose_tol=1e-15)
    res = Lifter(bases, hybrid).lift(x[0])
    assert res.history and {a.pose.n_iter for a in res.history} == {7}
    paper = LifterOptions(mode="paper", n_starts=1, hybrid_pose_max_iter=7, pose_tol=1e-15)
    res = Lifter(bases, paper).lift(x[0])
    assert res.history and {a.pose.n_iter for a in res.history} == {paper.pose_max_iter}
    with pytest.raises(OptionsError):
        LifterOptions(hybrid_pose_max_iter=0)
