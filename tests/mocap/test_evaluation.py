"""mocap.evaluation: what each condition does to the 2D, the figures of a track, the table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pose_lifter.core.model.skeleton import LIMBS, RIGHT_LOWER_LEG
from pose_lifter.core.model.synthetic import synthetic_poses
from pose_lifter.mocap import evaluation as ev
from tolerances import ROUND_OFF_ACCUMULATED


def _track(camera: tuple[float, float, str] = (45.0, 0.0, "weak"), n: int = 200) -> ev.Track:
    return ev.Track("t", synthetic_poses(n, seed=4), camera, 7)


def test_left_right_swaps_exchange_the_labels_of_whole_arms_or_legs() -> None:
    track = _track()
    clean, _, _, _ = ev.film_track(track, {}, np.random.default_rng(0))
    px, conf, _, _ = ev.film_track(track, ev.CONDITIONS["lrswap"], np.random.default_rng(0))
    assert np.all(conf == 1.0)
    arms = np.all(px[:, [0, 1, 2]] == clean[:, [3, 4, 5]], axis=(1, 2))
    legs = np.all(px[:, [6, 7, 8]] == clean[:, [9, 10, 11]], axis=(1, 2))
    same_arms = np.all(px[:, :6] == clean[:, :6], axis=(1, 2))
    same_legs = np.all(px[:, 6:] == clean[:, 6:], axis=(1, 2))
    assert np.all(arms ^ same_arms) and np.all(legs ^ same_legs)  # a limb pair swapped whole or kept
    assert 0.03 < arms.mean() < 0.2 and 0.03 < legs.mean() < 0.2  # ~10 % of frames each
    assert np.any(arms & ~legs)  # arms and legs swap independently


def test_the_lower_body_out_of_the_image_hides_knees_and_ankles_on_every_frame() -> None:
    _, conf, _, _ = ev.film_track(_track(), ev.CONDITIONS["lowercut"], np.random.default_rng(0))
    assert np.all(conf[:, [7, 8, 10, 11]] == 0.0) and np.all(np.delete(conf, [7, 8, 10, 11], axis=1) == 1.0)


def test_a_close_camera_is_in_perspective_and_a_high_one_looks_down() -> None:
    track = _track()
    far, _, _, cam_far = ev.film_track(track, {}, np.random.default_rng(0))
    near, _, _, cam_near = ev.film_track(track, ev.CONDITIONS["close"], np.random.default_rng(0))
    spread = lambda p: np.linalg.norm(p - p.mean(axis=1, keepdims=True), axis=-1).mean()  # noqa: E731
    assert spread(near) > 1.4 * spread(far)  # 3 m -> 2 m
    # perspective: the image is not the weak-perspective image of the same camera-frame pose
    weak = ev.FOCAL * cam_near[..., :2] / 2.0
    centred = near - near.mean(axis=1, keepdims=True)
    assert np.abs(centred - (weak - weak.mean(axis=1, keepdims=True))).max() > 1.0
    _, _, _, cam_above = ev.film_track(track, ev.CONDITIONS["above"], np.random.default_rng(0))
    # seen from 50 degrees above, the person's up direction (hips -> shoulders) leans 50 degrees
    # towards the camera (negative depth) compared with a level camera
    up = cam_above[:, [0, 3]].mean(axis=1) - cam_above[:, [6, 9]].mean(axis=1)
    up_level = cam_far[:, [0, 3]].mean(axis=1) - cam_far[:, [6, 9]].mean(axis=1)
    tilt = np.degrees(np.arctan2(up[:, 2], -up[:, 1])).mean()
    level = np.degrees(np.arctan2(up_level[:, 2], -up_level[:, 1])).mean()
    assert tilt - level == pytest.approx(-50.0, abs=8.0)


def test_the_detector_conditions_film_every_fault_at_their_distance() -> None:
    track = _track((90.0, 0.0, "weak"))
    clean6, _, _, cam6 = ev.film_track(track, {"distance": 6.0}, np.random.default_rng(0))
    px6, conf6, _, _ = ev.film_track(track, ev.CONDITIONS["detector6m"], np.random.default_rng(0))
    clean3, _, _, _ = ev.film_track(track, {"distance": 3.0}, np.random.default_rng(0))
    px3, _, _, _ = ev.film_track(track, ev.CONDITIONS["detector3m"], np.random.default_rng(0))
    spread = lambda p: np.linalg.norm(p - p.mean(axis=1, keepdims=True), axis=-1).mean()  # noqa: E731
    assert spread(clean3) == pytest.approx(2.0 * spread(clean6), rel=0.1)  # perspective at 6 and 3 m
    seen = conf6 >= 0.1
    err = np.linalg.norm(px6 - clean6, axis=-1)
    # noisy everywhere, a few joints lost, and the error in pixels halves with the distance doubled
    assert np.median(err[seen]) > 0.5 and 0.01 < (~seen).mean() < 0.2
    ratio = np.median(np.linalg.norm(px3 - clean3, axis=-1)) / np.median(err)
    assert ratio == pytest.approx(2.0, rel=0.2)
    assert np.isfinite(px6).all() and np.isfinite(cam6).all()


def test_the_detector_diagnostics_split_its_noise_from_its_faults() -> None:
    """detnoise6m: the detector's noise alone (nothing lost, swapped or displaced far), correlated
    over frames; detwhite6m: the same noise independent over frames; detfaults6m: its faults on
    exact 2D (most joints exactly where the camera puts them, the others lost, swapped or
    displaced)."""
    track = _track((90.0, 0.0, "weak"))
    clean, _, _, _ = ev.film_track(track, {"distance": 6.0}, np.random.default_rng(0))
    knee, ankle = LIMBS[RIGHT_LOWER_LEG]
    leg = np.linalg.norm(clean[:, knee] - clean[:, ankle], axis=-1).mean()  # the right shin, px
    errors = {}
    for cond in ("detnoise6m", "detwhite6m", "detfaults6m"):
        px, conf, _, _ = ev.film_track(track, ev.ALL_CONDITIONS[cond], np.random.default_rng(0))
        errors[cond] = (px - clean, conf)
    noise, conf = errors["detnoise6m"]
    white, white_conf = errors["detwhite6m"]
    assert np.all(conf > 0) and np.all(white_conf > 0)  # nothing lost
    assert np.abs(noise).max() < leg and np.abs(white).max() < leg  # no outliers, no swaps
    # as large as each other (~0.05 leg per axis), correlated 0.7 from frame to frame or not
    assert np.std(noise) == pytest.approx(np.std(white), rel=0.2)
    lag1 = lambda e: np.corrcoef(e[1:].ravel(), e[:-1].ravel())[0, 1]  # noqa: E731
    assert lag1(noise) == pytest.approx(0.7, abs=0.1) and abs(lag1(white)) < 0.1
    faults, fconf = errors["detfaults6m"]
    exact = np.all(np.abs(faults) < 1e-9, axis=-1) & (fconf > 0)
    assert 0.8 < exact.mean() < 0.99 and np.abs(faults).max() > leg  # confident outliers among them
    assert "detnoise6m" not in ev.CONDITIONS  # run only when named


def test_a_tracks_figures_per_method_and_frame() -> None:
    """The floors need no lifter: the flat floor's poses with the true depths put in are the truth
    (0 mm); the paper's method, warm-started over a clean track, lifts every frame, its P-MPJPE
    (similarity-aligned) never above its MPJPE (not aligned); a perspective track also gives the
    placement's depth error."""
    evaluator = ev.Evaluator(("flat", "mean-pose", "paper"), {"n_starts": 3})
    rec = evaluator.evaluate(_track((90.0, 0.0, "perspective"), n=6), "clean")
    assert rec["n"] == 6 and rec["cond"] == "clean" and set(rec["methods"]) == {"flat", "mean-pose", "paper"}
    flat, paper = rec["methods"]["flat"], rec["methods"]["paper"]
    assert all(len(flat[k]) == 6 for k in ev.FIGURES)
    assert np.allclose(flat["true_depth"], 0.0, atol=1e-6) and np.nanmin(flat["p_mpjpe"]) > 10.0
    assert np.isnan(flat["jitter"][0]) and np.isnan(flat["jitter"][-1])  # acceleration: inner frames
    assert np.isfinite(paper["p_mpjpe"]).all()
    assert np.all(np.array(paper["p_mpjpe"]) <= np.array(paper["mpjpe"]) + ROUND_OFF_ACCUMULATED)
    assert "depth_pct" in paper and "depth_pct" not in flat and np.isfinite(paper["depth_pct"]).all()


def _record(cond: str, p_mpjpe: list[float]) -> dict[str, object]:
    figures = {k: p_mpjpe for k in ev.FIGURES}
    return {"cond": cond, "methods": {"paper": {**figures, "ms": 2.0}}}


def test_the_table_averages_frames_over_tracks_and_renders_as_markdown() -> None:
    results = [_record("clean", [10.0, float("nan")]), _record("clean", [20.0, 30.0]),
               _record("noise0.1", [40.0, 40.0])]
    table = ev.summarise(results, ["clean", "noise0.1"], ["paper"])
    assert table["clean"]["paper"]["p_mpjpe"] == pytest.approx(20.0)  # frames, not tracks
    assert table["clean"]["paper"]["lifted"] == pytest.approx(0.75)
    assert np.isnan(table["clean"]["paper"]["depth_pct"])
    text = ev.render_table(table, ("paper",), "header line", "footer line")
    lines = text.splitlines()
    assert lines[0] == "header line" and lines[-1] == "footer line"
    assert "| clean | 20.0 / 20.0 / 20.0 |" in lines and "| noise0.1 | 40.0 / 40.0 / 40.0 |" in lines
    assert "frames lifted: paper 75.0 %" in text and "centroid depth error" not in text


def test_merged_runs_take_each_method_from_the_last_file_that_has_it(tmp_path: Path) -> None:
    row = {"p_mpjpe": 1.0}
    a, b, c = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "c.json"
    a.write_text(json.dumps({"split": "eval", "table": {"clean": {"paper": row, "hybrid": row}}}))
    b.write_text(json.dumps({"split": "eval", "table": {"clean": {"hybrid": {"p_mpjpe": 2.0}}}}))
    c.write_text(json.dumps({"split": "val", "table": {"clean": {"paper": row}}}))
    table, methods, header, by_file = ev.merge_runs([a, b])
    assert methods == ("paper", "hybrid") and table["clean"]["hybrid"]["p_mpjpe"] == 2.0
    assert by_file == {str(a): ["paper"], str(b): ["hybrid"]} and header.startswith("eval split")
    with pytest.raises(ValueError, match="different splits"):
        ev.merge_runs([a, c])


def test_a_run_is_stamped_with_its_commit_and_cpu(tmp_path: Path) -> None:
    repo = Path(__file__).resolve().parents[2]
    stamp = ev.run_stamp(repo)
    assert stamp.startswith("commit ") and ", CPU " in stamp and "unknown" not in stamp.split(",")[0]
    assert ev.run_stamp(tmp_path).startswith("commit unknown, CPU ")  # not a checkout
    assert ev.parse_settings(["n_starts=3", " mode = 'paper'"]) == {"n_starts": 3, "mode": "paper"}


def test_the_accuracy_tool_writes_a_merged_table_stamped_with_where_it_was_measured(tmp_path: Path) -> None:
    from tool_modules import load_tool

    tool = load_tool("accuracy", "accuracy_tool")
    figures = {k: 1.0 for k in ("p_mpjpe", "mpjpe", "jitter", "ms", "lifted")}
    runs = []
    for i, method in enumerate(("paper", "hybrid")):
        run = tmp_path / f"run{i}.json"
        run.write_text(json.dumps({"split": "eval", "measured_at": f"commit c{i}, CPU x",
                                   "table": {"clean": {method: figures}}}))
        runs.append(str(run))
    assert tool.main(["--merge", *runs, "--out", str(tmp_path / "out")]) == 0
    text = (tmp_path / "out" / "accuracy.md").read_text()
    assert text.splitlines()[0].endswith("measured at commit c0, CPU x and commit c1, CPU x")
    assert "| clean | 1.0 / 1.0 / 1.0 | 1.0 / 1.0 / 1.0 |" in text
    assert (tmp_path / "out" / "accuracy.png").stat().st_size > 0
