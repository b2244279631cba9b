"""The per-track rules run as arrays over a frame's tracks, against each rule written plainly per
track: the screening (``core/track/screening.py``, one compiled pass: where the track puts each
joint, the left/right label check, the temporal outlier gate and the 2D noise observation, on
random tracks with jumping joints and swapped labels) and the tracks' limb proportions
(``core/track/state.py``)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from pose_lifter.core import Lifter, LifterOptions
from pose_lifter.core.track.screening import ToScreen, screen_frames
from pose_lifter.core.track.state import (
    GATE_MAX_AGE_NS,
    GATE_MAX_FRACTION,
    GATE_MAX_FRAMES,
    GATE_NOISE_FACTOR,
    SWAP_MARGIN,
    SWAP_MAX_FRAMES,
    SWAP_RATIO,
    Track,
    swap_back,
)

STEP_NS = 33_333_333


#: The arms' and the legs' joints, left then right (JOINT_NAMES), and their counterparts.
GROUPS = [np.array([0, 1, 2, 3, 4, 5]), np.array([6, 7, 8, 9, 10, 11])]
OTHER = [np.array([3, 4, 5, 0, 1, 2]), np.array([9, 10, 11, 6, 7, 8])]


def _reference(track: Track, lifter: Lifter, x: np.ndarray, vis: np.ndarray, stamp: int
               ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, float | None, np.ndarray]:
    """One person's screening as a plain numpy rule: (joints kept, joints gated or None,
    prediction or None, the noise observation or None, the 2D with its labels swapped back);
    updates ``track.gated`` and ``track.swapped``."""
    opts = lifter.options
    x, vis = x.copy(), vis.copy()

    def predict(v: np.ndarray) -> np.ndarray | None:
        if not track.fits or not v.any():
            return None
        t1, p1, _ = track.fits[-1]
        if not 0 < stamp - t1 <= GATE_MAX_AGE_NS:
            return None
        return p1 + np.median(x[v] - p1[v], axis=0)

    predicted, gated = predict(vis), None
    if predicted is not None:
        for g, (both, other) in enumerate(zip(GROUPS, OTHER, strict=True)):
            v = vis[both]
            given = np.linalg.norm(x[both] - predicted[both], axis=1)[v].sum()
            swapped = np.linalg.norm(x[both] - predicted[other], axis=1)[v].sum()
            if (v.sum() >= 2 and track.swapped[g] < SWAP_MAX_FRAMES and swapped <= SWAP_RATIO * given
                    and given - swapped > v.sum() * SWAP_MARGIN * track.fits[-1][2]):
                x[both], vis[both] = x[other], vis[other]
                track.swapped[g] += 1
                predicted = predict(vis)
            else:
                track.swapped[g] = 0
        assert predicted is not None
        d = np.linalg.norm(np.where(vis[:, None], x, predicted) - predicted, axis=1) / track.fits[-1][2]
        limit = max(opts.outlier_gate, GATE_NOISE_FACTOR * track.noise_level())
        out = vis & (d > limit) & (track.gated < GATE_MAX_FRAMES)
        n_out, n_vis = out.sum(), vis.sum()
        if n_out == 0 or n_vis - n_out < opts.min_visible_joints or n_out > GATE_MAX_FRACTION * n_vis:
            track.gated[:] = 0
        else:
            track.gated = np.where(out, track.gated + 1, 0)
            gated, vis = out, vis & ~out
            predicted = predict(vis)
    noise = None
    (t0, x0, v0), (t1, x1, v1) = track.history[-2], track.history[-1]
    seen = v0 & v1 & vis
    if abs((stamp - t1) - (t1 - t0)) <= 0.2 * (t1 - t0) and seen.sum() >= 3:
        acc = np.linalg.norm(x[seen] - 2.0 * x1[seen] + x0[seen], axis=1) / np.sqrt(6.0)
        noise = float(np.median(acc)) / float(lifter.input_scales(x[None], seen[None].astype(float))[0])
    return vis, gated, predicted, noise, x


def _tracks(rng: np.random.Generator, n: int) -> tuple[list[Track], np.ndarray, np.ndarray, list[int]]:
    """n tracks with two past frames and a last fit, and this frame's 2D (some joints jumped, some
    missing, some frames too late for a prediction or unevenly spaced)."""
    tracks, points, vis, stamps = [], [], [], []
    for i in range(n):
        base = rng.normal(scale=60.0, size=(12, 2)) + 300.0
        t = 10 * STEP_NS * (i + 1)
        track = Track(None, t)
        for k, dt in ((2, 2 * STEP_NS), (1, STEP_NS)):
            track.history.append((t - dt, base + rng.normal(scale=1.5 * k, size=(12, 2)),
                                  rng.random(12) > 0.1))
        track.fits.append((t - STEP_NS, base + rng.normal(scale=1.0, size=(12, 2)), 80.0))
        for _ in range(int(rng.integers(0, 8))):  # a noise history: the gate's own scale
            track.noise.append(float(rng.uniform(0.0, 0.1)))
        track.gated = rng.integers(0, GATE_MAX_FRAMES + 1, size=12)
        track.swapped = rng.integers(0, SWAP_MAX_FRAMES + 1, size=2)
        x = base + rng.normal(scale=2.0, size=(12, 2)) + rng.normal(scale=5.0, size=2)  # and a motion
        for both, other in zip(GROUPS, OTHER, strict=True):  # a detector's swapped labels
            if rng.random() < 0.3:
                x[both] = x[other]
        jumped = rng.random(12) < rng.choice([0.0, 0.15, 0.6])
        x[jumped] += rng.normal(scale=150.0, size=(int(jumped.sum()), 2))
        late = rng.random() < 0.1
        uneven = rng.random() < 0.1
        tracks.append(track)
        points.append(x)
        vis.append(rng.random(12) > 0.15)
        stamps.append(t + (GATE_MAX_AGE_NS if late else 0) + (STEP_NS // 2 if uneven else 0))
    return tracks, np.array(points), np.array(vis), stamps


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_pass_screens_each_person_as_the_per_person_rule(seed: int) -> None:
    rng = np.random.default_rng(seed)
    lifter = Lifter(None, LifterOptions())
    tracks, points, vis, stamps = _tracks(rng, 40)
    copies, _, _, _ = _tracks(np.random.default_rng(seed), 40)  # the same tracks, for the reference
    got = screen_frames([ToScreen(t, True, lifter, x, np.where(v, 1.0, 0.0), s)
                         for t, x, v, s in zip(tracks, points, vis, stamps, strict=True)])
    n_gated = n_noise = n_swapped = 0
    for i, (t, x, v, s) in enumerate(zip(copies, points, vis, stamps, strict=True)):
        kept, gated, predicted, noise, labelled = _reference(t, lifter, x, v, s)
        assert got[i].visible is not None and (got[i].visible == kept).all()
        assert got[i].confidence is not None
        assert ((got[i].confidence == 0.0) == ~kept).all()
        assert (tracks[i].gated == t.gated).all()
        assert (tracks[i].swapped == t.swapped).all()
        if (labelled == x).all():
            assert got[i].swapped is None
        else:
            assert got[i].swapped is not None and (swap_back(x, got[i].swapped) == labelled).all()
            n_swapped += 1
        assert got[i].gated  # the gate was on
        if predicted is None:
            assert got[i].predicted is None
        else:
            assert got[i].predicted is not None
            np.testing.assert_allclose(got[i].predicted, predicted, rtol=0, atol=1e-9)
        assert len(tracks[i].noise) == len(t.noise) + (noise is not None)
        if noise is not None:
            assert tracks[i].noise[-1] == pytest.approx(noise, rel=1e-12)
            n_noise += 1
        n_gated += gated is not None
    # the cases were there: people gated, not gated, without a prediction, noise observed
    assert 3 <= n_gated <= 37 and n_noise >= 20 and 3 <= n_swapped <= 30
    assert any(g.predicted is None for g in got)


def test_swapped_labels_are_swapped_back_for_at_most_a_few_frames_in_a_row() -> None:
    """A track whose detector swaps the arms' labels: the screening gives the 2D with them swapped
    back (and the confidence with them) for SWAP_MAX_FRAMES frames in a row; on the next the
    detector's labels win, and the track follows them from then on. Without
    ``label_swaps`` the labels are the detector's."""
    rng = np.random.default_rng(7)
    base = rng.normal(scale=60.0, size=(12, 2)) + 300.0
    conf = np.linspace(0.5, 1.0, 12)
    for on in (True, False):
        lifter = Lifter(None, LifterOptions(label_swaps=on))
        track = Track(None, 0)
        for t in range(2):
            track.history.append((t * STEP_NS, base.copy(), np.ones(12, dtype=bool)))
        track.fits.append((STEP_NS, base.copy(), 80.0))
        swapped = base.copy()
        swapped[GROUPS[0]] = base[OTHER[0]]
        for k in range(SWAP_MAX_FRAMES + 2):
            stamp = (k + 2) * STEP_NS
            given_conf = conf[OTHER[0].tolist() + list(range(6, 12))]
            (got,) = screen_frames([ToScreen(track, True, lifter, swapped, given_conf, stamp)])
            seen = swapped if got.swapped is None else swap_back(swapped, got.swapped)
            if on and k < SWAP_MAX_FRAMES:
                assert (seen == base).all() and got.confidence is not None
                np.testing.assert_array_equal(got.confidence, conf)
            else:
                assert got.swapped is None and (seen == swapped).all()
            # the track as the policy leaves it: this frame's 2D, used, is where its joints were
            track.history.append((stamp, seen.copy(), np.ones(12, dtype=bool)))
            track.fits.append((stamp, seen.copy(), 80.0))


def test_a_frame_that_does_not_follow_its_track_is_not_screened() -> None:
    lifter = Lifter(None, LifterOptions())
    tracks, points, _, stamps = _tracks(np.random.default_rng(3), 3)
    before = [len(t.noise) for t in tracks]
    rows: Sequence[ToScreen] = [ToScreen(tracks[0], False, lifter, points[0], None, stamps[0]),
                                ToScreen(None, False, lifter, points[1], None, stamps[1]),
                                ToScreen(tracks[2], True, Lifter(None, LifterOptions(mode="paper")),
                                         points[2], None, stamps[2])]
    got = screen_frames(rows)
    assert [g.predicted is None and not g.gated for g in got] == [True, True, True]
    assert [len(t.noise) for t in tracks] == before


def test_the_tracks_limb_proportions_together_are_the_per_track_rule() -> None:
    """``tracks_limb_proportions`` over tracks of different ages, with and without the image
    spans, against the rule written per track: the calibrated median of the prior's proportions,
    blended in logs with the image's by the track's data weight."""
    from pose_lifter.core.track.state import (
        IMAGE_LIMB_MIN_FRAMES,
        LIMB_FRAMES,
        MIN_LIMB_FRAMES,
        calibrated_limb_proportions,
        tracks_limb_proportions,
    )

    rng = np.random.default_rng(5)
    tracks, image = [], []
    for n in (3, MIN_LIMB_FRAMES, 11, 11, 40, LIMB_FRAMES, LIMB_FRAMES + 7, 200):
        t = Track(None, 0)
        for _ in range(n):
            t.add_limbs(rng.uniform(0.8, 1.2, 8))
            t.add_spans(rng.uniform(0.7, 1.3, 8))
        for _ in range(int(rng.integers(0, 9))):
            t.noise.append(float(rng.uniform(0.0, 0.1)))
        tracks.append(t)
        image.append(bool(rng.random() < 0.6) or n == 200)
    got = tracks_limb_proportions(tracks, image)
    blended = 0
    for t, img, g in zip(tracks, image, got, strict=True):
        if t.n_limbs < MIN_LIMB_FRAMES:
            assert g is None
            continue
        prior = calibrated_limb_proportions(np.median(t.limbs[:min(t.n_limbs, LIMB_FRAMES)], axis=0))
        spans = t.image_limb_proportions() if img and t.n_spans >= IMAGE_LIMB_MIN_FRAMES else None
        want = prior
        if spans is not None:
            lam = t.data_weight()
            lp, ls = np.log(prior), np.log(spans)
            want = np.exp((1.0 - lam) * (lp - lp.mean()) + lam * (ls - ls.mean()) + lp.mean())
            blended += 1
        assert g is not None
        np.testing.assert_allclose(g, want, rtol=1e-13)
    assert blended >= 2
