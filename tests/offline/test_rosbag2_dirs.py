"""Recordings as ``ros2 bag record`` writes them: a rosbag2 directory (``metadata.yaml`` and one
or more ``.mcap`` files, several when split) is one bag for ``lift``, ``evaluate``, ``export``,
``play`` and a collection; its split files are one stream in time order, so a lift of the
directory equals, message for message, the lift of the same messages in one ``.mcap`` file."""

from __future__ import annotations

import itertools
import json
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from lift_compare import assert_same_lift
from mcap_check import check_mcap
from pose_lifter import cli
from pose_lifter.messages import convert as m
from pose_lifter.offline import bags
from pose_lifter.offline.bags import BagError
from pose_lifter.offline.collection import MANIFEST_NAME, expand_inputs, plan_jobs

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
TWO = BAGS / "two_people.mcap"  # 75 frames of two tracks: /camera_info, /keypoints_2d, ground truth


# --------------------------------------------------------------------------- recordings


def raw_messages(path: Path) -> list[bags.RawMessage]:
    return list(bags.read_raw(path))


def write_recording(directory: Path, raws: Sequence[bags.RawMessage]) -> Path:
    """A rosbag2 directory (version 9, MCAP storage) of these messages, written by rosbags:
    ``metadata.yaml`` and ``<name>.mcap``."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(directory, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns: dict[str, Any] = {}
        for r in raws:
            if r.topic not in conns:
                conns[r.topic] = w.add_connection(r.topic, r.msgtype, msgdef=r.msgdef, rihs01=r.rihs01)
            w.write(conns[r.topic], r.stamp_ns, r.data)
    return directory


def _metadata(directory: Path) -> dict[str, Any]:
    from ruamel.yaml import YAML

    info: dict[str, Any] = YAML(typ="safe").load((directory / "metadata.yaml").read_text())
    return dict(info["rosbag2_bagfile_information"])


def write_split_recording(directory: Path, parts: Sequence[Sequence[bags.RawMessage]]) -> Path:
    """A split recording as ``ros2 bag record --max-bag-duration`` leaves it: ``<name>_0.mcap``,
    ``<name>_1.mcap``, ... in one directory and one ``metadata.yaml`` that lists them
    (``relative_file_paths``, a ``files`` entry per file with its start, duration and message
    count) and counts every topic over all of them. rosbags' writer cannot split: each part is
    written as a recording of its own, then the files are moved into one directory and their
    metadata merged."""
    from ruamel.yaml import YAML

    stage = directory.parent / f".{directory.name}-parts"
    directory.mkdir()
    infos = []
    for i, part in enumerate(parts):
        name = f"{directory.name}_{i}"
        write_recording(stage / name, part)
        infos.append(_metadata(stage / name))
        (stage / name / f"{name}.mcap").rename(directory / f"{name}.mcap")
    shutil.rmtree(stage)
    topics: dict[str, dict[str, Any]] = {}
    for info in infos:
        for t in info["topics_with_message_count"]:
            name = t["topic_metadata"]["name"]
            if name in topics:
                topics[name]["message_count"] += t["message_count"]
            else:
                topics[name] = {"topic_metadata": t["topic_metadata"], "message_count": t["message_count"]}
    files = [f for info in infos for f in info["files"]]
    start = min(f["starting_time"]["nanoseconds_since_epoch"] for f in files)
    end = max(f["starting_time"]["nanoseconds_since_epoch"] + f["duration"]["nanoseconds"] for f in files)
    merged = {
        "version": 9,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(f["message_count"] for f in files),
        "topics_with_message_count": list(topics.values()),
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f["path"] for f in files],
        "files": files,
        "custom_data": None,
        "ros_distro": "jazzy",
    }
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    with open(directory / "metadata.yaml", "w") as f:
        yaml.dump({"rosbag2_bagfile_information": merged}, f)
    return directory


def thirds(raws: Sequence[bags.RawMessage]) -> list[list[bags.RawMessage]]:
    """Three consecutive parts, cut inside a frame (messages of one stamp in two files), as a
    split by size cuts a recording."""
    n = len(raws)
    cuts = [0, n // 3 + 1, 2 * n // 3 + 2, n]
    assert raws[cuts[1] - 1].stamp_ns == raws[cuts[1]].stamp_ns  # a frame across two files
    return [list(raws[a:b]) for a, b in itertools.pairwise(cuts)]


def lift(*args: str) -> int:
    """``pose-lifter lift`` without the REP-155 outputs (the counts below are of the lift's own)."""
    return cli.main(["lift", *args, "--quiet", "--workers", "1", "--no-publish-hri"])


@pytest.fixture(scope="module")
def joined(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The committed bag lifted as one ``.mcap`` file: what every recording of its messages must give."""
    out = tmp_path_factory.mktemp("joined") / "joined.mcap"
    assert lift(str(TWO), "--out", str(out)) == 0
    return out


# --------------------------------------------------------------------------- one bag


def test_a_recording_directory_lifts_as_the_joined_bag(tmp_path: Path, joined: Path) -> None:
    raws = raw_messages(TWO)
    rec = write_recording(tmp_path / "rec", raws)
    assert sorted(p.name for p in rec.iterdir()) == ["metadata.yaml", "rec.mcap"]
    assert [(r.topic, r.stamp_ns, r.data) for r in bags.read_raw(rec)] == [
        (r.topic, r.stamp_ns, r.data) for r in raws]
    for given in (rec, rec / "metadata.yaml"):
        out = tmp_path / f"{given.name}.out.mcap"
        assert lift(str(given), "--out", str(out)) == 0
        assert check_mcap(out)["/skeletons_3d"] == 75
        assert assert_same_lift(out, joined) == 3 * 75 + 2 * 75
    assert sorted(p.name for p in rec.iterdir()) == ["metadata.yaml", "rec.mcap"]  # untouched


def test_a_split_recording_is_one_stream_and_its_tracks_continue_across_files(
        tmp_path: Path, joined: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raws = raw_messages(TWO)
    rec = write_split_recording(tmp_path / "rec", thirds(raws))
    meta = _metadata(rec)
    assert meta["relative_file_paths"] == ["rec_0.mcap", "rec_1.mcap", "rec_2.mcap"]
    assert [f["message_count"] for f in meta["files"]] == [76, 76, 73]
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == {
        "/camera_info": 75, "/keypoints_2d": 75, "/ground_truth/skeletons_3d": 75}
    assert [(r.topic, r.stamp_ns, r.data) for r in bags.read_raw(rec)] == [
        (r.topic, r.stamp_ns, r.data) for r in raws]
    for given in (rec, rec / "metadata.yaml"):
        out = tmp_path / f"{given.name}.out.mcap"
        capsys.readouterr()
        assert lift(str(given), "--out", str(out), "--workers", "2") == 0
        # one cold start per track in the whole recording: no track restarts at a file boundary
        text = capsys.readouterr().out
        assert "lifted 150 of 150 skeletons in 75 messages (148 warm-started, 0 failed)" in text
        assert check_mcap(out)["/skeletons_3d"] == 75
        assert assert_same_lift(out, joined) == 5 * 75
    answers = list(bags.read_messages(tmp_path / "rec.out.mcap", ["/skeletons_3d"]))
    keypoints = [r.stamp_ns for r in raws if r.topic == "/keypoints_2d"]
    assert [a.stamp_ns for a in answers] == keypoints
    assert [m.stamp_to_ns(a.msg.header.stamp) for a in answers] == keypoints
    warm = [[s.warm_started for s in a.msg.skeletons] for a in answers]
    assert warm == [[False, False]] + [[True, True]] * 74


def test_files_that_overlap_in_time_are_merged_by_stamp(tmp_path: Path, joined: Path) -> None:
    """A frame recorded into the earlier file (its stamp after the later file's first messages):
    the recording is still read, and lifted, in time order."""
    raws = raw_messages(TWO)
    stamps = sorted({r.stamp_ns for r in raws})
    late = stamps[40]
    first = [r for r in raws if r.stamp_ns < stamps[38] or r.stamp_ns == late]
    second = [r for r in raws if r.stamp_ns >= stamps[38] and r.stamp_ns != late]
    rec = write_split_recording(tmp_path / "rec", [first, second])
    assert [(r.topic, r.stamp_ns, r.data) for r in bags.read_raw(rec)] == [
        (r.topic, r.stamp_ns, r.data) for r in raws]
    assert [x.stamp_ns for x in bags.read_messages(rec, ["/keypoints_2d"])] == stamps
    out = tmp_path / "out.mcap"
    assert lift(str(rec), "--out", str(out)) == 0
    assert assert_same_lift(out, joined) == 5 * 75


def test_evaluate_export_and_play_take_a_recording_directory(tmp_path: Path, joined: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    lifted = raw_messages(joined)
    one = write_recording(tmp_path / "one", lifted)
    split = write_split_recording(tmp_path / "split", thirds(lifted))
    capsys.readouterr()
    assert cli.main(["evaluate", str(joined), "--json"]) == 0
    expected = json.loads(capsys.readouterr().out)
    assert expected["n_matched"] == 150
    for given in (one, split, split / "metadata.yaml"):
        assert cli.main(["evaluate", str(given), "--json"]) == 0
        assert json.loads(capsys.readouterr().out) == expected
    assert cli.main(["export", str(joined), "--out", str(tmp_path / "joined.csv")]) == 0
    for i, given in enumerate((one, split, split / "metadata.yaml")):
        assert cli.main(["export", str(given), "--out", str(tmp_path / f"{i}.csv")]) == 0
        assert (tmp_path / f"{i}.csv").read_bytes() == (tmp_path / "joined.csv").read_bytes()
    # the input recording: evaluate measures its floors
    rec = write_split_recording(tmp_path / "rec", thirds(raw_messages(TWO)))
    capsys.readouterr()
    assert cli.main(["evaluate", str(rec)]) == 0
    assert "matched 0 of 150 ground-truth skeletons" in capsys.readouterr().out
    # play reads the directory's topics (and stops here, before any ROS, on a topic it lacks)
    assert cli.main(["play", str(rec), "--topics", "/keypoints_2d", "/nope"]) == 2
    err = capsys.readouterr().err
    assert "has no topic(s) ['/nope']" in err and "'/keypoints_2d'" in err and err.count("\n") == 1


# --------------------------------------------------------------------------- collections


def campaign(tmp: Path) -> Path:
    """A bag at the top, a split recording beside it, a bag in a sub-directory."""
    src = tmp / "campaign"
    (src / "robot_b").mkdir(parents=True)
    shutil.copy(BAGS / "walk_clean.mcap", src / "walk.mcap")
    write_split_recording(src / "rec", thirds(raw_messages(TWO)))
    shutil.copy(BAGS / "punch_clean.mcap", src / "robot_b" / "punch.mcap")
    return src


def test_a_collection_takes_a_recording_directory_as_one_input(tmp_path: Path, joined: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    src = campaign(tmp_path)
    rec = (src / "rec").resolve()
    for inputs in ([str(src)], [str(src / "**" / "*.mcap")], [str(src / "walk.mcap"), str(rec),
                                                               str(src / "robot_b")]):
        files, _ = expand_inputs(inputs)
        assert rec in files and len(files) == 3, inputs
        assert not any(f.parent == rec for f in files)
    jobs = plan_jobs([str(src)], tmp_path / "out")
    assert sorted(j.rel for j in jobs) == ["rec.mcap", "robot_b/punch.mcap", "walk.mcap"]
    job = next(j for j in jobs if j.rel == "rec.mcap")
    assert job.input == str(rec)
    assert job.size == sum(f.stat().st_size for f in rec.iterdir()) and job.size > 3 * 20_000

    out = tmp_path / "out"
    assert cli.main(["lift", str(src), "--out", str(out), "--workers", "2", "--quiet",
                     "--no-publish-hri"]) == 0
    assert "3 bags: 3 lifted, 0 skipped" in capsys.readouterr().out
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.mcap")) == [
        "rec.mcap", "robot_b/punch.mcap", "walk.mcap"]
    assert assert_same_lift(out / "rec.mcap", joined) == 5 * 75
    entry = json.loads((out / MANIFEST_NAME).read_text())["bags"]["rec.mcap"]
    assert entry["status"] == "done" and entry["input"] == str(rec) and entry["poses"] == 150
    assert entry["input_sha256"] == bags.bag_sha256(rec) and entry["input_size"] == job.size
    before = (out / "rec.mcap").stat().st_mtime_ns

    # resumed: done; a file touched but unchanged (its digest) is still done
    (rec / "rec_1.mcap").touch()
    assert cli.main(["lift", str(src), "--out", str(out), "--quiet", "--no-publish-hri"]) == 0
    assert "3 bags: 0 lifted, 3 skipped" in capsys.readouterr().out
    # one file of the recording changed: the recording is lifted again, the others are not
    part = raw_messages(rec / "rec_2.mcap")
    (rec / "rec_2.mcap").unlink()
    write_recording(tmp_path / "again", part[:-3])
    (tmp_path / "again" / "again.mcap").rename(rec / "rec_2.mcap")
    assert cli.main(["lift", str(src), "--out", str(out), "--quiet", "--no-publish-hri"]) == 0
    assert "3 bags: 1 lifted, 2 skipped" in capsys.readouterr().out
    assert (out / "rec.mcap").stat().st_mtime_ns != before


def test_one_recording_lifts_into_a_file_or_a_directory(tmp_path: Path, joined: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    rec = write_split_recording(tmp_path / "rec", thirds(raw_messages(TWO)))
    assert lift(str(rec), "--out", str(tmp_path / "lifted.mcap")) == 0
    assert assert_same_lift(tmp_path / "lifted.mcap", joined) == 5 * 75
    # --out a directory: a collection of one, <name>.mcap in it
    assert lift(str(rec / "metadata.yaml"), "--out", str(tmp_path / "lifted")) == 0
    assert "1 bags: 1 lifted" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "lifted").glob("*.mcap")) == ["rec.mcap"]
    assert assert_same_lift(tmp_path / "lifted" / "rec.mcap", joined) == 5 * 75


def test_a_bag_and_a_recording_of_one_name_are_refused(tmp_path: Path) -> None:
    src = tmp_path / "src"
    write_recording(src / "walk", raw_messages(BAGS / "walk_clean.mcap"))
    shutil.copy(BAGS / "walk_clean.mcap", src / "walk.mcap")
    with pytest.raises(BagError, match="would both be lifted into"):
        plan_jobs([str(src)], tmp_path / "out")
    with pytest.raises(BagError, match="inside the recording"):
        plan_jobs([str(src / "walk")], src / "walk")


# --------------------------------------------------------------------------- errors


def _one_line(capsys: pytest.CaptureFixture[str], cmd: str = "lift") -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"pose-lifter {cmd}: error: "), err
    assert "Traceback" not in err
    return err


def test_a_damaged_recording_is_one_clear_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raws = raw_messages(TWO)
    out = tmp_path / "o.mcap"

    missing = write_split_recording(tmp_path / "missing", thirds(raws))
    (missing / "missing_1.mcap").unlink()
    assert lift(str(missing), "--out", str(out)) == 1
    err = _one_line(capsys)
    assert "cannot read" in err and "missing" in err and "missing_1.mcap" in err

    truncated = write_split_recording(tmp_path / "truncated", thirds(raws))
    data = (truncated / "truncated_2.mcap").read_bytes()
    (truncated / "truncated_2.mcap").write_bytes(data[: len(data) // 2])
    assert lift(str(truncated), "--out", str(out)) == 1
    assert "cannot read" in _one_line(capsys)

    garbled = write_recording(tmp_path / "garbled", raws)
    (garbled / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    assert lift(str(garbled / "metadata.yaml"), "--out", str(out)) == 1
    assert "cannot read" in _one_line(capsys)
    assert cli.main(["export", str(garbled), "--out", str(tmp_path / "e.csv")]) == 1
    assert "cannot read" in _one_line(capsys, "export")
    assert cli.main(["evaluate", str(garbled)]) == 1
    assert "cannot read" in _one_line(capsys, "evaluate")
    assert not out.exists() and not (tmp_path / "e.csv").exists()
    assert list(tmp_path.glob(".bagwriter-*")) == []

    # the output may not be written into the recording
    good = write_recording(tmp_path / "good", raws)
    assert lift(str(good), "--out", str(good / "lifted.mcap")) == 2
    assert "inside the input recording" in _one_line(capsys)
    assert cli.main(["lift", str(good), "--out", str(good / "good.mcap"), "--overwrite", "--quiet"]) == 2
    assert "inside the input recording" in _one_line(capsys)
    assert sorted(p.name for p in good.iterdir()) == ["good.mcap", "metadata.yaml"]

    # a directory without metadata.yaml is no recording: a collection for lift (as ever), an
    # error for a command that reads one bag
    plain = tmp_path / "plain"
    plain.mkdir()
    shutil.copy(TWO, plain / "two.mcap")
    assert lift(str(plain), "--out", str(out)) == 2
    assert "names a .mcap file" in _one_line(capsys)
    assert cli.main(["export", str(plain), "--out", str(tmp_path / "e.csv")]) == 2
    assert "not a rosbag2 recording" in _one_line(capsys, "export")


def test_a_damaged_recording_in_a_collection_is_reported_and_the_others_lifted(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = campaign(tmp_path)
    (src / "rec" / "rec_0.mcap").unlink()
    out = tmp_path / "out"
    assert cli.main(["lift", str(src), "--out", str(out), "--max-messages", "6", "--quiet"]) == 1
    text = capsys.readouterr().out
    assert "3 bags: 2 lifted, 0 skipped (done already), 1 failed" in text
    assert "cannot read" in text and "rec_0.mcap" in text
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.mcap")) == [
        "robot_b/punch.mcap", "walk.mcap"]
