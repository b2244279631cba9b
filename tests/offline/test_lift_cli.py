"""``pose-lifter lift`` on real-world-shaped bags: another topic name, yolo_ros input, kept
topics, the node's params file, bounded memory on a bag with a large image topic, and one clear
line (exit 2, no output file) for every bad input. Every MCAP written is checked with the
independent ``mcap`` reader (tests/mcap_check.py)."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from detector_poses import coco17, model_xy
from mcap_check import check_mcap
from params_cases import LIVE_ONLY_PARAMS, NON_DEFAULT_PARAMS
from pose_lifter import cli
from pose_lifter.messages import typestore
from pose_lifter.offline import bags

REPO = Path(__file__).resolve().parents[2]
WALK = REPO / "bags" / "walk_clean.mcap"
PARAMS = REPO / "ros2_ws" / "src" / "pose_lifter" / "config" / "lifter.yaml"
THIRD_PARTY = REPO / "tests" / "ros" / "msgs"


def renamed(src: Path, dst: Path, names: dict[str, str], extra: Any = None) -> Path:
    """A copy of a bag with topics renamed (bytes untouched); ``extra(writer, raw)`` may add more."""
    with bags.BagWriter(dst, compress=False) as w:
        for raw in bags.read_raw(src):
            w.write_raw(dataclasses.replace(raw, topic=names.get(raw.topic, raw.topic)))
            if extra is not None:
                extra(w, raw)
    return dst


def lift(*args: str) -> int:
    return cli.main(["lift", *args, "--quiet", "--workers", "1"])


def lift_checked(bag: Path, tmp_path: Path, *args: str) -> tuple[Path, Counter[str]]:
    """``bag`` lifted into ``tmp_path/out.mcap`` (more flags: ``args``), the exit status 0 and
    the MCAP checked: the output and its messages per topic."""
    out = tmp_path / "out.mcap"
    assert lift(str(bag), "--out", str(out), *args) == 0
    return out, check_mcap(out)


def test_lift_topic_camera_info_topic_and_keep(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = renamed(WALK, tmp_path / "in.mcap", {"/keypoints_2d": "/detector/pose",
                                                "/camera_info": "/cam/camera_info"})
    out, counts = lift_checked(bag, tmp_path, "--topic", "/detector/pose", "--camera-info-topic",
                               "/cam/camera_info", "--keep", "/cam/camera_info", "--max-messages", "10",
                               "--no-publish-hri")
    assert set(counts) == {"/cam/camera_info", "/skeletons_3d", "/skeleton_markers"}
    assert counts["/skeletons_3d"] == 10
    skels = [x.msg for x in bags.read_messages(out, ["/skeletons_3d"])]
    z = np.array([[p.z for p in s.joints] for a in skels for s in a.skeletons])
    assert np.all(np.abs(z.mean(axis=1) - 5.0) < 1.0)  # placed with the camera's focal length
    assert "lifted 10 of 10 skeletons" in capsys.readouterr().out
    # without --keep everything is copied (and the default camera_info topic does not exist here:
    # a note, the default distance)
    assert lift(str(bag), "--out", str(tmp_path / "all.mcap"), "--topic", "/detector/pose",
                "--max-messages", "3") == 0
    assert "has no /camera_info: depth at the default distance, 5 m" in capsys.readouterr().err
    assert {"/detector/pose", "/cam/camera_info", "/ground_truth/skeletons_3d"} <= set(
        check_mcap(tmp_path / "all.mcap"))


def test_lift_yolo_detection_array_bag(tmp_path: Path) -> None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    typestore.register_msg_package(store, "yolo_msgs", THIRD_PARTY / "yolo_msgs" / "msg")
    f = {n: typestore.message_factory(f"yolo_msgs/msg/{n}", store)
         for n in ("DetectionArray", "Detection", "KeyPoint2D", "KeyPoint2DArray", "Point2D")}
    header = typestore.message_factory("std_msgs/msg/Header", store)
    time = typestore.message_factory("builtin_interfaces/msg/Time", store)
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(tmp_path / "yolo", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/yolo/detections", "yolo_msgs/msg/DetectionArray", typestore=store)
        for i in range(5):
            kp, conf = coco17(model_xy(30.0 + 3 * i))
            data = [f["KeyPoint2D"](id=k + 1, point=f["Point2D"](x=float(x), y=float(y)), score=float(c))
                    for k, ((x, y), c) in enumerate(zip(kp, conf, strict=True))]
            msg = f["DetectionArray"](header=header(stamp=time(sec=1, nanosec=i * 10**8), frame_id="cam"),
                                      detections=[f["Detection"](class_name="person", id="7",
                                                                 keypoints=f["KeyPoint2DArray"](data=data))])
            w.write(conn, 10**9 + i * 10**8, store.serialize_cdr(msg, "yolo_msgs/msg/DetectionArray"))
    bag = next((tmp_path / "yolo").glob("*.mcap"))
    out, counts = lift_checked(bag, tmp_path, "--topic", "/yolo/detections")
    assert counts["/yolo/detections"] == 5 and counts["/skeletons_3d"] == 5
    answers = [x.msg for x in bags.read_messages(out, ["/skeletons_3d"])]
    assert [s.track_id for a in answers for s in a.skeletons] == [7] * 5
    assert sum(s.warm_started for a in answers for s in a.skeletons) == 4


def test_params_file_sets_the_node_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = PARAMS.read_text().replace("warm_start: true", "warm_start: false")
    (tmp_path / "p.yaml").write_text(text.replace("/**:\n", "pose_lifter:\n", 1))  # the node-name key
    out = tmp_path / "o.mcap"
    assert lift(str(WALK), "--out", str(out), "--params-file", str(tmp_path / "p.yaml"),
                "--max-messages", "4") == 0
    assert "(0 warm-started" in capsys.readouterr().out
    check_mcap(out)
    (tmp_path / "bad.yaml").write_text(text.replace("theta: 0.1", "theta: -1.0"))
    bad = str(tmp_path / "bad.yaml")
    assert lift(str(WALK), "--out", str(tmp_path / "b.mcap"), "--params-file", bad) == 2
    err = capsys.readouterr().err
    assert "theta" in err and "Traceback" not in err and not (tmp_path / "b.mcap").exists()


def bad_inputs(tmp: Path) -> list[tuple[list[str], str, int]]:
    """(arguments, expected text, exit code): 2 usage errors, 1 data errors (unreadable bags)."""
    (tmp / "truncated.mcap").write_bytes(WALK.read_bytes()[:5000])
    (tmp / "empty.mcap").write_bytes(b"")
    (tmp / "exists.mcap").write_bytes(b"x")
    (tmp / "adir.mcap").mkdir()
    (tmp / "noparams.yaml").write_text("other_node:\n  ros__parameters:\n    theta: 1.0\n")
    w, o = str(WALK), str(tmp / "o.mcap")
    return [
        ([str(tmp / "missing.mcap"), "--out", o], "bag not found", 2),
        ([str(tmp / "truncated.mcap"), "--out", o], "cannot read", 1),
        ([str(tmp / "empty.mcap"), "--out", o], "cannot read", 1),
        ([w, "--out", str(tmp / "o.bag")], "must end in .mcap", 2),
        ([w, "--out", str(tmp / "exists.mcap")], "exists already", 2),
        ([w, "--out", str(tmp / "adir.mcap")], "is a directory", 2),
        ([w, "--out", str(tmp / "nodir" / "o.mcap")], "does not exist", 2),
        ([w, "--out", o, "--topic", "/nope"], "has no topic '/nope'", 2),
        ([w, "--out", o, "--topic", "/ground_truth/skeletons_3d"], "lift takes", 2),
        ([w, "--out", o, "--camera-info-topic", "/keypoints_2d"], "not sensor_msgs/msg/CameraInfo", 2),
        ([w, "--out", o, "--camera-info-topic", "/cam/info"], "has no topic '/cam/info'", 2),
        ([w, "--out", o, "--keep", "/camera_info", "/images"], "to keep", 2),
        ([w, "--out", o, "--params-file", str(tmp / "none.yaml")], "cannot read params file", 2),
        ([w, "--out", o, "--params-file", str(tmp / "noparams.yaml")], "no /** / pose_lifter", 2),
    ]


def test_bad_inputs_one_line_exit_code_no_output(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for args, expected, code in bad_inputs(tmp_path):
        assert lift(*args) == code, args
        err = capsys.readouterr().err
        assert expected in err, (args, err)
        assert err.count("\n") == 1 and err.startswith("pose-lifter lift: error: "), err
        assert not (tmp_path / "o.mcap").exists() and not (tmp_path / "nodir").exists()
    assert (tmp_path / "exists.mcap").read_bytes() == b"x"


def test_camera_info_topic_named_must_exist_the_default_may_not(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A mistyped --camera-info-topic is an error as a mistyped --topic is; the default topic on a
    bag without camera_info lifts at the default distance with a note; '' means none, silently."""
    bag = tmp_path / "no_info.mcap"
    with bags.BagWriter(bag, compress=False) as w:
        for raw in bags.read_raw(WALK, ["/keypoints_2d"]):
            w.write_raw(raw)
    out = tmp_path / "o.mcap"
    for typed in ("/camera_info", "/camera/camera_info"):  # named, even as the default's name
        assert lift(str(bag), "--out", str(out), "--camera-info-topic", typed) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"pose-lifter lift: error: {bag} has no topic {typed!r}"), err
        assert err.count("\n") == 1
        assert not out.exists()
    assert lift(str(bag), "--out", str(out), "--max-messages", "2") == 0
    err = capsys.readouterr().err
    assert err == (f"pose-lifter lift: note: {bag} has no /camera_info: depth at the default distance, 5 m "
                   "(--camera-info-topic names another topic)\n")
    assert lift(str(bag), "--out", str(tmp_path / "none.mcap"), "--max-messages", "2",
                "--camera-info-topic", "") == 0
    assert capsys.readouterr().err == ""
    skels = [x.msg for x in bags.read_messages(out, ["/skeletons_3d"])]
    z = np.array([[p.z for p in s.joints] for a in skels for s in a.skeletons])
    assert np.allclose(z.mean(axis=1), 5.0)  # the centroid at the default distance


@pytest.mark.parametrize("workers", ["1", "2"])
def test_the_progress_bar_counts_each_skeleton_once(workers: str, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str],
                                                    tmp_path: Path) -> None:
    """Two tracks lifted in one group (one worker) or two (two workers): the bar's total and its
    final count are the skeletons lifted."""
    import tqdm

    bars: list[Recorder] = []

    class Recorder:
        def __init__(self, *args: Any, total: int | None = None, **kwargs: Any) -> None:
            self.total, self.n = total, 0
            bars.append(self)

        def update(self, n: int = 1) -> None:
            self.n += n

        def close(self) -> None:
            pass

    monkeypatch.setattr(tqdm, "tqdm", Recorder)
    assert cli.main(["lift", str(REPO / "bags" / "two_people.mcap"), "--out", str(tmp_path / "o.mcap"),
                     "--max-messages", "10", "--workers", workers]) == 0
    assert "lifted 20 of 20 skeletons" in capsys.readouterr().out
    assert [(b.total, b.n) for b in bars] == [(20, 20)]


def test_a_typed_flag_wins_over_the_params_file_even_at_its_default(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The file sets 5 starts, paper mode and a 0.40 m leg; flags typed with the parser's defaults
    (30, paper, 0.43) still win; flags not typed leave the file's values; a typed flag that leaves
    the file's paper option in another mode is refused with the reason."""
    text = PARAMS.read_text()
    for old, new in (("n_starts: 30", "n_starts: 5"), ('mode: "hybrid"', 'mode: "paper"'),
                     ("lower_leg_length: 0.43", "lower_leg_length: 0.40")):
        assert old in text
        text = text.replace(old, new)
    (tmp_path / "p.yaml").write_text(text)
    from pose_lifter.offline import flags

    made: list[Any] = []
    real = flags.lift_settings

    def recorded(args: Any, params: Any) -> Any:
        made.append(real(args, params))
        return made[-1]

    monkeypatch.setattr(flags, "lift_settings", recorded)
    base = [str(WALK), "--params-file", str(tmp_path / "p.yaml"), "--max-messages", "1"]
    assert lift(*base, "--out", str(tmp_path / "a.mcap")) == 0
    assert lift(*base, "--out", str(tmp_path / "b.mcap"), "--n-starts", "30", "--mode", "hybrid",
                "--lower-leg-length", "0.43") == 0
    assert lift(*base, "--out=" + str(tmp_path / "c.mcap"), "--n-start=30") == 0  # an abbreviation
    got = [(s.options.n_starts, s.options.mode, s.frame.lower_leg_length) for s in made]
    assert got == [(5, "paper", 0.40), (30, "hybrid", 0.43), (30, "paper", 0.40)]
    assert lift(*base, "--out", str(tmp_path / "d.mcap"), "--mode", "hybrid") == 2
    assert not (tmp_path / "d.mcap").exists()


def test_play_waits_by_default() -> None:
    from pose_lifter.ros.play import DEFAULT_WAIT_S, lifter_topics

    assert cli.build_parser().parse_args(["play", "x.mcap"]).wait == DEFAULT_WAIT_S > 0
    assert lifter_topics(bags.bag_topics(WALK)) == ["/camera_info", "/keypoints_2d"]  # not the ground truth


@pytest.mark.slow
def test_streaming_memory_does_not_grow_with_a_large_image_topic(tmp_path: Path) -> None:
    image = typestore.message_factory("sensor_msgs/msg/Image")
    pixels = np.frombuffer(np.random.default_rng(0).bytes(640 * 480 * 3), dtype=np.uint8)

    def add_image(w: bags.BagWriter, raw: bags.RawMessage) -> None:
        if raw.topic == "/keypoints_2d":
            w.write("/camera/image_raw", raw.stamp_ns, image(height=480, width=640, encoding="rgb8",
                                                             step=1920, data=pixels), "sensor_msgs/msg/Image")

    big = renamed(WALK, tmp_path / "big.mcap", {}, add_image)
    assert big.stat().st_size > 100e6  # 120 images of 0.9 MB

    def peak_rss_mb(bag: Path, out: Path, *extra: str) -> float:
        code = ("import resource, sys; from pose_lifter import cli; "
                f"rc = cli.main(['lift', {str(bag)!r}, '--out', {str(out)!r}, '--quiet', '--workers', '1', "
                f"*{list(extra)!r}]); "
                "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024); sys.exit(rc)")
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        return float(done.stdout.strip().splitlines()[-1])

    small = peak_rss_mb(WALK, tmp_path / "small_out.mcap")
    kept = peak_rss_mb(big, tmp_path / "big_out.mcap")
    dropped = peak_rss_mb(big, tmp_path / "big_none.mcap", "--keep", "none")
    print(f"peak RSS: small bag {small:.0f} MB, 110 MB image bag kept {kept:.0f} MB, "
          f"dropped {dropped:.0f} MB")
    assert kept - small < 30.0 and dropped - small < 15.0
    assert check_mcap(tmp_path / "big_out.mcap")["/camera/image_raw"] == 120
    assert "/camera/image_raw" not in check_mcap(tmp_path / "big_none.mcap")


def test_export_csv_npz_json_agree_with_the_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import csv
    import json

    from pose_lifter.messages import convert as m

    lifted = tmp_path / "l.mcap"
    # punch_outliers has missing joints (observed False); two_people has two tracks
    assert lift(str(REPO / "bags" / "punch_outliers.mcap"), "--out", str(tmp_path / "p.mcap"),
                "--max-messages", "3", "--keep", "none") == 0
    assert lift(str(REPO / "bags" / "two_people.mcap"), "--out", str(lifted), "--max-messages", "3",
                "--keep", "none") == 0
    truth = [(m.stamp_to_ns(a.header.stamp), s.track_id, m.skeleton3d_to_joints(s), list(s.observed))
             for a in (x.msg for x in bags.read_messages(lifted, ["/skeletons_3d"])) for s in a.skeletons]
    assert len(truth) == 6
    for fmt in ("csv", "npz", "json"):
        assert cli.main(["export", str(lifted), "--out", str(tmp_path / f"e.{fmt}")]) == 0
        mask = os.umask(0)
        os.umask(mask)
        assert (tmp_path / f"e.{fmt}").stat().st_mode & 0o777 == 0o666 & ~mask  # a new file's mode
    data = np.load(tmp_path / "e.npz", allow_pickle=False)
    assert data["joints"].shape == (6, 12, 3) and str(data["joint_names"][0]) == "left_shoulder"
    assert data["observed"].shape == (6, 12) and data["observed"].dtype == bool
    with open(tmp_path / "e.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    # units in the column names (a pandas user reads them with the data)
    assert reader.fieldnames == ["stamp_ns", "frame_id", "track_id", "joint", "x_m", "y_m", "z_m", "observed",
                                 "reprojection_error_px", "warm_started", "std_x_m", "std_y_m", "std_z_m"]
    document = json.loads((tmp_path / "e.json").read_text())
    assert document["units"]["joints"].startswith("metres")
    from_json = [(fr["stamp_ns"], s["track_id"], np.array(s["joints"]), s["observed"])
                 for fr in document["frames"] for s in fr["skeletons"]]
    assert len(rows) == 6 * 12
    for i, (stamp, tid, joints, observed) in enumerate(truth):
        assert len(observed) == 12
        assert data["stamp_ns"][i] == stamp and data["track_id"][i] == tid
        np.testing.assert_array_equal(data["joints"][i], joints)
        assert data["observed"][i].tolist() == observed
        assert from_json[i][:2] == (stamp, tid) and from_json[i][3] == observed
        np.testing.assert_array_equal(from_json[i][2], joints)
        block = rows[12 * i:12 * i + 12]
        xyz = [[float(r["x_m"]), float(r["y_m"]), float(r["z_m"])] for r in block]
        np.testing.assert_array_equal(np.array(xyz), joints)
        assert [r["observed"] for r in block] == [str(int(v)) for v in observed]
        assert int(rows[12 * i]["stamp_ns"]) == stamp and int(rows[12 * i]["track_id"]) == tid
    # a joint the 2D did not show is exported as not observed, alike in the three formats
    flags = [list(s.observed) for x in bags.read_messages(tmp_path / "p.mcap", ["/skeletons_3d"])
             for s in x.msg.skeletons]
    assert not all(all(f) for f in flags)
    for fmt in ("csv", "npz", "json"):
        assert cli.main(["export", str(tmp_path / "p.mcap"), "--out", str(tmp_path / f"p.{fmt}")]) == 0
    with open(tmp_path / "p.csv", newline="") as f:
        assert [r["observed"] == "1" for r in csv.DictReader(f)] == [v for f in flags for v in f]
    assert np.load(tmp_path / "p.npz")["observed"].tolist() == flags
    assert [s["observed"] for fr in json.loads((tmp_path / "p.json").read_text())["frames"]
            for s in fr["skeletons"]] == flags
    # ground truth carries no flags: an empty cell, null, False
    gt = REPO / "bags" / "two_people.mcap"
    for fmt in ("csv", "npz", "json"):
        assert cli.main(["export", str(gt), "--topic", "/ground_truth/skeletons_3d",
                         "--out", str(tmp_path / f"gt.{fmt}")]) == 0
    with open(tmp_path / "gt.csv", newline="") as f:
        assert {r["observed"] for r in csv.DictReader(f)} == {""}
    assert not np.load(tmp_path / "gt.npz")["observed"].any()
    assert {str(s["observed"]) for fr in json.loads((tmp_path / "gt.json").read_text())["frames"]
            for s in fr["skeletons"]} == {"None"}
    capsys.readouterr()
    for args, expected in [
        ([str(lifted), "--out", str(tmp_path / "e.txt")], "must end in .csv or .npz or .json"),
        ([str(lifted), "--out", str(tmp_path / "e.csv")], "exists already"),
        ([str(WALK), "--out", str(tmp_path / "w.csv")], "has no topic '/skeletons_3d'"),
        ([str(WALK), "--out", str(tmp_path / "w.csv"), "--topic", "/keypoints_2d"], "not pose_lifter_msgs"),
        ([str(tmp_path / "nope.mcap"), "--out", str(tmp_path / "w.csv")], "bag not found"),
    ]:
        assert cli.main(["export", *args]) == 2
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1, err
        assert not (tmp_path / "w.csv").exists()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # no temp files


def test_play_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for args, expected in [([str(WALK), "--topics", "/nope"], "has no topic(s) ['/nope']"),
                           ([str(WALK), "--rate", "0"], "rate must be > 0"),
                           ([str(tmp_path / "x.mcap")], "bag not found")]:
        assert cli.main(["play", *args]) == 2
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1, err


def test_lift_upgrades_an_older_skeleton3d_definition(tmp_path: Path) -> None:
    """A bag written before Skeleton3D had ``observed`` / ``joint_weights``: its kept ground truth
    is rebuilt in today's definition (one layout per type in the output, readable by both readers)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    old = get_typestore(Stores.ROS2_JAZZY)
    texts = {n: (typestore.msg_dir() / f"{n}.msg").read_text() for n in typestore.MSG_NAMES}
    texts["Skeleton3D"] = texts["Skeleton3D"].split("\n# Per joint (order of joint_names)")[0] + "\n"
    assert "observed" not in texts["Skeleton3D"]
    types: dict[str, Any] = {}
    for n, text in texts.items():
        types.update(get_types_from_msg(text, f"pose_lifter_msgs/msg/{n}"))
    old.register(types)
    gt = [x for x in bags.read_raw(WALK) if x.topic == "/ground_truth/skeletons_3d"][:3]
    msgs = [typestore.pose_lifter_typestore().deserialize_cdr(x.data, x.msgtype) for x in gt]
    with Writer(tmp_path / "old", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for x in bags.read_raw(WALK):
            if x.topic == "/ground_truth/skeletons_3d":
                continue
            if x.topic not in conns:
                conns[x.topic] = w.add_connection(x.topic, x.msgtype, msgdef=x.msgdef, rihs01=x.rihs01)
            w.write(conns[x.topic], x.stamp_ns, x.data)
        c = w.add_connection("/ground_truth/skeletons_3d", "pose_lifter_msgs/msg/Skeleton3DArray",
                             typestore=old)
        for x, msg in zip(gt, msgs, strict=True):
            upgraded = typestore.upgrade_message(msg, x.msgtype, old)
            w.write(c, x.stamp_ns, old.serialize_cdr(upgraded, x.msgtype))
    bag = next((tmp_path / "old").glob("*.mcap"))
    out, counts = lift_checked(bag, tmp_path, "--max-messages", "3")
    assert counts["/ground_truth/skeletons_3d"] == 3 and counts["/skeletons_3d"] == 3
    back = [x.msg for x in bags.read_messages(out, ["/ground_truth/skeletons_3d"])]
    for a, b in zip(back, msgs, strict=True):
        assert len(a.skeletons[0].observed) == 0
        np.testing.assert_array_equal([[p.x, p.y, p.z] for p in a.skeletons[0].joints],
                                      [[p.x, p.y, p.z] for p in b.skeletons[0].joints])


def test_the_command_line_answers_a_bare_call_a_version_request_and_a_closed_reader(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bare `pose-lifter` prints its help (exit 0); `--version` the package's version;
    `evaluate` of a bag without estimates says it measured the floors only; a reader that goes away
    (`pose-lifter evaluate X | head -1`) ends the command quietly, as SIGPIPE would (141)."""
    assert cli.main([]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: pose-lifter") and "evaluate" in out
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("pose-lifter ")
    bag = str(REPO / "bags" / "walk_clean.mcap")
    assert cli.main(["evaluate", bag]) == 0
    assert "only the floors" in capsys.readouterr().err
    lifted = tmp_path / "l.mcap"
    assert lift(bag, "--out", str(lifted), "--max-messages", "2") == 0
    proc = subprocess.Popen([sys.executable, "-m", "pose_lifter.cli", "evaluate", str(lifted), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader is gone before the command writes
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 141 and "Broken pipe" not in err and "Traceback" not in err, err


def test_lift_hri_writes_the_node_s_rep155_bodies_and_tf(tmp_path: Path) -> None:
    """``lift`` (``--publish-hri``, on by default as the node's ``publish_hri``): per keypoint
    message the node's REP-155 outputs (tracked, each body's joint_states / skeleton2d / roi, /tf),
    each body's URDF once; the TF joint links land on /skeletons_3d's joints; with
    ``--no-publish-hri`` none of it."""
    from pose_lifter.core.model.skeleton import JOINT_NAMES
    from pose_lifter.messages import body, hri
    from pose_lifter.messages.convert import skeleton3d_to_joints
    from scipy.spatial.transform import Rotation

    src = REPO / "bags" / "two_people.mcap"
    out = tmp_path / "hri.mcap"
    assert lift(str(src), "--out", str(out), "--max-messages", "6") == 0
    check_mcap(out)
    msgs = list(bags.read_messages(out))
    skeletons = [x for x in msgs if x.topic == "/skeletons_3d"]
    tracked = [x for x in msgs if x.topic == "/humans/bodies/tracked"]
    tfs = [x for x in msgs if x.topic == "/tf"]
    assert len(skeletons) == len(tracked) == len(tfs) == 6
    ids = {int(s.track_id): hri.body_id(int(s.track_id)) for s in skeletons[0].msg.skeletons}
    assert sorted(tracked[-1].msg.ids) == sorted(ids.values())
    for bid in ids.values():
        assert len([x for x in msgs if x.topic == f"/humans/bodies/{bid}/urdf"]) == 1
        for kind in ("joint_states", "skeleton2d", "roi"):
            assert len([x for x in msgs if x.topic == f"/humans/bodies/{bid}/{kind}"]) == 6
    links = body.joint_link_names()
    for sk, tf in zip(skeletons, tfs, strict=True):
        edges = {t.child_frame_id: t for t in tf.msg.transforms}
        for s in sk.msg.skeletons:
            bid = ids[int(s.track_id)]

            def pose(name: str, edges: dict[str, Any] = edges,
                     root: str = sk.msg.header.frame_id) -> np.ndarray:
                if name not in edges:
                    assert name == root
                    return np.eye(4)
                t = edges[name]
                local = np.eye(4)
                q = t.transform.rotation
                local[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
                v = t.transform.translation
                local[:3, 3] = [v.x, v.y, v.z]
                return pose(t.header.frame_id, edges, root) @ local

            got = np.array([pose(f"{links[n]}_{bid}")[:3, 3] for n in JOINT_NAMES])
            np.testing.assert_allclose(got, skeleton3d_to_joints(s), atol=1e-9)
    plain = tmp_path / "plain.mcap"
    assert lift(str(src), "--out", str(plain), "--max-messages", "2", "--no-publish-hri") == 0
    assert not [t for t in bags.bag_topics(plain) if t.startswith("/humans") or t == "/tf"]


def test_a_params_file_of_non_default_values_reaches_the_offline_lift(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The node's file, read offline: every value it sets is used (the caps too); a parameter of
    the live node only at another value than its default is an error naming it, and so is an
    option of the paper mode with the hybrid mode."""
    import yaml
    from pose_lifter.ros.params import SPECS, read_params_file

    for name, value in {**NON_DEFAULT_PARAMS, **LIVE_ONLY_PARAMS}.items():
        assert value != SPECS[name].default and type(value) is type(SPECS[name].default), name
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({"pose_lifter": {"ros__parameters": NON_DEFAULT_PARAMS}}))
    assert read_params_file(path) == NON_DEFAULT_PARAMS
    out = tmp_path / "out.mcap"
    assert lift(str(WALK), "--out", str(out), "--params-file", str(path), "--max-messages", "4") == 0
    skeletons = [s for x in bags.read_messages(out, ["/skeletons_3d"]) for s in x.msg.skeletons]
    assert len(skeletons) == 4 and not any(s.warm_started for s in skeletons)
    assert "/skeleton_markers" not in bags.bag_topics(out)  # publish_markers: false
    from pose_lifter.messages.convert import skeleton3d_to_joints

    shins = [np.linalg.norm(np.subtract(*skeleton3d_to_joints(s)[[10, 11]])) for s in skeletons]
    np.testing.assert_allclose(shins, 0.41, rtol=0.01)  # the metric scale is the file's
    # a cap the file sets is the offline lift's (it was dropped before): 17 keypoints > 10
    capped = tmp_path / "capped.yaml"
    capped.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"max_keypoints": 10}}}))
    assert lift(str(WALK), "--out", str(tmp_path / "capped.mcap"), "--params-file", str(capped),
                "--max-messages", "2") == 0
    assert "lifted 0 of 2 skeletons" in capsys.readouterr().out
    for name, value in LIVE_ONLY_PARAMS.items():
        bad = tmp_path / f"{name}.yaml"
        bad.write_text(yaml.safe_dump({"/**": {"ros__parameters": {**NON_DEFAULT_PARAMS, name: value}}}))
        assert lift(str(WALK), "--out", str(tmp_path / "no.mcap"), "--params-file", str(bad)) == 2
        err = capsys.readouterr().err
        assert err.startswith("pose-lifter lift: error: params file") and err.count("\n") == 1, err
        assert f"{name} = {value!r} cannot be honoured offline" in err
    hybrid = tmp_path / "hybrid.yaml"
    hybrid.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"n_starts": 3}}}))
    assert lift(str(WALK), "--out", str(tmp_path / "no.mcap"), "--params-file", str(hybrid)) == 2
    assert "n_starts = 3 is read only in paper mode, not in 'hybrid' mode" in capsys.readouterr().err
    assert not (tmp_path / "no.mcap").exists()


def test_the_lift_imports_none_of_the_references_scipy() -> None:
    """scipy's optimisers and rotations serve the reference solvers only (and ``scipy.linalg``
    the lifted ADMM on large bases): importing the lift and the node's core must not load them
    (~0.2 s of every ``pose-lifter lift`` and node start-up)."""
    code = ("import sys, pose_lifter.offline.lift, pose_lifter.offline.settings, pose_lifter.core.reference; "
            "print(sorted(m for m in ('scipy.optimize', 'scipy.spatial', 'scipy.linalg') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
