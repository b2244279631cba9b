"""The depth camera model (pose_lifter.mocap.body_surface and .depth_model): the rendered body
surface against analytic depths, occlusion order, the background, and each sensor fault at its
stated rate (statistical bounds are several standard errors wide)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import tolerances as tol
from pose_lifter.core.errors import InvalidInputError
from pose_lifter.mocap import body_surface as bs
from pose_lifter.mocap import depth_model as dm
from scipy import ndimage

F = 800.0
CX, CY = 320.0, 240.0
INTR = ((F, F), (CX, CY))
#: A sensor with every fault off; each test turns one on.
IDEAL = dm.DepthSensor(noise_c=0.0, quantisation_m=0.0, mixed_rate=0.0, baseline_m=0.0, hole_rate=0.0,
                       min_range_m=0.0, max_range_m=100.0)


def _t_pose(depth: float, shoulder_y: float) -> np.ndarray:
    """(12, 3) a person in a T-pose facing the camera (their left at +x), upright (up = -y), every
    joint at z = ``depth``, shoulder centre at (0, shoulder_y): the head's centre is at
    (0, shoulder_y - HEAD_ABOVE_SHOULDERS, depth); arms horizontal, legs vertical."""
    y, z = shoulder_y, depth
    return np.array([
        [0.18, y, z], [0.46, y, z], [0.72, y, z],  # left shoulder, elbow, wrist
        [-0.18, y, z], [-0.46, y, z], [-0.72, y, z],  # right
        [0.1, y + 0.5, z], [0.1, y + 0.95, z], [0.1, y + 1.4, z],  # left hip, knee, ankle
        [-0.1, y + 0.5, z], [-0.1, y + 0.95, z], [-0.1, y + 1.4, z],  # right
    ])


def _row_extent(mask: np.ndarray) -> tuple[int, int]:
    cols = np.flatnonzero(mask)
    return int(cols.min()), int(cols.max())


# --------------------------------------------------------------------------- geometry


def test_head_sphere_depth_and_silhouette_match_the_analytic_sphere() -> None:
    d = 3.0
    pose = _t_pose(d, bs.HEAD_ABOVE_SHOULDERS)  # head centre on the optical axis at depth d
    r = dm.render_depth(pose[None], INTR, background=None)
    head = bs.PART_NAMES.index("head")
    v, u = int(CY), int(CX)
    assert r.part[v, u] == head and r.person[v, u] == 0
    assert r.depth[v, u] == pytest.approx(d - bs.HEAD_RADIUS, abs=tol.ROUND_OFF_ACCUMULATED)
    # the silhouette: a circle of f r / sqrt(d^2 - r^2) pixels
    radius_px = F * bs.HEAD_RADIUS / np.sqrt(d * d - bs.HEAD_RADIUS**2)
    lo, hi = _row_extent(r.part[v] == head)
    assert lo == int(np.ceil(CX - radius_px)) and hi == int(np.floor(CX + radius_px))
    top = np.flatnonzero(r.part[:, u] == head).min()
    assert top == int(np.ceil(CY - radius_px))
    # every head pixel is where the ray meets the sphere: |t ray - centre| = r
    vv, uu = np.nonzero(r.part == head)
    t = r.depth[vv, uu]
    pts = np.stack([t * (uu - CX) / F, t * (vv - CY) / F, t], axis=1)
    np.testing.assert_allclose(np.linalg.norm(pts - [0.0, 0.0, d], axis=1), bs.HEAD_RADIUS,
                               atol=tol.ROUND_OFF_ACCUMULATED)


def test_vertical_shin_capsule_matches_the_analytic_cylinder() -> None:
    d = 2.5
    pose = _t_pose(d, -1.175)  # the shins' middles on the row y = 0 (row cy), at x = +-0.1
    r = dm.render_depth(pose[None], INTR, background=None)
    shin = bs.PART_NAMES.index("left_shin")
    v = int(CY)
    # the row's rays (xn, 0, 1) meet the circle of radius r about (0.1, d) in the plane y = 0
    rad, xc = bs.SHIN_RADIUS, 0.1
    lo, hi = _row_extent(r.part[v] == shin)
    rho, theta = np.hypot(xc, d), np.arctan2(xc, d)
    edges = CX + F * np.tan(theta + np.array([-1.0, 1.0]) * np.arcsin(rad / rho))
    assert lo == int(np.ceil(edges[0])) and hi == int(np.floor(edges[1]))
    u = np.arange(lo, hi + 1)
    xn = (u - CX) / F
    a, b, c = xn * xn + 1.0, xn * xc + d, xc * xc + d * d - rad * rad
    np.testing.assert_allclose(r.depth[v, u], (b - np.sqrt(b * b - a * c)) / a,
                               atol=tol.ROUND_OFF_ACCUMULATED)
    assert r.depth[v, int(CX + F * xc / d)] == pytest.approx(d - rad, abs=1e-4)  # the nearest point


def test_torso_is_the_stated_width_and_depth() -> None:
    d = 3.0
    pose = _t_pose(d, 0.0)
    r = dm.render_depth(pose[None], INTR, background=None)
    torso = bs.PART_NAMES.index("torso")
    v = int(CY + F * 0.3 / d)  # between the arms and the legs
    lo, hi = _row_extent(r.part[v] == torso)
    width_m = (hi - lo + 1) * d / F
    assert width_m == pytest.approx(2 * bs.TORSO_HALF_WIDTH, abs=2 * d / F)
    assert 0.3 <= 2 * bs.TORSO_HALF_WIDTH <= 0.35 and 2 * bs.TORSO_HALF_DEPTH == pytest.approx(0.2)
    assert r.depth[v, int(CX)] == pytest.approx(d - bs.TORSO_HALF_DEPTH, abs=1e-4)


def test_a_near_limb_occludes_the_torso_and_a_far_one_is_hidden() -> None:
    d = 3.0
    pose = _t_pose(d, 0.0)
    front, back = pose.copy(), pose.copy()
    # the right forearm reaching across the chest, 0.35 m in front of the body / behind the back
    front[5] = [0.05, 0.25, d - 0.35]
    back[5] = [0.05, 0.25, d + 0.35]
    u, v = int(CX + F * 0.02 / (d - 0.3)), int(CY + F * 0.25 / d)
    rf = dm.render_depth(front[None], INTR, background=None)
    rb = dm.render_depth(back[None], INTR, background=None)
    assert bs.PART_NAMES[rf.part[v, u]] in ("right_forearm", "right_hand")
    assert rf.depth[v, u] < d - bs.TORSO_HALF_DEPTH - 0.1
    assert bs.PART_NAMES[rb.part[v, u]] == "torso"
    assert rb.depth[v, u] == pytest.approx(d - bs.TORSO_HALF_DEPTH, abs=0.01)
    # a nearer person hides a farther one where they overlap
    far = _t_pose(4.0, 0.0) + np.array([1.0, 0.0, 0.0])
    two = dm.render_depth(np.stack([far, _t_pose(2.0, 0.0)]), INTR, background=None)
    alone = dm.render_depth(far[None], INTR, background=None)
    assert two.person[int(CY), int(CX)] == 1
    assert 0 < (two.person == 0).sum() < (alone.person == 0).sum()


def test_wall_and_floor() -> None:
    d = 3.0
    pose = _t_pose(d, -0.8)  # feet in the image
    r = dm.render_depth(pose[None], INTR)
    wall = d + dm.Background().wall_behind
    assert r.depth[5, 5] == pytest.approx(wall, abs=tol.ROUND_OFF_ACCUMULATED) and r.person[5, 5] == -1
    floor_y = pose[[8, 11], 1].max() + bs.ANKLE_HEIGHT  # camera y is down
    v = 479
    assert r.person[v, 5] == -1
    assert r.depth[v, 5] == pytest.approx(floor_y / ((v - CY) / F), abs=tol.ROUND_OFF_ACCUMULATED)
    # the feet stand on the floor: their lowest point is at the floor's height
    foot = np.isin(r.part, [bs.PART_NAMES.index("left_foot"), bs.PART_NAMES.index("right_foot")])
    vv, uu = np.nonzero(foot)
    k = np.argmax(vv)
    lowest_y = (vv[k] - CY) / F * r.depth[vv[k], uu[k]]
    assert floor_y - 2 * d / F <= lowest_y <= floor_y + tol.ROUND_OFF_ACCUMULATED
    assert np.all(np.isinf(dm.render_depth(pose[None], INTR, background=None).depth[:, 5]))
    empty = dm.render_depth(np.zeros((0, 12, 3)), INTR, background=dm.Background(wall_depth=2.0))
    assert np.all(empty.depth == 2.0) and np.all(empty.person == -1)


def test_scene_backgrounds_stay_put_when_the_person_jumps() -> None:
    d = 3.0
    standing = _t_pose(d, -0.8)
    jumping = standing + np.array([0.0, -0.3, 0.5])  # 0.3 m up, 0.5 m farther
    seq = np.stack([standing, jumping])[None]  # (1, 2, 12, 3)
    up = np.tile([0.0, -1.0, 0.0], (2, 1))
    backs = dm.scene_backgrounds(seq, up)
    assert backs[0] == backs[1]
    assert backs[0].wall_depth == pytest.approx(d + 0.25 + backs[0].wall_behind)
    assert backs[0].floor_height == pytest.approx(-(standing[8, 1] + bs.ANKLE_HEIGHT))
    a, b = (dm.render_depth(p[None], INTR, background=g) for p, g in zip(seq[0], backs, strict=True))
    assert a.depth[479, 5] == b.depth[479, 5] and a.depth[5, 5] == b.depth[5, 5]
    # on a per-image background the floor would follow the feet up
    c = dm.render_depth(jumping[None], INTR)
    assert c.depth[479, 5] < b.depth[479, 5]  # a higher floor meets the downward rays sooner


def test_bounding_boxes_clip_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each primitive cast over its image box only gives the image that casting every primitive
    over the whole image gives: near the camera (primitives across its plane), far, off-centre."""
    rng = np.random.default_rng(0)
    poses = [_t_pose(d, rng.uniform(-1.2, 0.5)) + rng.normal(0.0, 0.05, (12, 3)) + [rng.uniform(-1, 1), 0, 0]
             for d in (0.08, 0.4, 1.5, 3.0, 6.0) for _ in range(3)]
    boxed = [dm.render_depth(np.maximum(p, [-9, -9, 0.02])[None], INTR) for p in poses]
    monkeypatch.setattr(bs._Canvas, "boxes", lambda self, c, r: [[0, self.h, 0, self.w]] * len(c))
    for p, r in zip(poses, boxed, strict=True):
        full = dm.render_depth(np.maximum(p, [-9, -9, 0.02])[None], INTR)
        assert np.array_equal(r.depth, full.depth) and np.array_equal(r.part, full.part)


def test_bad_input_is_refused() -> None:
    with pytest.raises(InvalidInputError, match=r"\(P, 12, 3\)"):
        dm.render_depth(np.zeros((12, 3)), INTR)
    pose = _t_pose(3.0, 0.0)
    pose[2, 2] = -0.1
    with pytest.raises(InvalidInputError, match="in front of the camera"):
        dm.render_depth(pose[None], INTR)
    with pytest.raises(InvalidInputError, match="wall_depth"):
        dm.Background(wall_depth=-1.0)
    with pytest.raises(ValueError, match="hole_rate"):
        dm.DepthSensor(hole_rate=1.5)


# --------------------------------------------------------------------------- the sensor


def _wall(depth: float) -> dm.RenderedDepth:
    return dm.render_depth(np.zeros((0, 12, 3)), INTR, background=dm.Background(wall_depth=depth))


def _person(d: float = 3.0, wall: float = 5.5) -> dm.RenderedDepth:
    return dm.render_depth(_t_pose(d, -0.4)[None], INTR,
                           background=dm.Background(wall_depth=wall, floor=False))


@pytest.mark.parametrize("depth", [2.0, 4.0])
def test_noise_std_grows_with_the_square_of_the_distance(depth: float) -> None:
    sensor = replace(IDEAL, noise_c=dm.REALISTIC.noise_c, quantisation_m=0.001)
    z = dm.sense(_wall(depth), sensor, np.random.default_rng(0))
    assert z.dtype == np.float32 and z.shape == (480, 640) and np.all(np.isfinite(z))
    err = z.astype(np.float64) - depth
    sigma = dm.REALISTIC.noise_c * depth**2
    assert err.std() == pytest.approx(sigma, rel=0.03)
    assert abs(err.mean()) < 0.01 * sigma
    assert 0.002 <= dm.REALISTIC.noise_c <= 0.003
    # correlated over the window: neighbours alike, pixels a window apart independent
    w = sensor.noise_window_px
    assert np.corrcoef(err[:, :-1].ravel(), err[:, 1:].ravel())[0, 1] > 0.5
    assert abs(np.corrcoef(err[:, :-w].ravel(), err[:, w:].ravel())[0, 1]) < 0.02


def test_quantisation_is_one_millimetre() -> None:
    z = dm.sense(_person(), replace(IDEAL, noise_c=dm.REALISTIC.noise_c, quantisation_m=0.001),
                 np.random.default_rng(1))
    mm = z[np.isfinite(z)].astype(np.float64) * 1000.0
    assert np.abs(mm - np.round(mm)).max() < 1e-3  # float32 of k mm, k < 6000
    assert len(np.unique(np.round(mm))) > 100


def test_holes_are_blobs_at_the_stated_rate() -> None:
    sensor = replace(IDEAL, hole_rate=0.03)
    z = dm.sense(_wall(2.0), sensor, np.random.default_rng(2))
    lost = np.isnan(z)
    assert lost.mean() == pytest.approx(0.03, abs=0.005)  # ~19000 cells: std 0.0012
    labels, n = ndimage.label(lost)
    sizes = np.bincount(labels.ravel())[1:]
    assert n > 100 and np.median(sizes) >= sensor.hole_size_px**2 / 2  # blobs, not single pixels
    assert not np.isnan(dm.sense(_wall(2.0), IDEAL, np.random.default_rng(2))).any()


def test_edge_shadow_is_on_the_far_side_left_of_the_person_only() -> None:
    d, wall = 3.0, 5.5
    r = _person(d, wall)
    z = dm.sense(r, replace(IDEAL, baseline_m=dm.REALISTIC.baseline_m), np.random.default_rng(3))
    lost = np.isnan(z)
    assert lost.any()
    assert np.all(r.person[lost] == -1)  # only the background is shadowed
    width = F * dm.REALISTIC.baseline_m * (1 / d - 1 / wall)  # ~6.1 px
    # per row: each run of lost pixels ends just left of the person, as wide as the disparity step
    for v in (int(CY - F * 0.2 / d), int(CY + F * 0.4 / d)):  # torso, thighs
        person = r.person[v] >= 0
        runs, n = ndimage.label(lost[v])
        assert n >= 1
        for k in range(1, n + 1):
            run = np.flatnonzero(runs == k)
            assert person[run.max() + 1]
            near = r.depth[v, run.max() + 1]
            assert run.size == pytest.approx(F * dm.REALISTIC.baseline_m * (1 / near - 1 / wall), abs=1.0)
        assert not lost[v, np.flatnonzero(person).max():].any()
    assert 4 < width < 8


def test_mixed_pixels_only_at_silhouettes_between_near_and_far() -> None:
    r = _person()
    rate = 0.3
    z = dm.sense(r, replace(IDEAL, mixed_rate=rate), np.random.default_rng(4)).astype(np.float64)
    ideal = r.depth
    changed = np.abs(z - ideal) > 1e-6  # float32 of the ideal depth elsewhere
    edge = dm.silhouette(ideal, IDEAL.edge_jump_m)
    assert changed.any() and np.all(edge[changed])
    pad = np.pad(ideal, 1, constant_values=np.inf)
    vv, uu = np.nonzero(changed)
    around = np.stack([pad[vv + i, uu + j] for i in range(3) for j in range(3)])
    assert np.all(z[changed] >= around.min(axis=0) - 1e-6) and np.all(z[changed] <= around.max(axis=0) + 1e-6)
    # strictly between: neither surface's own depth (a flying pixel)
    assert np.mean((z[changed] > around.min(axis=0) + 0.01) & (z[changed] < around.max(axis=0) - 0.01)) > 0.8
    assert changed.sum() / edge.sum() == pytest.approx(rate, abs=0.04)


def test_nothing_beyond_the_range() -> None:
    sensor = dm.REALISTIC
    assert np.isnan(dm.sense(_wall(6.5), sensor, np.random.default_rng(5))).all()
    assert np.isnan(dm.sense(_wall(0.25), sensor, np.random.default_rng(5))).all()
    z = dm.sense(_wall(5.9), sensor, np.random.default_rng(5))  # sigma 84 mm: many draws beyond 6 m
    finite = z[np.isfinite(z)]
    assert finite.max() <= sensor.max_range_m and 0.3 < finite.size / z.size < 0.9
    everything = dm.sense(_person(), sensor, np.random.default_rng(6))
    assert np.nanmax(everything) <= sensor.max_range_m and np.nanmin(everything) >= sensor.min_range_m


def test_sense_is_deterministic_for_a_generator_state() -> None:
    r = _person()
    a = dm.sense(r, dm.REALISTIC, np.random.default_rng(7))
    b = dm.sense(r, dm.REALISTIC, np.random.default_rng(7))
    c = dm.sense(r, dm.REALISTIC, np.random.default_rng(8))
    assert np.array_equal(a, b, equal_nan=True) and not np.array_equal(a, c, equal_nan=True)


@pytest.mark.parametrize("turn_deg", [-90, -75, -60, -45, -30, 0, 30, 45, 60, 75, 90])
def test_the_fusions_occlusion_test_hides_what_the_rendered_body_hides(turn_deg: int) -> None:
    """A body turning away from the camera about its spine: the fusion's occlusion test
    (``core.depth.fuse._hidden``: limbs and an elliptic trunk) hides at each joint's pixel what the
    rendered body surface shows nearer than the joint's surface by its margin (the trunk's
    width matters from ~60 degrees: a round trunk misses the far elbow there)."""
    from pose_lifter.core.depth.fuse import _hidden
    from pose_lifter.core.depth.reading import SURFACE_OFFSET_M

    k = ((600.0, 600.0), (320.0, 240.0))
    facing = np.array([[0.19, -0.5, 0.0], [0.22, -0.2, 0.0], [0.22, 0.05, 0.0], [-0.19, -0.5, 0.0],
                       [-0.22, -0.2, 0.0], [-0.22, 0.05, 0.0], [0.1, 0.05, 0.0], [0.1, 0.5, 0.0],
                       [0.1, 0.9, 0.0], [-0.1, 0.05, 0.0], [-0.1, 0.5, 0.0], [-0.1, 0.9, 0.0]])
    a = np.radians(turn_deg)
    turn = np.array([[np.cos(a), 0.0, -np.sin(a)], [0.0, 1.0, 0.0], [np.sin(a), 0.0, np.cos(a)]])
    body = facing @ turn.T + np.array([0.0, 0.0, 3.0])
    pixels = 600.0 * body[:, :2] / body[:, 2:] + np.array([320.0, 240.0])
    margin = 0.08
    img = bs.render_depth(body[None], k, (640, 480), bs.Background(floor=False)).depth
    u, v = np.round(pixels).astype(int).T
    rendered = img[v, u] < body[:, 2] - SURFACE_OFFSET_M - margin
    got = _hidden(body[None], pixels[None], np.ones((1, 12), dtype=bool), k, margin)[0]
    np.testing.assert_array_equal(got, rendered)
    assert rendered.any() == (abs(turn_deg) >= 60)  # the far side is hidden when turned far enough
