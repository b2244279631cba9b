"""An MCAP input read and copied through its index (pose_lifter.offline.mcap_index and
pose_lifter.offline.chunk_copy): the lift's output with the input's chunks copied as they are holds
the same messages in the same order as the message-by-message write, read back by rosbags, by the
``mcap`` package and by ``read_raw``; a topic read by number, or in order with only its headers,
gives the stream's messages; inputs that cannot be copied so (a rosbag2 directory, our own types in
an older layout, a cut or a topic left out) take the message-by-message path."""

from __future__ import annotations

import multiprocessing
import shutil
from collections import Counter
from contextlib import closing
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap_check import check_mcap
from pose_lifter.core import Lifter
from pose_lifter.messages import typestore
from pose_lifter.messages.convert import stamp_to_ns
from pose_lifter.messages.names import IMAGE, TOPIC_DEPTH, TOPIC_KEYPOINTS
from pose_lifter.offline import bags, chunk_copy, lift, mcap_index
from pose_lifter.offline.bags import BagError
from pose_lifter.offline.depth import HEADER_BYTES, header_stamp, pair_depth
from pose_lifter.offline.first_pass import FirstPassPlan, read_ahead, read_first_pass
from pose_lifter.offline.settings import LiftSettings

REPO = Path(__file__).resolve().parents[2]
WALK = REPO / "bags" / "walk_clean.mcap"
N = 10  # keypoints messages, each with a 640 x 480 depth image: two images a chunk, five chunks
#: walk_clean's ground truth is an older Skeleton3D (read_raw upgrades it): not in the bags made here
OLD_LAYOUT = "/ground_truth/skeletons_3d"
DEPTH_INFO = "/camera/aligned_depth_to_color/camera_info"


def _depth_image(stamp_ns: int, mm: int) -> Any:
    msg = typestore.message_factory(IMAGE)(height=480, width=640, encoding="16UC1", step=1280,
                                          data=np.full(480 * 640, mm, dtype="<u2").view(np.uint8))
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return msg


def rgbd_bag(path: Path, tracks: int = 1) -> Path:
    """walk_clean's first N frames (zstd chunks), each with a depth image (a wall at 4.5 m) of its
    keypoints' header stamp and the depth camera's camera_info, recorded at the keypoints' bag
    stamp right after them: the lift's answers share that log time with input messages read
    after the keypoints, in the keypoints' chunk and (the camera_info after a chunk's second image)
    in the next chunk. ``tracks``: the walker's frames cut into that many tracks, one after another."""
    store = typestore.pose_lifter_typestore()
    with bags.BagWriter(path) as w:
        n = 0
        info: bags.RawMessage | None = None
        for raw in bags.read_raw(WALK):
            if raw.topic == OLD_LAYOUT:
                continue
            info = raw if raw.topic == "/camera_info" else info
            if raw.topic != TOPIC_KEYPOINTS:
                w.write_raw(raw)
                continue
            assert info is not None
            msg = store.deserialize_cdr(raw.data, raw.msgtype)
            for sk in msg.skeletons:
                sk.track_id = n * tracks // N
            w.write(raw.topic, raw.stamp_ns, msg, raw.msgtype)
            w.write(TOPIC_DEPTH, raw.stamp_ns, _depth_image(stamp_to_ns(msg.header.stamp), 4500 + n), IMAGE)
            w.write_raw(replace(info, topic=DEPTH_INFO, stamp_ns=raw.stamp_ns))
            n += 1
            if n == N:
                break
    return path


def _raw(path: Path) -> list[bags.RawMessage]:
    return list(bags.read_raw(path))


def _lift_both_ways(bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, **settings: Any
                    ) -> tuple[Path, Path]:
    """The bag lifted once; its answers written through ``lift._write_lifted`` as it chooses and
    message by message (the chunk copy turned off): the two outputs."""
    calls: list[tuple[Any, ...]] = []
    write = lift._write_lifted

    def spy(*args: Any) -> None:
        calls.append(args)
        write(*args[:5], dict(args[5]), *args[6:])

    monkeypatch.setattr(lift, "_write_lifted", spy)
    fast, slow = tmp_path / "fast.mcap", tmp_path / "slow.mcap"
    lift.lift_bag(bag, fast, Lifter(), LiftSettings(**settings), progress=False)
    (args,) = calls
    monkeypatch.setattr(lift, "chunked_mcap", lambda _: None)
    write(args[0], slow, *args[2:])
    return fast, slow


def test_the_chunk_copy_writes_what_the_message_by_message_path_writes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap")
    monkeypatch.setattr(chunk_copy, "NEW_CHUNK_BYTES", 3000)  # the answers' chunks between the copied ones
    source = mcap_index.chunked_mcap(bag)
    assert source is not None and len(source.chunks) >= 4
    starts = {c.message_start_time for c in source.chunks}
    assert any(c.message_end_time in starts for c in source.chunks)  # a log time in two chunks
    fast, slow = _lift_both_ways(bag, tmp_path, monkeypatch)
    copied = mcap_index.chunked_mcap(fast)
    assert copied is not None and len(copied.chunks) > len(source.chunks) + 2
    last_copied = max(d.chunk_start_offset for d in copied.chunks if d.chunk_length in
                      {c.chunk_length for c in source.chunks})
    assert any(d.chunk_start_offset < last_copied for d in copied.chunks if d.chunk_length not in
               {c.chunk_length for c in source.chunks})
    # every input chunk is in the output byte for byte (not decompressed and compressed again)
    with bag.open("rb") as a, fast.open("rb") as b:
        for c in source.chunks:
            a.seek(c.chunk_start_offset)
            data = a.read(c.chunk_length)
            assert sum(1 for d in copied.chunks if d.chunk_length == c.chunk_length
                       and b.seek(d.chunk_start_offset) >= 0 and b.read(d.chunk_length) == data) == 1
    out, ref = _raw(fast), _raw(slow)
    assert out == ref  # topic, type, stamp, bytes, definition: in the same order
    inputs = _raw(bag)
    kept = {x.topic for x in inputs}
    assert [x for x in out if x.topic in kept] == inputs
    stamps = [x.stamp_ns for x in out]
    assert stamps == sorted(stamps)
    for t in set(stamps):  # the answers after every input message of their log time
        topics = [x.topic in kept for x in out if x.stamp_ns == t]
        assert topics == sorted(topics, reverse=True) and topics.count(False) >= 2
    # the mcap package reads the same messages in the same order, every chunk's CRC checked,
    # and the summary's and rosbag2's counts are the output's
    from mcap.reader import make_reader

    with fast.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        read = [(c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages(log_time_order=True)]
        summary = reader.get_summary()
        meta = next(iter(reader.iter_metadata())).metadata
    assert read == [(x.topic, x.stamp_ns, x.data) for x in out]
    monkeypatch.setattr(bags, "_chunked", lambda *_: None)  # rosbags' own reader: the same
    assert _raw(fast) == out
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(out)
    counts = Counter(x.topic for x in out)
    assert check_mcap(fast) == counts
    info = yaml.safe_load(meta["serialized_metadata"])
    assert info["message_count"] == len(out)
    assert {t["topic_metadata"]["name"]: t["message_count"]
            for t in info["topics_with_message_count"]} == counts
    assert info["starting_time"]["nanoseconds_since_epoch"] == stamps[0]
    assert info["duration"]["nanoseconds"] == stamps[-1] - stamps[0]


def test_inputs_that_cannot_be_copied_as_they_are_are_written_message_by_message(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Our own type in an older layout (upgraded when read), a topic left out or a cut: the
    message-by-message path, with the answers after every input message of their log time."""
    copies: list[bool] = []
    copy_with = chunk_copy.copy_with

    def spy(*args: Any, **kw: Any) -> bool:
        copies.append(copy_with(*args, **kw))
        return copies[-1]

    monkeypatch.setattr(lift, "copy_with", spy)
    out = tmp_path / "out.mcap"
    lift.lift_bag(WALK, out, Lifter(), LiftSettings(max_messages=None), progress=False)
    assert copies == [False]
    schemas = {x.msgtype: x.msgdef for x in _raw(out)}
    assert "joint_std" in schemas["pose_lifter_msgs/msg/Skeleton3DArray"]  # upgraded, one layout
    bag = rgbd_bag(tmp_path / "new.mcap")
    for settings in ({"keep": [TOPIC_KEYPOINTS, "/camera_info"]}, {"max_messages": N - 2}):
        lift.lift_bag(bag, out, Lifter(), LiftSettings(**settings), progress=False, overwrite=True)
        got = _raw(out)
        assert (TOPIC_DEPTH in {x.topic for x in got}) == ("keep" not in settings)
        stamps = [x.stamp_ns for x in got]
        assert stamps == sorted(stamps) and sum(x.topic == "/skeletons_3d" for x in got) == N - (
            2 if "max_messages" in settings else 0)
    assert copies == [False]  # neither was offered to the copy


def test_a_rosbag2_directory_or_a_sqlite_bag_is_not_read_through_an_mcap_index(tmp_path: Path) -> None:
    (tmp_path / "rec").mkdir()
    bag = rgbd_bag(tmp_path / "rec" / "rec.mcap")
    assert mcap_index.chunked_mcap(bag) is not None
    (tmp_path / "rec" / bags.METADATA_NAME).write_text("rosbag2_bagfile_information: {}\n")
    assert mcap_index.chunked_mcap(tmp_path / "rec") is None
    db3 = tmp_path / "x.db3"
    shutil.copy(bag, db3)
    assert mcap_index.chunked_mcap(db3) is None
    truncated = tmp_path / "cut.mcap"
    truncated.write_bytes(bag.read_bytes()[:-100])
    assert mcap_index.chunked_mcap(truncated) is None


def test_a_topic_read_by_number_is_the_stream(tmp_path: Path) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap")
    mcap = mcap_index.chunked_mcap(bag)
    assert mcap is not None
    positions = mcap.positions(mcap.channel_ids([TOPIC_DEPTH]))
    stream = [x for x in _raw(bag) if x.topic == TOPIC_DEPTH]
    assert [t for t, _, _ in positions] == [x.stamp_ns for x in stream]
    with closing(mcap_index.IndexedMessages(mcap, positions)) as read:
        for k in reversed(range(len(stream))):  # any order
            assert bytes(read.data(k)) == stream[k].data
        assert read.n_decompressed == len({c for _, c, _ in positions})


def test_the_depth_stamps_read_with_the_keypoints_pair_as_a_pass_of_their_own(tmp_path: Path) -> None:
    bag = rgbd_bag(tmp_path / "rgbd.mcap")
    kp = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, [TOPIC_KEYPOINTS])]
    frames = [stamp_to_ns(msg.header.stamp) + 5_000_000 * (k % 2) for k, (_, msg) in enumerate(kp)]
    read = header_stamp
    stamps = [(x.stamp_ns, read(x.data).stamp_ns) for x in bags.read_raw(bag, [TOPIC_DEPTH])]
    sizes = [(640.0, 480.0)] * len(kp)
    alone = pair_depth(bag, TOPIC_DEPTH, IMAGE, frames, sizes, 0.003)
    given = pair_depth(bag, TOPIC_DEPTH, IMAGE, frames, sizes, 0.003, stamps)
    assert alone.located is not None and given.located is not None
    assert replace(given, located=None) == replace(alone, located=None)
    assert given.located[1] == alone.located[1]
    assert alone.paired == (len(kp) + 1) // 2 and sum(alone.unpaired.values()) == len(kp) // 2
    assert read(b"\x00\x01").stamp_ns == -1  # not even a header: never a partner
    # the keypoints pass reads the same stamps, of every image even when the keypoints are cut,
    # from each image's first bytes alone
    for cut in (None, 3):
        plan = FirstPassPlan(TOPIC_KEYPOINTS, "/camera_info", cut, (TOPIC_DEPTH, IMAGE))
        first = read_first_pass(bag, plan)
        assert first.depth_stamps == stamps and len(first.keypoints) == (cut or len(kp))
        # read ahead in a forked process: the same pass
        ahead = read_ahead(bag, plan)()
        assert ahead.depth_stamps == first.depth_stamps
        assert [s for s, _ in ahead.keypoints] == [s for s, _ in first.keypoints]
        for (_, a), (_, b) in zip(ahead.keypoints, first.keypoints, strict=True):
            assert (a.header, a.layout, [s.track_id for s in a.skeletons]) == \
                (b.header, b.layout, [s.track_id for s in b.skeletons])
            for x, y in zip(a.skeletons, b.skeletons, strict=True):
                np.testing.assert_array_equal(x.xyc, y.xyc)
        assert [s for s, _ in ahead.infos] == [s for s, _ in first.infos]
    with pytest.raises(BagError, match="has no topic"):  # what the pass raises, raised when asked
        read_ahead(bag, FirstPassPlan("/none", None, None, (TOPIC_DEPTH, IMAGE)))()
    assert not multiprocessing.active_children()
    with read_ahead(bag, plan):  # closed unasked (its caller failed on the way): its reader stopped
        assert multiprocessing.active_children()
    assert not multiprocessing.active_children()
    sizes_read = [x.msg for x in bags.read_messages(bag, [TOPIC_DEPTH], {IMAGE: len}, {IMAGE: HEADER_BYTES})]
    assert len(sizes_read) == len(kp) and max(sizes_read) <= HEADER_BYTES
    # read from their chunks or as a stream: the same images, the stream read once
    streamed = replace(alone, located=None)
    with alone.frames() as a, streamed.frames() as b:
        for i in range(len(kp)):
            x, y = a.image(i), b.image(i)
            assert (x is None) == (y is None) == (alone.partners[i] is None)
            if x is not None and y is not None:
                np.testing.assert_array_equal(x, y)
        assert (a.n_passes, b.n_passes) == (0, 1)


def test_one_person_a_message_is_lifted_in_step_by_frame_as_by_message(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Tracks one after another, one person a message, images read by number: the chains are lifted
    in step by their own frames (a batch of people from different messages, each on its own image),
    and each gets what it gets lifted message by message (the images read as a stream)."""
    from pose_lifter.messages.frame import FramePipeline
    from pose_lifter.offline import chains as chains_module
    from pose_lifter.offline.chains import split_chains

    batches: list[int] = []
    together = chains_module.lift_together

    def spy(frames: Any, depths: Any = None) -> Any:
        batches.append(len(frames))
        return together(frames, depths)

    monkeypatch.setattr(chains_module, "lift_together", spy)

    bag = rgbd_bag(tmp_path / "rgbd.mcap", tracks=2)
    kp = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, [TOPIC_KEYPOINTS])]
    infos = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, ["/camera_info"])]
    assert {sk.track_id for _, msg in kp for sk in msg.skeletons} == {0, 1}
    frames = [stamp_to_ns(msg.header.stamp) for _, msg in kp]
    depth = pair_depth(bag, TOPIC_DEPTH, IMAGE, frames, [(640.0, 480.0)] * len(kp), 0.003)
    assert depth.located is not None and depth.paired == len(kp)
    lifter, settings = Lifter(), LiftSettings()
    chains, _, _ = split_chains(kp, infos, FramePipeline(lifter, settings.frame))
    assert sorted(len(c) for c in chains) == [N // 2, N // 2]
    got = {}
    for by, d in (("frame", depth), ("message", replace(depth, located=None))):
        batches.clear()
        got[by] = lift.lift_messages(kp, infos, lifter, settings, depth=d)
        assert batches == ([2] * (N // 2) if by == "frame" else [1] * N)
    assert len(got["frame"]) == len(kp)
    for a, b in zip(got["frame"], got["message"], strict=True):
        assert (a.stamp_ns, a.track_id) == (b.stamp_ns, b.track_id)
        np.testing.assert_array_equal(a.joints_m, b.joints_m)
        np.testing.assert_array_equal(a.std_m, b.std_m)


def test_chains_in_step_read_each_chunk_of_depth_images_once(tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """More tracks one after another than the images held at once: the chains go in step that
    many at a time, so a step reads no more chunks than the reader keeps and each chunk (two
    images) is decompressed once; the poses are those lifted message by message."""
    from pose_lifter.messages.frame import FramePipeline
    from pose_lifter.offline import chains as chains_module
    from pose_lifter.offline import depth as depth_module
    from pose_lifter.offline.chains import split_chains

    held = 2
    monkeypatch.setattr(depth_module, "HELD_IMAGES", held)
    monkeypatch.setattr(chains_module, "HELD_IMAGES", held)
    batches: list[int] = []
    together = chains_module.lift_together

    def spy(frames: Any, depths: Any = None) -> Any:
        batches.append(len(frames))
        return together(frames, depths)

    decompressed: list[int] = []
    close = mcap_index.IndexedMessages.close

    def counted(self: mcap_index.IndexedMessages) -> None:
        decompressed.append(self.n_decompressed)
        close(self)

    monkeypatch.setattr(chains_module, "lift_together", spy)
    monkeypatch.setattr(mcap_index.IndexedMessages, "close", counted)
    bag = rgbd_bag(tmp_path / "rgbd.mcap", tracks=N // 2)  # five tracks of two frames, a chunk each
    kp = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, [TOPIC_KEYPOINTS])]
    infos = [(x.stamp_ns, x.msg) for x in bags.read_messages(bag, ["/camera_info"])]
    depth = pair_depth(bag, TOPIC_DEPTH, IMAGE, [stamp_to_ns(msg.header.stamp) for _, msg in kp],
                       [(640.0, 480.0)] * len(kp), 0.003)
    assert depth.located is not None
    lifter, settings = Lifter(), LiftSettings()
    chains, _, _ = split_chains(kp, infos, FramePipeline(lifter, settings.frame))
    assert len(chains) == N // 2
    by_frame = lift.lift_messages(kp, infos, lifter, settings, depth=depth)
    assert batches == [2, 2, 2, 2, 1, 1] and decompressed == [N // 2]
    by_message = lift.lift_messages(kp, infos, lifter, settings, depth=replace(depth, located=None))
    for a, b in zip(by_frame, by_message, strict=True):
        assert (a.stamp_ns, a.track_id) == (b.stamp_ns, b.track_id)
        np.testing.assert_array_equal(a.joints_m, b.joints_m)
