"""pose-lifter CLI: learn-bases, make-bag, evaluate (lift is exercised in test_bags.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tolerances as tol
from cmu_data import DATA, needs_data
from mcap_check import check_mcap
from pose_lifter import cli
from pose_lifter.core.model.bases import PoseBases
from pose_lifter.messages import convert as m
from pose_lifter.mocap import cmu as mocap
from pose_lifter.mocap import scenes
from pose_lifter.offline import bags
from pose_lifter.offline.evaluate import evaluate_bag
from scipy.spatial.transform import Rotation


def test_help_lists_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("learn-bases", "make-bag", "lift", "evaluate", "demo"):
        assert cmd in out


def test_missing_data_is_a_clean_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = cli.main(["make-bag", "07_05", "--out", str(tmp_path / "x.mcap"), "--data", str(tmp_path)])
    assert rc == 2
    assert "CMU mocap data not found" in capsys.readouterr().err


@needs_data
def test_learn_bases_pca(tmp_path: Path) -> None:
    out = tmp_path / "b.npz"
    rc = cli.main(["learn-bases", "--method", "pca", "--n-bases", "12", "--step", "60", "--starts", "4",
                   "--out", str(out)])
    assert rc == 0
    b = PoseBases.load(out)
    assert b.method == "pca" and b.n_bases == 12 and b.start_alphas.shape == (4, 12)
    assert "learn-bases --method pca" in b.metadata["command"]
    assert b.metadata["training_trials"][0] == "01_01" and all(
        t.startswith("01_") for t in b.metadata["training_trials"])
    # normalised training data: the mean pose has a unit right lower leg (roughly)
    assert b.limb_proportions[7] == pytest.approx(1.0)
    # PCA bases are orthonormal
    np.testing.assert_allclose(b.components.T @ b.components, np.eye(12), atol=tol.ROUND_OFF_ACCUMULATED)


@needs_data
def test_make_bag_and_floors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "w.mcap"
    rc = cli.main(["make-bag", "07_05", "02_05", "--out", str(out), "--frames", "12", "--fps", "15",
                   "--noise", "0.05", "--missing", "0.1"])
    assert rc == 0
    assert check_mcap(out) == {"/camera_info": 12, "/keypoints_2d": 12, "/ground_truth/skeletons_3d": 12}
    kp = [x.msg for x in bags.read_messages(out, ["/keypoints_2d"])]
    assert len(kp) == 12 and [s.track_id for s in kp[0].skeletons] == [0, 1]
    stamps = [m.stamp_to_ns(x.header.stamp) for x in kp]
    assert np.allclose(np.diff(stamps), 1e9 / 15, atol=1)
    # the ground truth is the loaded mocap (15 Hz = every 8th frame), rigidly moved into the camera
    gt = [x.msg for x in bags.read_messages(out, ["/ground_truth/skeletons_3d"])]
    truth = np.array([m.skeleton3d_to_joints(x.skeletons[0]) for x in gt])
    source = mocap.load_trial("07_05", DATA, step=8, max_frames=12)
    d_truth = np.linalg.norm(truth[:, :, None] - truth[:, None], axis=-1)
    d_source = np.linalg.norm(source[:, :, None] - source[:, None], axis=-1)
    np.testing.assert_allclose(d_truth, d_source, atol=tol.ROUND_OFF_ACCUMULATED)
    capsys.readouterr()
    assert cli.main(["evaluate", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["n_matched"] == 0 and res["n_ground_truth"] == 24
    assert res["mean"]["lifter"]["p_mpjpe_mm"] is None
    assert 50 < res["mean"]["flat_floor"]["p_mpjpe_mm"] < 250
    assert 50 < res["mean"]["mean_pose_floor"]["p_mpjpe_mm"] < 250


@needs_data
def test_make_bag_one_after_another_without_camera_info(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "seq.mcap"
    rc = cli.main(["make-bag", "07_05", "02_05", "07_05", "--out", str(out), "--frames", "6", "--fps", "15",
                   "--noise", "0.05", "--one-after-another", "--no-camera-info"])
    assert rc == 0 and "tracks [0, 1, 2]" in capsys.readouterr().out
    assert check_mcap(out) == {"/keypoints_2d": 18, "/ground_truth/skeletons_3d": 18}
    kp = [x.msg for x in bags.read_messages(out, ["/keypoints_2d"])]
    assert [[s.track_id for s in x.skeletons] for x in kp] == [[0]] * 6 + [[1]] * 6 + [[2]] * 6
    stamps = np.array([m.stamp_to_ns(x.header.stamp) for x in kp])
    # 15 Hz within a trial; each trial starts a second after the previous one's last frame
    steps = np.diff(stamps)
    np.testing.assert_allclose(np.delete(steps, [5, 11]), 1e9 / 15, atol=1)
    np.testing.assert_array_equal(steps[[5, 11]], 1_000_000_000)
    # the same trial twice: the same person, its own corruption
    pts = np.array([m.skeleton2d_to_arrays(x.skeletons[0], x.layout)[0] for x in kp])
    truth = np.array([m.skeleton3d_to_joints(x.msg.skeletons[0])
                      for x in bags.read_messages(out, ["/ground_truth/skeletons_3d"])])
    np.testing.assert_allclose(truth[12:], truth[:6], atol=tol.ROUND_OFF_ACCUMULATED)
    assert not np.allclose(pts[12:], pts[:6])


def _bag_with_estimates(tmp_path: Path, transform: np.ndarray, offset: np.ndarray) -> Path:
    """A scene bag plus /skeletons_3d = ground truth moved by a rotation and offset."""
    rng = np.random.default_rng(0)
    clip = rng.normal(scale=0.3, size=(5, 12, 3)) + np.array([0.0, 1.0, 0.0])
    sc = scenes.build_scene([clip, clip + 0.01], scenes.SceneOptions(distance=4.0), track_ids=[3, 8])
    path = tmp_path / "in.mcap"
    bags.write_messages(path, scenes.scene_messages(sc))
    t = m.rosbags_types()
    out = tmp_path / "est.mcap"
    with bags.BagWriter(out) as w:
        for x in bags.read_messages(path):
            w.write(x.topic, x.stamp_ns, x.msg, x.msgtype)
            if x.topic == "/ground_truth/skeletons_3d" and x.stamp_ns != sc.stamps_ns[-1]:
                skels = []
                for sk in x.msg.skeletons:
                    j = m.skeleton3d_to_joints(sk)
                    c = j.mean(axis=0)
                    skels.append(m.skeleton3d_from_joints(sk.track_id, (j - c) @ transform.T + c + offset, t))
                w.write("/skeletons_3d", x.stamp_ns, m.skeletons3d_array(x.msg.header, skels, t),
                        "pose_lifter_msgs/msg/Skeleton3DArray")
    return out


def test_evaluate_matches_by_stamp_and_track(tmp_path: Path) -> None:
    out = _bag_with_estimates(tmp_path, np.eye(3), np.array([0.0, 0.0, 0.5]))
    ev = evaluate_bag(out)
    assert (ev.n_ground_truth, ev.n_estimates, ev.n_matched) == (10, 8, 8)
    # a translated copy of the truth: every centred error is 0
    np.testing.assert_allclose(ev.mpjpe_mm, 0, atol=tol.ROUND_OFF_ACCUMULATED)
    np.testing.assert_allclose(ev.p_mpjpe_mm, 0, atol=tol.ROUND_OFF_ACCUMULATED)
    np.testing.assert_allclose(ev.normalised, 0, atol=tol.ROUND_OFF_ACCUMULATED)
    assert sorted(set(ev.track_ids.tolist())) == [3, 8]


def test_evaluate_rotation_counts_in_mpjpe_only(tmp_path: Path) -> None:
    rot = Rotation.from_euler("y", 40, degrees=True).as_matrix()
    ev = evaluate_bag(_bag_with_estimates(tmp_path, rot, np.zeros(3)))
    assert np.all(ev.mpjpe_mm > 50)
    np.testing.assert_allclose(ev.p_mpjpe_mm, 0, atol=1e-6)
    np.testing.assert_allclose(ev.normalised, 0, atol=1e-6)


def test_demo_plot_writes_png(tmp_path: Path) -> None:
    from pose_lifter.offline.demo import find_demo_bag, plot_frames

    bag = find_demo_bag()
    frames: dict[int, dict[int, dict[str, np.ndarray]]] = {}
    for x in bags.read_messages(bag, ["/keypoints_2d", "/ground_truth/skeletons_3d"]):
        for sk in x.msg.skeletons:
            p = frames.setdefault(x.stamp_ns, {}).setdefault(int(sk.track_id), {})
            if x.topic == "/keypoints_2d":
                p["points_2d"], p["confidence"] = m.skeleton2d_to_arrays(sk, x.msg.layout)
            else:
                p["truth"] = m.skeleton3d_to_joints(sk)
                p["lifted"] = p["truth"] + 0.05
    picked = [{"stamp_ns": s, "people": [{"track_id": t, **p} for t, p in frames[s].items()]}
              for s in sorted(frames)[:2]]
    assert len(picked[0]["people"]) == 2
    out = tmp_path / "demo.png"
    plot_frames(picked, out, title="test")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


def test_the_node_s_parameters_and_the_lift_s_flags_are_one_table() -> None:
    """Every parameter the offline lift honours is a ``pose-lifter lift`` flag of the node's name
    (``--`` + the name with ``_`` -> ``-``), default and range; the live node's own are no flag;
    ``lift`` and ``demo`` take the same flags."""
    from pose_lifter.ros.params import OFFLINE_PARAMS, PARAMS

    commands = cli._build_parsers()[1]
    for command in ("lift", "demo"):
        actions = {a.dest: a for a in commands[command]._actions}
        for spec in OFFLINE_PARAMS:
            action = actions[spec.name]
            assert spec.flag in action.option_strings, (command, spec.name)
            assert action.default == spec.default and type(action.default) is type(spec.default), spec.name
            assert spec.description.replace("%", "%%") in (action.help or ""), spec.name
            if isinstance(spec.default, bool):
                assert "--no-" + spec.flag[2:] in action.option_strings, spec.name
        for spec in PARAMS:
            if spec.live_only:
                assert spec.name not in actions and spec.flag not in commands[command]._option_string_actions
    defaults = vars(cli.build_parser().parse_args(["lift", "in.mcap", "--out", "o.mcap"]))
    assert {p.name: defaults[p.name] for p in OFFLINE_PARAMS} == {p.name: p.default for p in OFFLINE_PARAMS}
    # the names the flags had before are gone: the node's names only
    for old in ("--starts", "--leg-length", "--lag", "--hri", "--bases"):
        assert old not in commands["lift"]._option_string_actions, old
    assert defaults["publish_hri"] is True and defaults["marker_lifetime"] == 1.0


def test_a_flag_out_of_the_node_s_range_or_of_another_mode_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = Path(__file__).resolve().parents[1] / "bags" / "walk_clean.mcap"
    out = tmp_path / "o.mcap"
    with pytest.raises(SystemExit) as exc:
        cli.main(["lift", str(bag), "--out", str(out), "--max-skeletons", "0"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --max-skeletons: max_skeletons must be an int in [1, 10000], got 0" in err
    # an option only the paper mode reads, with the hybrid mode: the core's reason, one line, exit 2
    assert cli.main(["lift", str(bag), "--out", str(out), "--n-starts", "5", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == ("pose-lifter lift: error: n_starts = 5 is read only in paper mode, not in 'hybrid' mode: "
                   "leave it at its default (30) or set mode to 'paper'\n")
    assert not out.exists()
